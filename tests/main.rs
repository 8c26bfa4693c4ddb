//! fragrace's integration tests, one binary: each file of this directory is a module.
//!
//! One test binary instead of one per file: every file links the whole stack (emulator,
//! kernels, CLI library), and linking it once instead of sixteen times is most of what
//! compiling the tests cost (`cargo test --workspace` from a fresh clone). A file is added
//! here as a `mod` line; `every_file_of_tests_is_a_module` fails when one is forgotten.
//!
//! Run one file's tests with a filter: `cargo test --test integration differential::`. The
//! long tier of the differential sweep: `cargo test --test integration -- --ignored long_`.

mod acceptance;
mod bucket;
mod camera;
mod cli;
mod coverage;
mod differential;
mod fuzz_smoke;
mod geometry_culling;
mod geometry_passes;
mod limits;
mod memory;
mod merging;
mod obj;
mod occupancy;
mod output;
mod params;
mod presorted;
mod presorted_exact;
mod racebench;
mod render;
mod report;
mod scenes;
mod shards;

/// Every `.rs` file next to this one is declared above: with `autotests = false`, a file
/// left out would silently not run.
#[test]
fn every_file_of_tests_is_a_module() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/tests");
    let this = include_str!("main.rs");
    let mut missing = Vec::new();
    for entry in std::fs::read_dir(dir).expect("tests/ is readable") {
        let name = entry
            .expect("an entry")
            .file_name()
            .into_string()
            .expect("UTF-8");
        if let Some(m) = name.strip_suffix(".rs") {
            if m != "main" && !this.contains(&format!("\nmod {m};\n")) {
                missing.push(name);
            }
        }
    }
    assert!(
        missing.is_empty(),
        "tests/main.rs does not declare {missing:?}"
    );
}
