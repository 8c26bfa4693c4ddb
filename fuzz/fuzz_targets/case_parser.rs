//! The case-file parser on arbitrary bytes, and case round trips (see
//! `fragrace::fuzz::targets::case_parser`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Err(v) = fragrace::fuzz::targets::case_parser(data) {
        panic!("{v}");
    }
});
