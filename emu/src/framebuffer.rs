//! Render targets, depth and stencil, stored tile-major so that each tile's memory is
//! contiguous and tiles can be written in parallel through disjoint `&mut` borrows.
//!
//! This module knows nothing of shaders or executors; [`TileMemory`] applies the
//! fixed-function state of [`crate::state`] to one tile in whatever order it is called
//! (the pipeline calls it in API order).

use crate::raster::SampleCount;
use crate::state::{Format, FragmentState};

/// Largest accepted width or height (and the pixel budget is `MAX_PIXELS`).
pub const MAX_DIMENSION: u32 = 16384;
/// Largest accepted `width * height * samples`.
pub const MAX_SAMPLES_TOTAL: u64 = 1 << 28;

/// Why a framebuffer cannot be made.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum FramebufferError {
    #[error("viewport {width}x{height} is empty")]
    Empty { width: u32, height: u32 },
    #[error("viewport {width}x{height} with {samples} samples is larger than the supported {max} samples ({MAX_DIMENSION} pixels per side)")]
    TooLarge { width: u32, height: u32, samples: usize, max: u64 },
    #[error("{0} render targets requested, at most 8 are supported")]
    TooManyTargets(usize),
    #[error("tile size {0} is not a power of two from 8 to 256")]
    BadTileSize(u32),
}

/// The memory of one tile: every target, depth and stencil, all samples.
/// Texel index: `(ly * tile_size + lx) * samples + s` with `lx, ly` tile-local.
pub struct TileMemory {
    /// Tile rectangle in pixels: origin and (clamped) size.
    pub x0: u32,
    pub y0: u32,
    pub w: u32,
    pub h: u32,
    pub tile_size: u32,
    pub samples: u32,
    /// Raw channel words per target (f32 bits for float and RGBA8 formats, u32 otherwise).
    pub color: Vec<Vec<[u32; 4]>>,
    pub depth: Vec<f32>,
    pub stencil: Vec<u8>,
}

impl TileMemory {
    /// Runs the stencil and depth tests of `state` on the covered samples of pixel
    /// `(lx, ly)`, applying the stencil ops and (when `write_depth`) depth writes, in the
    /// order GL specifies (stencil test, then depth test). `depths[s]` is the fragment's
    /// depth at sample `s`. Returns the mask of samples that passed.
    pub fn depth_stencil(
        &mut self,
        state: &FragmentState,
        lx: u32,
        ly: u32,
        coverage: u8,
        depths: &[f32; 8],
        front_facing: bool,
        write_depth: bool,
    ) -> u8 {
        let _ = (state, lx, ly, coverage, depths, front_facing, write_depth);
        todo!()
    }

    /// Writes the shader outputs (one per target, raw words) to the samples in `mask`,
    /// through each target's blend / logic op / write mask.
    pub fn write_outputs(
        &mut self,
        state: &FragmentState,
        lx: u32,
        ly: u32,
        mask: u8,
        outputs: &[[u32; 4]],
    ) {
        let _ = (state, lx, ly, mask, outputs);
        todo!()
    }
}

/// A read-only, row-major snapshot of one target (all samples), for later passes.
#[derive(Clone, Debug)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub samples: u32,
    pub format: Format,
    /// Index `(y * width + x) * samples + s`.
    pub texels: Vec<[u32; 4]>,
}

impl Image {
    pub fn texel(&self, x: u32, y: u32, sample: u32) -> [u32; 4] {
        self.texels[((y * self.width + x) * self.samples + sample) as usize]
    }
    /// The texel as floats (f32 bits of float formats; u32 converted for integer formats).
    pub fn texel_f32(&self, x: u32, y: u32, sample: u32) -> [f32; 4] {
        let _ = (x, y, sample);
        todo!()
    }
}

/// Render targets plus depth and stencil, tile-major.
pub struct Framebuffer {
    pub width: u32,
    pub height: u32,
    pub samples: SampleCount,
    pub tile_size: u32,
    pub tiles_x: u32,
    pub tiles_y: u32,
    pub formats: Vec<Format>,
    tiles: Vec<TileMemory>,
}

impl Framebuffer {
    /// A framebuffer with the given targets, colour cleared to 0, depth to 1.0, stencil to 0.
    pub fn new(
        width: u32,
        height: u32,
        samples: SampleCount,
        tile_size: u32,
        formats: &[Format],
    ) -> Result<Framebuffer, FramebufferError> {
        let _ = (width, height, samples, tile_size, formats);
        todo!()
    }
    pub fn tiles(&self) -> &[TileMemory] {
        &self.tiles
    }
    pub fn tiles_mut(&mut self) -> &mut [TileMemory] {
        &mut self.tiles
    }
    /// Clears a target to raw words (every sample).
    pub fn clear_color(&mut self, target: usize, value: [u32; 4]) {
        let _ = (target, value);
        todo!()
    }
    pub fn clear_depth(&mut self, value: f32) {
        let _ = value;
        todo!()
    }
    pub fn clear_stencil(&mut self, value: u8) {
        let _ = value;
        todo!()
    }
    pub fn color(&self, target: usize, x: u32, y: u32, sample: u32) -> [u32; 4] {
        let _ = (target, x, y, sample);
        todo!()
    }
    pub fn depth(&self, x: u32, y: u32, sample: u32) -> f32 {
        let _ = (x, y, sample);
        todo!()
    }
    pub fn stencil(&self, x: u32, y: u32, sample: u32) -> u8 {
        let _ = (x, y, sample);
        todo!()
    }
    /// Row-major snapshot of a target, for binding read-only in a later pass.
    pub fn image(&self, target: usize) -> Image {
        let _ = target;
        todo!()
    }
}
