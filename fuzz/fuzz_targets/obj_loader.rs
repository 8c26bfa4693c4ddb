//! The OBJ loader on arbitrary bytes (see `fragrace::fuzz::targets::obj_loader`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Err(v) = fragrace::fuzz::targets::obj_loader(data) {
        panic!("{v}");
    }
});
