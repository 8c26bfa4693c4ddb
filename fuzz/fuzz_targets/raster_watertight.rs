//! Rasterizer watertightness and no duplicate coverage on arbitrary tilings and triangles
//! (see `fragrace::fuzz::targets::raster_watertight`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Err(v) = fragrace::fuzz::targets::raster_watertight(data) {
        panic!("{v}");
    }
});
