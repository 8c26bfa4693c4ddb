//! Rasterization: homogeneous clipping, fixed-point triangle setup, tile binning and
//! per-tile coverage, as D3D11/OpenGL hardware does it.
//!
//! This module knows nothing of shading, memory or executors: it turns clip-space
//! triangles into [`Fragment`]s, tile by tile, in API order.
//!
//! Rules:
//! - viewport transform `x = (x_ndc + 1) / 2 * W`, `y = (1 - y_ndc) / 2 * H`: screen space has
//!   y pointing down (row 0 is the top row of the image); NDC +y is up;
//! - 8 sub-pixel bits of fixed point ([`SUBPIXEL_BITS`], round to nearest), pixel centres at
//!   +0.5; every vertex is snapped once, so a vertex shared by several triangles is
//!   bit-identical in all of them;
//! - top-left fill rule on integer (i64) edge functions: *watertight*, a sample on an edge
//!   shared by two triangles is covered by exactly one of them; no duplicate fragments;
//! - facing as OpenGL: counter-clockwise in window coordinates with y up (that is, in NDC) is
//!   front-facing for [`FrontFace::Ccw`]; zero-area triangles produce nothing;
//! - depth `z_window = (z_ndc + 1) / 2` (OpenGL's default depth range), a plane in screen
//!   space ([`SetupTriangle::depth_at`]), bit-identical for identical vertices;
//!   barycentrics perspective-correct and relative to the source triangle
//!   ([`SetupTriangle::bary_at`]);
//! - homogeneous clipping against `w > 0`, the near and far planes, and a guard band of
//!   ±2^20 pixels for x/y (which also bounds the fixed-point coordinates so the i64 edge
//!   functions never overflow); a clipped polygon is fanned into setup triangles that keep
//!   their source and partition its samples exactly;
//! - MSAA with 1, 2, 4 or 8 samples at the standard D3D positions, exact per-sample coverage.
//!
//! Speed (a dense mesh is mostly sub-pixel triangles): vertices are projected once; a
//! branch-free pass drops triangles whose snapped bounding box reaches no sample; the few
//! left get an exact sample test, and a triangle covering a single pixel has its coverage
//! stored in its bin entry, so rasterizing it costs nothing; setup records are 64 bytes with no
//! heap; large buffers are recycled from frame to frame (`pool`).

mod block;
mod clip;
mod coverage;
pub(crate) mod pool;
mod setup;

pub use setup::{
    bin_triangles, bin_triangles_with, effective_tile_size, prepare, prepare_projected, Binned,
    FlatChunk, PlaneSetup, Prepared, Projected, Segment, SetupTriangle, MAX_TILE, MIN_TILE,
};

/// Sub-pixel precision of snapped vertex positions.
pub const SUBPIXEL_BITS: u32 = 8;

/// Number of samples per pixel.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
pub enum SampleCount {
    #[default]
    X1,
    X2,
    X4,
    X8,
}

impl SampleCount {
    pub fn count(self) -> usize {
        match self {
            SampleCount::X1 => 1,
            SampleCount::X2 => 2,
            SampleCount::X4 => 4,
            SampleCount::X8 => 8,
        }
    }
    pub fn from_count(n: u32) -> Option<SampleCount> {
        match n {
            1 => Some(SampleCount::X1),
            2 => Some(SampleCount::X2),
            4 => Some(SampleCount::X4),
            8 => Some(SampleCount::X8),
            _ => None,
        }
    }
    /// Standard sample positions (D3D11 / Vulkan standard), as offsets in pixels from the
    /// pixel's top-left corner (so the centre is (0.5, 0.5)).
    pub fn positions(self) -> &'static [(f32, f32)] {
        coverage::sample_positions(self)
    }
}

/// Which faces are culled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum CullMode {
    #[default]
    None,
    Front,
    Back,
}

/// Which winding (in window space, as seen on screen) is front-facing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum FrontFace {
    /// Counter-clockwise on screen (OpenGL's default).
    #[default]
    Ccw,
    Cw,
}

/// Rasterizer state of one draw.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct RasterState {
    pub cull: CullMode,
    pub front_face: FrontFace,
    pub samples: SampleCount,
    /// Tile edge in pixels (a power of two from 8 to 256; other values are rounded up to one,
    /// see [`effective_tile_size`]).
    pub tile_size: u32,
    /// With several samples: `false` rasterizes as if single-sampled (GL's
    /// `glDisable(GL_MULTISAMPLE)`, D3D's `MultisampleEnable = FALSE`): a fragment covers
    /// all samples or none, by the pixel centre, at the centre's depth. Stencil routing
    /// relies on it. Applied by the pipeline.
    pub multisample: bool,
}

impl Default for RasterState {
    fn default() -> Self {
        RasterState {
            cull: CullMode::None,
            front_face: FrontFace::Ccw,
            samples: SampleCount::X1,
            tile_size: 64,
            multisample: true,
        }
    }
}

/// Size of the render area in pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Viewport {
    pub width: u32,
    pub height: u32,
}

/// A run of pixels `x0..x1` of row `y` covered by one triangle with the same samples: the
/// unit the rasterizer hands out (one per row of a triangle with one sample; single pixels
/// with several).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Span {
    pub y: u32,
    pub x0: u32,
    /// Exclusive.
    pub x1: u32,
    /// Setup index: into [`Binned::tris`] when the planes were set up.
    pub tri: u32,
    /// Coverage of every pixel of the run (see [`Fragment::coverage`]).
    pub coverage: u8,
    /// The triangle's [`SetupTriangle::source`] and [`SetupTriangle::front_facing`],
    /// carried along so that shading need not load the setup record (64 bytes, a cache
    /// miss per triangle on a large mesh) unless it reads depth or barycentrics.
    pub source: u32,
    pub front_facing: bool,
}

/// One covered pixel of one triangle (a fragment before shading).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fragment {
    pub x: u32,
    pub y: u32,
    /// Setup index: into [`Binned::tris`] when the planes were set up.
    pub tri: u32,
    /// Bit `s` set = sample `s` covered (bit 0 only, with one sample: the pixel centre).
    pub coverage: u8,
    /// As [`Span::source`] and [`Span::front_facing`].
    pub source: u32,
    pub front_facing: bool,
}
