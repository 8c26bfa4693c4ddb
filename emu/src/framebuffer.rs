//! Render targets, depth and stencil, stored tile-major so that each tile's memory is
//! contiguous and tiles can be written in parallel through disjoint `&mut` borrows.
//!
//! This module knows nothing of shaders or executors; [`TileMemory`] applies the
//! fixed-function state of [`crate::state`] to one tile in whatever order it is called
//! (the pipeline calls it in API order).

use crate::raster::SampleCount;
use crate::state::{Format, FragmentState};

/// Largest accepted width or height (the total budget is [`MAX_SAMPLES_TOTAL`]).
pub const MAX_DIMENSION: u32 = 16384;
/// Largest framebuffer allocation (targets, depth and stencil, padded to whole tiles).
pub const MAX_BYTES: u64 = 8 << 30;
/// Largest accepted `width * height * samples`.
pub const MAX_SAMPLES_TOTAL: u64 = 1 << 28;

/// Why a framebuffer cannot be made.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum FramebufferError {
    #[error("viewport {width}x{height} is empty")]
    Empty { width: u32, height: u32 },
    #[error("viewport {width}x{height} with {samples} samples is larger than the supported {max} samples ({MAX_DIMENSION} pixels per side)")]
    TooLarge {
        width: u32,
        height: u32,
        samples: usize,
        max: u64,
    },
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
    /// While `color_fill` is set they are not the tile's values (see there).
    pub(crate) color: Vec<Vec<[u32; 4]>>,
    /// A pending clear (a GPU's per-tile fast clear): `Some(v)` when the colour planes
    /// still hold words that are not the tile's, and every texel of every plane has the
    /// value `v`. Whoever first writes the tile clears it first
    /// ([`TileMemory::clear_pending_color`], or row by row just ahead of the writes in the
    /// fused full-screen path, which owns the tile: the clear is then done by the pass's
    /// threads, each on rows it is about to write); a readback fills in `v`. Two sources:
    /// - a new framebuffer takes kept planes without clearing them ([`TilePlanes::take`]):
    ///   `v` = 0, the clear, instead of a 64 MiB `memset` on one thread for a 2048x2048
    ///   RGBA32F target before the frame's passes;
    /// - a full-screen pass that writes one value to every pixel of a tile no geometry
    ///   reached (a resolve's background: [`TileMemory::fast_clear`]) writes nothing: at
    ///   2048x2048 the bunny leaves three tiles in four empty, 48 MiB of background texels.
    pub(crate) color_fill: Option<[u32; 4]>,
    /// Depth per sample. Empty until a depth or stencil test first needs it (most
    /// multi-fragment passes never test): then all samples hold `depth_clear`.
    pub depth: Vec<f32>,
    /// Stencil per sample; empty until needed, like `depth`.
    pub stencil: Vec<u8>,
    /// The value every sample has while `depth` is empty.
    pub depth_clear: f32,
    /// The value every sample has while `stencil` is empty.
    pub stencil_clear: u8,
}

impl TileMemory {
    /// A tile at `(x0, y0)` of clamped size `w x h`, with every buffer full-size
    /// (`tile_size * tile_size * samples`) so that tile-local indexing is the same for edge
    /// tiles; colour cleared to 0, depth to 1.0, stencil to 0.
    pub fn new(
        x0: u32,
        y0: u32,
        w: u32,
        h: u32,
        tile_size: u32,
        samples: u32,
        targets: usize,
    ) -> TileMemory {
        let mut t = TileMemory::lazy(x0, y0, w, h, tile_size, samples, targets);
        t.materialize();
        t.clear_pending_color();
        t
    }

    /// [`TileMemory::new`] with depth and stencil left lazy (allocated on first use): what a
    /// framebuffer starts with, so that passes that never test never pay for them.
    fn lazy(
        x0: u32,
        y0: u32,
        w: u32,
        h: u32,
        tile_size: u32,
        samples: u32,
        targets: usize,
    ) -> TileMemory {
        let n = (tile_size * tile_size * samples) as usize;
        let mut unclear = false;
        let color = (0..targets)
            .map(|_| {
                let (plane, kept) = TILE_COLORS.take(n);
                unclear |= kept;
                plane
            })
            .collect();
        TileMemory {
            x0,
            y0,
            w,
            h,
            tile_size,
            samples,
            color,
            color_fill: unclear.then_some([0; 4]),
            depth: Vec::new(),
            stencil: Vec::new(),
            depth_clear: 1.0,
            stencil_clear: 0,
        }
    }

    /// Allocates depth and stencil (at their clear values) if they are still lazy.
    pub fn materialize(&mut self) {
        let n = (self.tile_size * self.tile_size * self.samples) as usize;
        if self.depth.is_empty() {
            self.depth = vec![self.depth_clear; n];
        }
        if self.stencil.is_empty() {
            self.stencil = vec![self.stencil_clear; n];
        }
    }

    /// Texel `i` (an [`TileMemory::index`]) of target `target`'s plane: the pending clear's
    /// value while the planes await it (`color_fill`).
    pub fn color_at(&self, target: usize, i: usize) -> [u32; 4] {
        let texel = self.color[target][i];
        self.color_fill.unwrap_or(texel)
    }

    /// Texels of each colour plane (the full tile, padding included, every sample).
    pub fn plane_len(&self) -> usize {
        (self.tile_size * self.tile_size * self.samples) as usize
    }

    /// Performs the pending clear of the colour planes, if any (`color_fill`): before
    /// anything reads or writes them as the tile's.
    #[inline]
    pub(crate) fn clear_pending_color(&mut self) {
        if let Some(v) = self.color_fill {
            self.clear_all_color(v);
        }
    }

    #[cold]
    fn clear_all_color(&mut self, v: [u32; 4]) {
        for plane in &mut self.color {
            plane.fill(v);
        }
        self.color_fill = None;
    }

    /// Takes over the pending clear of the colour planes: its value if there was one, and
    /// the caller now clears every row of the tile to it ([`TileMemory::clear_color_row`],
    /// padding rows included) before it reads or writes the row.
    #[inline]
    pub(crate) fn take_pending_color(&mut self) -> Option<[u32; 4]> {
        self.color_fill.take()
    }

    /// Sets row `ly` of the tile (every column, padding included, every sample) to `v` in
    /// every colour plane.
    #[inline]
    pub(crate) fn clear_color_row(&mut self, ly: u32, v: [u32; 4]) {
        let per_row = (self.tile_size * self.samples) as usize;
        let at = ly as usize * per_row;
        for plane in &mut self.color {
            plane[at..at + per_row].fill(v);
        }
    }

    /// Gives every texel of every colour plane (every sample, padding included) the value
    /// `v` without writing it: a pending clear (`color_fill`), performed by the first write
    /// to the tile or filled in by a readback. What writing `v` everywhere leaves.
    #[inline]
    pub(crate) fn fast_clear(&mut self, v: [u32; 4]) {
        self.color_fill = Some(v);
    }

    /// Index of sample `s` of tile-local pixel `(lx, ly)` in every buffer of the tile.
    #[inline]
    pub fn index(&self, lx: u32, ly: u32, s: u32) -> usize {
        debug_assert!(lx < self.tile_size && ly < self.tile_size && s < self.samples);
        ((ly * self.tile_size + lx) * self.samples + s) as usize
    }

    /// The bits of a sample mask that name existing samples (coverage bits beyond the
    /// sample count are ignored rather than indexing a neighbouring pixel).
    #[inline]
    fn sample_bits(&self) -> u8 {
        ((1u16 << self.samples) - 1) as u8
    }

    /// Runs the stencil and depth tests of `state` on the covered samples of pixel
    /// `(lx, ly)`, applying the stencil ops and (when `write_depth`) depth writes, in the
    /// order GL specifies (stencil test, then depth test). `depths[s]` is the fragment's
    /// depth at sample `s`. Returns the mask of samples that passed.
    ///
    /// The arguments are the per-fragment inputs of the fixed-function test, passed flat so
    /// the hot path builds no struct per fragment.
    #[allow(clippy::too_many_arguments)]
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
        let mut mask = coverage & state.sample_mask & self.sample_bits();
        let stencil = &state.stencil;
        let depth = &state.depth;
        if !stencil.enabled && !depth.test {
            // Nothing to test and nothing written: with the depth test disabled GL never
            // writes depth, even when the depth write mask is set.
            return mask;
        }
        let face = if front_facing {
            &stencil.front
        } else {
            &stencil.back
        };
        self.materialize();
        let base = self.index(lx, ly, 0);
        let mut bits = mask;
        while bits != 0 {
            let s = bits.trailing_zeros();
            bits &= bits - 1;
            let i = base + s as usize;
            let stored_stencil = self.stencil[i];
            if stencil.enabled
                && !face.func.test(
                    face.reference & face.read_mask,
                    stored_stencil & face.read_mask,
                )
            {
                self.stencil[i] =
                    face.fail_op
                        .apply(stored_stencil, face.reference, face.write_mask);
                mask &= !(1 << s);
                continue;
            }
            if depth.test {
                if !depth.func.test(depths[s as usize], self.depth[i]) {
                    if stencil.enabled {
                        self.stencil[i] = face.depth_fail_op.apply(
                            stored_stencil,
                            face.reference,
                            face.write_mask,
                        );
                    }
                    mask &= !(1 << s);
                    continue;
                }
                if write_depth && depth.write {
                    self.depth[i] = depths[s as usize];
                }
            }
            if stencil.enabled {
                self.stencil[i] =
                    face.pass_op
                        .apply(stored_stencil, face.reference, face.write_mask);
            }
        }
        mask
    }

    /// The depth test of `state` alone, reading the depth plane and writing nothing: for
    /// passes with the stencil test off and depth writes off, where the test of one fragment
    /// does not depend on any other, so several threads may test one tile at once.
    /// Returns the mask of samples that passed.
    pub fn depth_test_readonly(
        &self,
        state: &FragmentState,
        lx: u32,
        ly: u32,
        coverage: u8,
        depths: &[f32; 8],
    ) -> u8 {
        debug_assert!(!(state.stencil.enabled || state.depth.test && state.depth.write));
        let mut mask = coverage & state.sample_mask & self.sample_bits();
        if !state.depth.test {
            return mask;
        }
        let base = self.index(lx, ly, 0);
        let mut bits = mask;
        while bits != 0 {
            let s = bits.trailing_zeros();
            bits &= bits - 1;
            // An untouched depth plane is still all `depth_clear` (see `materialize`).
            let stored = self
                .depth
                .get(base + s as usize)
                .copied()
                .unwrap_or(self.depth_clear);
            if !state.depth.func.test(depths[s as usize], stored) {
                mask &= !(1 << s);
            }
        }
        mask
    }

    /// Writes the shader outputs (one per target, raw words) to the samples in `mask`,
    /// through each target's blend / logic op / write mask.
    #[inline]
    pub fn write_outputs(
        &mut self,
        state: &FragmentState,
        lx: u32,
        ly: u32,
        mask: u8,
        outputs: &[[u32; 4]],
    ) {
        let mask = mask & self.sample_bits();
        let base = self.index(lx, ly, 0);
        self.clear_pending_color();
        for (i, (target, out)) in state.targets.iter().zip(outputs).enumerate() {
            let color = &mut self.color[i];
            let mut bits = mask;
            while bits != 0 {
                let idx = base + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                color[idx] = target.combine(*out, color[idx]);
            }
        }
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
        let t = self.texel(x, y, sample);
        if self.format.is_integer() {
            t.map(|w| w as f32)
        } else {
            t.map(f32::from_bits)
        }
    }
}

/// Render targets plus depth and stencil, tile-major: tile `(tx, ty)` is
/// `tiles()[ty * tiles_x + tx]` and covers pixels `tx*tile_size ..` and `ty*tile_size ..`
/// (edge tiles clamped to the framebuffer in `w`, `h`, but with full-size buffers).
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

/// The colour planes of dropped framebuffers' tiles, for the next framebuffer's.
///
/// Why: a 2048x2048 RGBA32F resolve target is 64 MiB in 1024 tiles of 64 KiB, allocated for
/// every frame (every run has its framebuffer). Freed, they went back to the OS (the top of
/// `malloc`'s heap is trimmed), so each frame's resolve faulted them in again, a page fault
/// per 4 KiB as it wrote its first pixel of each page. A tile here takes a kept plane of its
/// size as it is, and clears it when it is first written (`TileMemory::color_fill`).
/// Plain `std` mutex: bookkeeping.
static TILE_COLORS: TilePlanes = TilePlanes {
    free: std::sync::Mutex::new(Vec::new()),
};

/// Most bytes of tile planes kept (a 4096x4096 RGBA32F target).
const MAX_KEPT_TILE_BYTES: usize = 256 << 20;

struct TilePlanes {
    free: std::sync::Mutex<Vec<Vec<[u32; 4]>>>,
}

impl TilePlanes {
    /// A plane of `n` texels: a kept plane of that length, as an earlier framebuffer left
    /// it, when there is one (`true`: it still needs its clear), else a new one of zeros.
    fn take(&self, n: usize) -> (Vec<[u32; 4]>, bool) {
        let kept = {
            let mut free = self.free.lock().unwrap_or_else(|e| e.into_inner());
            match free.last() {
                Some(v) if v.len() == n => free.pop(),
                _ => None,
            }
        };
        match kept {
            Some(v) => (v, true),
            None => (vec![[0u32; 4]; n], false),
        }
    }

    /// Keeps the planes of `tiles` (all of one length in a framebuffer), up to the bound.
    fn give(&self, tiles: &mut [TileMemory]) {
        let mut free = self.free.lock().unwrap_or_else(|e| e.into_inner());
        // Planes of another length are of another framebuffer size: the newest size wins.
        let n = tiles.first().and_then(|t| t.color.first()).map(Vec::len);
        if free.first().map(Vec::len) != n {
            free.clear();
        }
        let mut bytes: usize = free.iter().map(|v| v.len() * 16).sum();
        for plane in tiles.iter_mut().flat_map(|t| t.color.drain(..)) {
            bytes += plane.len() * 16;
            if bytes > MAX_KEPT_TILE_BYTES || Some(plane.len()) != n {
                break;
            }
            free.push(plane);
        }
    }
}

impl Drop for Framebuffer {
    fn drop(&mut self) {
        TILE_COLORS.give(&mut self.tiles);
    }
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
        if width == 0 || height == 0 {
            return Err(FramebufferError::Empty { width, height });
        }
        let n = samples.count();
        // The product is only computed once both dimensions are known to be <= 2^14 (the `||`
        // short-circuits), so it is below 2^31 and cannot overflow u64; nothing is allocated
        // before every check has passed.
        if width > MAX_DIMENSION
            || height > MAX_DIMENSION
            || u64::from(width) * u64::from(height) * n as u64 > MAX_SAMPLES_TOTAL
        {
            return Err(FramebufferError::TooLarge {
                width,
                height,
                samples: n,
                max: MAX_SAMPLES_TOTAL,
            });
        }
        if formats.len() > 8 {
            return Err(FramebufferError::TooManyTargets(formats.len()));
        }
        if !(8..=256).contains(&tile_size) || !tile_size.is_power_of_two() {
            return Err(FramebufferError::BadTileSize(tile_size));
        }
        let tiles_x = width.div_ceil(tile_size);
        let tiles_y = height.div_ceil(tile_size);
        // What will really be allocated: edge tiles are full-size, each colour sample is 16
        // bytes, depth and stencil 5 more.
        let padded = u64::from(tiles_x * tile_size) * u64::from(tiles_y * tile_size) * n as u64;
        if padded * (16 * formats.len() as u64 + 5) > MAX_BYTES {
            return Err(FramebufferError::TooLarge {
                width,
                height,
                samples: n,
                max: MAX_SAMPLES_TOTAL,
            });
        }
        let mut tiles = Vec::with_capacity((tiles_x * tiles_y) as usize);
        for ty in 0..tiles_y {
            for tx in 0..tiles_x {
                let x0 = tx * tile_size;
                let y0 = ty * tile_size;
                tiles.push(TileMemory::lazy(
                    x0,
                    y0,
                    tile_size.min(width - x0),
                    tile_size.min(height - y0),
                    tile_size,
                    n as u32,
                    formats.len(),
                ));
            }
        }
        Ok(Framebuffer {
            width,
            height,
            samples,
            tile_size,
            tiles_x,
            tiles_y,
            formats: formats.to_vec(),
            tiles,
        })
    }

    /// The tile holding pixel `(x, y)` and the index of `sample` of that pixel in the tile's
    /// buffers. Panics outside the framebuffer (the padding of edge tiles is not pixels).
    pub fn locate(&self, x: u32, y: u32, sample: u32) -> (usize, usize) {
        assert!(
            x < self.width && y < self.height && (sample as usize) < self.samples.count(),
            "pixel ({x}, {y}) sample {sample} outside the {}x{} framebuffer with {} samples",
            self.width,
            self.height,
            self.samples.count()
        );
        let ts = self.tile_size;
        let tile = ((y / ts) * self.tiles_x + x / ts) as usize;
        (tile, self.tiles[tile].index(x % ts, y % ts, sample))
    }
    pub fn tiles(&self) -> &[TileMemory] {
        &self.tiles
    }
    pub fn tiles_mut(&mut self) -> &mut [TileMemory] {
        &mut self.tiles
    }
    /// Clears a target to raw words (every sample).
    ///
    /// The words are stored as given (no conversion to the format; channels beyond the
    /// format's count should be 0, as `combine` keeps them).
    pub fn clear_color(&mut self, target: usize, value: [u32; 4]) {
        for t in &mut self.tiles {
            t.clear_pending_color();
            t.color[target].fill(value);
        }
    }
    /// Clears depth on every sample.
    pub fn clear_depth(&mut self, value: f32) {
        for t in &mut self.tiles {
            t.depth.fill(value);
            t.depth_clear = value;
        }
    }
    /// Clears stencil on every sample.
    pub fn clear_stencil(&mut self, value: u8) {
        for t in &mut self.tiles {
            t.stencil.fill(value);
            t.stencil_clear = value;
        }
    }
    /// Raw words of one sample of a target, global pixel coordinates.
    pub fn color(&self, target: usize, x: u32, y: u32, sample: u32) -> [u32; 4] {
        let (t, i) = self.locate(x, y, sample);
        let t = &self.tiles[t];
        t.color_at(target, i)
    }
    /// Depth of one sample, global pixel coordinates.
    pub fn depth(&self, x: u32, y: u32, sample: u32) -> f32 {
        let (t, i) = self.locate(x, y, sample);
        let t = &self.tiles[t];
        t.depth.get(i).copied().unwrap_or(t.depth_clear)
    }
    /// Stencil of one sample, global pixel coordinates.
    pub fn stencil(&self, x: u32, y: u32, sample: u32) -> u8 {
        let (t, i) = self.locate(x, y, sample);
        let t = &self.tiles[t];
        t.stencil.get(i).copied().unwrap_or(t.stencil_clear)
    }
    /// Row-major snapshot of a target, for binding read-only in a later pass.
    pub fn image(&self, target: usize) -> Image {
        let samples = self.samples.count();
        let mut texels = vec![[0u32; 4]; self.width as usize * self.height as usize * samples];
        let row = self.width as usize * samples;
        for tile in &self.tiles {
            let src = &tile.color[target];
            // Each tile row is a contiguous run of `w * samples` texels in both layouts.
            let run = tile.w as usize * samples;
            for ly in 0..tile.h {
                let to = (tile.y0 + ly) as usize * row + tile.x0 as usize * samples;
                match tile.color_fill {
                    // The texels are zeros already.
                    Some([0, 0, 0, 0]) => {}
                    Some(v) => texels[to..to + run].fill(v),
                    None => {
                        let from = tile.index(0, ly, 0);
                        texels[to..to + run].copy_from_slice(&src[from..from + run]);
                    }
                }
            }
        }
        Image {
            width: self.width,
            height: self.height,
            samples: samples as u32,
            format: self.formats[target],
            texels,
        }
    }
}
