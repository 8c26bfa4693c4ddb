//! Fixed-function per-fragment state (`state`) and the tile-major framebuffer
//! (`framebuffer`), one binary: compare funcs, stencil ops, blending, RGBA8 quantization,
//! logic ops, write masks, per-sample depth/stencil with MSAA, stencil routing, framebuffer
//! limits and readback round trips.

mod blending;
mod common;
mod depth_stencil;
mod framebuffer;
