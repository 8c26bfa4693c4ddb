//! # fragrace-emu: a software GPU for multi-fragment rendering under races
//!
//! (crate docs are written in `docs/architecture.md` and below, as the modules land)

pub mod framebuffer;
pub mod geometry;
pub mod raster;
pub mod state;
pub mod sync;
