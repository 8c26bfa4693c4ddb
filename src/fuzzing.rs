//! Fuzz target logic, shared by the cargo-fuzz targets in `fuzz/` and the bounded smoke
//! tests of the normal test suite (being written).
