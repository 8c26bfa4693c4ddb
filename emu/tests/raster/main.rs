//! Rasterizer tests through the public API, one binary: fill rule and sample coverage
//! against a brute-force reference, watertightness, facing, depth and perspective-correct
//! barycentrics, clipping, bad input, and binning invariance. The timings of binning and
//! rasterizing large meshes are a benchmark (`cargo bench -p fragrace-emu --bench raster`).

mod binning;
mod clipping;
mod common;
mod coverage;
mod input;
