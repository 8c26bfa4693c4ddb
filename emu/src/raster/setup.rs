//! Triangle setup (snap to fixed point, edge functions, planes) and tile binning.
//!
//! Pipeline of [`bin_triangles`], each step parallel over `threads` threads
//! (`sync::pool::broadcast`):
//! 1. every vertex is classified against the clip planes once and, when inside all of them,
//!    snapped to 8-bit sub-pixel fixed point (a vertex shared by many triangles is projected
//!    once, and shared vertices are bit-identical in all of them: the basis of watertightness);
//! 2. triangles, in chunks: the snapped bounding box is tested for a sample first (most
//!    triangles of a dense mesh are sub-pixel and end here), then area, facing and culling, an
//!    exact sample test for tiny ones, the depth and barycentric planes, and the tile bins.
//!    Triangles with a vertex outside a plane go through homogeneous clipping ([`super::clip`]);
//! 3. chunk results are concatenated in chunk order, so setup indices follow API order; each
//!    chunk keeps its own per-tile lists (a stable counting sort done by its worker), and
//!    [`Binned::raster_tile`] walks the chunks in order.
//!
//! Step 1 is [`prepare`]; steps 2 and 3 are [`Prepared::bin`]. [`Prepared::setup_flat`] runs
//! step 2's setup code on one chunk without bins, its covered runs coming out of setup
//! directly (the unbinned passes of the parallel executor).
use super::clip::{self, ClipVert, Planes, MAX_POLY, NON_FINITE};
use super::coverage::{self, area2, bbox, Edges, SampleInfo, ONE};
use super::pool::Pool;
use super::{
    CullMode, Fragment, FrontFace, RasterState, SampleCount, Span, Viewport, SUBPIXEL_BITS,
};
use crate::hint::prefetch;
use glam::Vec4;

/// Largest magnitude of a snapped coordinate (sub-pixel units). The guard band keeps real
/// coordinates below 2^28; the clamp only makes absurd inputs (viewports wider than the guard
/// band) harmless.
const COORD_LIMIT: f64 = (1u32 << 29) as f64;

/// Largest viewport side handled (pixels); pixels beyond are never covered.
const MAX_VIEWPORT: u32 = 1 << 20;

/// A triangle after clipping and snapping, ready to rasterize.
///
/// 64 bytes (one cache line), no heap: the depth plane and three barycentric planes, each
/// relative to a reference pixel inside the viewport. The snapped vertices, needed only to
/// rasterize triangles larger than a pixel, live in the tile bins instead.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SetupTriangle {
    /// Index of the input triangle (into `indices`) this comes from (several setup triangles share one
    /// source when clipping split it).
    pub source: u32,
    pub front_facing: bool,
    /// Reference pixel of the planes: the top-left corner of the pixels the triangle's
    /// bounding box reaches (clamped to the viewport), so plane evaluations stay short-range.
    rx: i32,
    ry: i32,
    /// Depth plane: `z(x, y) = depth[0] + depth[1] (x - rx) + depth[2] (y - ry)`, pixels.
    depth: [f32; 3],
    /// Planes (same form) of `b_k / w`: the weight of source vertex `k` divided by clip `w`.
    /// Both are linear in screen space; normalising them gives perspective-correct
    /// barycentrics of the *source* triangle, also for the pieces of a clipped one.
    bary: [[f32; 3]; 3],
}

impl SetupTriangle {
    /// Window depth in `[0, 1]` at a screen position (pixels, y down), linear in screen space.
    ///
    /// The plane is computed from the snapped vertices taken in a canonical order (sorted by
    /// position) and referred to a pixel that depends only on them, so triangles with
    /// identical vertices give bit-identical depths whatever their vertex order or winding.
    #[inline]
    pub fn depth_at(&self, x: f32, y: f32) -> f32 {
        let z = eval(
            &self.depth,
            x as f64 - self.rx as f64,
            y as f64 - self.ry as f64,
        );
        z.clamp(0.0, 1.0) as f32
    }

    /// Perspective-correct barycentrics of the *source* triangle's vertices at a screen position.
    #[inline]
    pub fn bary_at(&self, x: f32, y: f32) -> [f32; 3] {
        let (dx, dy) = (x as f64 - self.rx as f64, y as f64 - self.ry as f64);
        let b = [
            eval(&self.bary[0], dx, dy),
            eval(&self.bary[1], dx, dy),
            eval(&self.bary[2], dx, dy),
        ];
        let s = b[0] + b[1] + b[2];
        if s == 0.0 || !s.is_finite() {
            return [1.0 / 3.0; 3];
        }
        [(b[0] / s) as f32, (b[1] / s) as f32, (b[2] / s) as f32]
    }
}

#[inline]
fn eval(p: &[f32; 3], dx: f64, dy: f64) -> f64 {
    p[0] as f64 + p[1] as f64 * dx + p[2] as f64 * dy
}

/// Triangles set up and binned into tiles.
pub struct Binned {
    /// The setup records, by setup index; empty when the planes were skipped
    /// ([`PlaneSetup::Skip`]).
    pub tris: Vec<SetupTriangle>,
    /// Setup triangles (as many as `tris` holds when the planes were set up).
    setup_count: u32,
    /// Input triangles.
    input_triangles: usize,
    pub tiles_x: u32,
    pub tiles_y: u32,
    pub tile_size: u32,
    /// Input triangles dropped for non-finite coordinates (or out-of-range indices).
    pub rejected: u64,
    /// The render area the triangles were set up for.
    pub viewport: Viewport,
    /// Samples per pixel the coverage masks refer to.
    pub samples: SampleCount,
    /// Per-tile lists, one set per chunk of input triangles, in chunk (= API) order.
    chunks: Vec<ChunkBins>,
}

/// The tile lists of one chunk of input triangles: `entries[tile_start[t]..tile_start[t+1]]`
/// are tile `t`'s entries, ascending. Built by the worker that set the chunk up, so no global
/// scatter is needed; [`Binned::raster_tile`] walks the chunks in order.
struct ChunkBins {
    /// Setup index of the chunk's first triangle.
    base: u32,
    tile_start: Vec<u32>,
    entries: Vec<BinEntry>,
    /// Snapped vertices (sub-pixel units, y down, positively oriented: see
    /// [`coverage::area2`]) of the chunk's triangles that are rasterized in the tiles.
    verts: Vec<[[i32; 2]; 3]>,
    /// Coverage of the chunk's small triangles, computed at setup (see [`SmallCoverage`]).
    smalls: Vec<SmallCoverage>,
    /// Per setup triangle of the chunk (by `BinEntry::tri`): what shading needs of it
    /// besides coverage, kept apart from the 64-byte setup records.
    meta: Vec<TriMeta>,
}

/// A setup triangle's source index and facing (see [`SetupTriangle`]).
#[derive(Clone, Copy, Debug, Default)]
struct TriMeta {
    source: u32,
    front_facing: bool,
}

/// The coverage of a small one-sample triangle (pixel rectangle of at most 8x8, most
/// triangles of a dense mesh at high resolution), computed once at setup: bit `8 j + i` is
/// pixel `(x + i, y + j)`. Rasterizing it is then a walk over bits, with no edge set-up
/// and no per-pixel edge stepping, in every tile it is binned to.
#[derive(Clone, Copy, Debug, Default)]
struct SmallCoverage {
    x: i32,
    y: i32,
    bits: u64,
}

impl SmallCoverage {
    /// Calls `f(y, x0, x1)` for the covered run of each row with one, in order. The block
    /// must hold one run per row at most, as the coverage of a one-sample triangle does
    /// (the samples inside a convex region, along a line, are consecutive).
    #[inline(always)]
    fn convex_runs(&self, mut f: impl FnMut(u32, u32, u32)) {
        let mut bits = self.bits;
        while bits != 0 {
            let k = bits.trailing_zeros();
            let (j, start) = (k / 8, k % 8);
            let row = (bits >> (8 * j)) as u32 & 0xff;
            let len = (!(row >> start)).trailing_zeros();
            debug_assert!(row >> (start + len) == 0, "two runs in a row of {self:?}");
            bits &= !(0xff << (8 * j));
            let x0 = (self.x + start as i32) as u32;
            f((self.y + j as i32) as u32, x0, x0 + len);
        }
    }

    /// Calls `f(y, x0, x1)` for the covered runs inside the pixel rectangle `rect`
    /// (`[x0, y0, x1, y1)`), in row-major order.
    #[inline]
    fn runs(&self, rect: [i32; 4], mut f: impl FnMut(u32, u32, u32)) {
        // Columns of the 8-wide block inside the rectangle.
        let lo = (rect[0] - self.x).clamp(0, 8);
        let hi = (rect[2] - self.x).clamp(0, 8);
        let cols = ((1u64 << hi) - 1) & !((1u64 << lo) - 1);
        // Only the rows with a covered pixel are visited.
        let mut bits = self.bits & (cols * 0x0101_0101_0101_0101);
        while bits != 0 {
            let j = bits.trailing_zeros() / 8;
            let mut row = (bits >> (8 * j)) as u32 & 0xff;
            bits &= !(0xff << (8 * j));
            let y = self.y + j as i32;
            if y < rect[1] || y >= rect[3] {
                continue;
            }
            while row != 0 {
                let start = row.trailing_zeros();
                let len = (!(row >> start)).trailing_zeros();
                let x0 = (self.x + start as i32) as u32;
                f(y as u32, x0, x0 + len);
                row &= !(((1u32 << len) - 1) << start);
            }
        }
    }
}

/// One triangle in one tile: its setup index relative to the chunk, and `info`: for a
/// triangle whose coverage is a single pixel (most triangles of a dense mesh) that pixel and
/// mask, computed at setup, as `SINGLE | mask << 16 | dy << 8 | dx` relative to the tile
/// origin; for a small one-sample triangle `SMALL | i`, its coverage being
/// [`ChunkBins::smalls`]`[i]`; otherwise the index of its vertices in [`ChunkBins::verts`].
#[derive(Clone, Copy, Debug, Default)]
struct BinEntry {
    tri: u32,
    info: u32,
}

/// Flag of a precomputed single-pixel [`BinEntry`].
const SINGLE: u32 = 1 << 31;
/// Flag of a [`BinEntry`] of one of several fan pieces of a clipped triangle.
const PIECE: u32 = 1 << 30;
/// Most input triangles per setup chunk (see [`bin_triangles`]).
const MAX_CHUNK: usize = 1 << 25;
const _: () = assert!(MAX_CHUNK * MAX_POLY < SMALL as usize);

/// Flag of a [`BinEntry`] whose coverage was computed at setup: `info` (without the flags)
/// indexes [`ChunkBins::smalls`].
const SMALL: u32 = 1 << 29;
/// The flags of a [`BinEntry`]'s `info`.
const FLAGS: u32 = SINGLE | PIECE | SMALL;

/// Whether triangle setup computes each triangle's depth and barycentric planes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlaneSetup {
    /// Planes for every setup triangle ([`Binned::tris`]).
    Compute,
    /// Coverage only: nothing downstream reads a depth or an interpolant (no depth or
    /// stencil test, and a kernel that declared `without_interpolants`). `Binned::tris`
    /// stays empty.
    Skip,
}

impl Binned {
    /// Setup triangles (fan pieces of clipped triangles count one each).
    pub fn setup_count(&self) -> u32 {
        self.setup_count
    }

    /// Input triangles (set up or not).
    pub fn input_triangles(&self) -> usize {
        self.input_triangles
    }

    pub fn tile_count(&self) -> usize {
        self.tiles_x as usize * self.tiles_y as usize
    }

    /// Pixel rectangle `(x0, y0, x1, y1)` (exclusive ends, clamped to the viewport) of a tile.
    pub fn tile_rect(&self, tile: usize) -> (u32, u32, u32, u32) {
        let tx = (tile % self.tiles_x.max(1) as usize) as u32;
        let ty = (tile / self.tiles_x.max(1) as usize) as u32;
        let ts = self.tile_size;
        let x0 = tx.saturating_mul(ts).min(self.viewport.width);
        let y0 = ty.saturating_mul(ts).min(self.viewport.height);
        let x1 = x0.saturating_add(ts).min(self.viewport.width);
        let y1 = y0.saturating_add(ts).min(self.viewport.height);
        (x0, y0, x1, y1)
    }

    /// Setup indices (into [`Binned::tris`]) of the triangles binned to a tile, ascending.
    /// A triangle can be binned to a tile where it ends up covering no sample.
    pub fn tile_triangles(&self, tile: usize) -> impl Iterator<Item = u32> + '_ {
        let ok = tile < self.tile_count();
        self.chunks.iter().filter(move |_| ok).flat_map(move |c| {
            let list = &c.entries[c.tile_start[tile] as usize..c.tile_start[tile + 1] as usize];
            list.iter().map(move |e| c.base + e.tri)
        })
    }

    /// Total number of (triangle, tile) pairs binned.
    pub fn bin_entries(&self) -> usize {
        self.chunks.iter().map(|c| c.entries.len()).sum()
    }

    /// Emits the fragments of one tile in API order (by `tri`); within one triangle in
    /// row-major order.
    pub fn raster_tile(&self, tile: usize, mut emit: impl FnMut(Fragment)) {
        if tile >= self.tile_count() {
            return;
        }
        for (c, chunk) in self.chunks.iter().enumerate() {
            let n = chunk.tile_start[tile + 1] - chunk.tile_start[tile];
            self.raster_segment(
                &Segment {
                    tile: tile as u32,
                    chunk: c as u32,
                    start: 0,
                    end: n,
                },
                &mut emit,
            );
        }
    }

    /// Splits tile `tile`'s work into [`Segment`]s of at most `max_entries` bin entries
    /// (API order: appending them in order and rastering each gives [`Binned::raster_tile`]).
    /// The fan pieces of one clipped triangle are never split (their coverage is merged).
    pub fn tile_segments(&self, tile: usize, max_entries: u32, out: &mut Vec<Segment>) {
        if tile >= self.tile_count() {
            return;
        }
        let max_entries = max_entries.max(1);
        for (c, chunk) in self.chunks.iter().enumerate() {
            let lo = chunk.tile_start[tile];
            let list = &chunk.entries[lo as usize..chunk.tile_start[tile + 1] as usize];
            let n = list.len() as u32;
            let mut start = 0;
            while start < n {
                let mut end = (start + max_entries).min(n);
                // Keep a piece group whole: move the cut past pieces of the same source.
                while end < n && list[end as usize].info & PIECE != 0 && {
                    let prev = &list[end as usize - 1];
                    prev.info & PIECE != 0
                        && chunk.meta[prev.tri as usize].source
                            == chunk.meta[list[end as usize].tri as usize].source
                } {
                    end += 1;
                }
                out.push(Segment {
                    tile: tile as u32,
                    chunk: c as u32,
                    start,
                    end,
                });
                start = end;
            }
        }
    }

    /// Emits the fragments of one segment of a tile in API order (by `tri`); within one
    /// triangle in row-major order.
    pub fn raster_segment(&self, seg: &Segment, mut emit: impl FnMut(Fragment)) {
        self.raster_segment_spans(seg, |s| {
            for x in s.x0..s.x1 {
                emit(Fragment {
                    x,
                    y: s.y,
                    tri: s.tri,
                    coverage: s.coverage,
                    source: s.source,
                    front_facing: s.front_facing,
                })
            }
        })
    }

    /// [`Binned::raster_segment`] as runs of pixels: the same fragments in the same order.
    pub fn raster_segment_spans(&self, seg: &Segment, mut emit: impl FnMut(Span)) {
        let tile = seg.tile as usize;
        let Some(c) = self.chunks.get(seg.chunk as usize) else {
            return;
        };
        if tile >= self.tile_count() {
            return;
        }
        let (x0, y0, x1, y1) = self.tile_rect(tile);
        if x0 >= x1 || y0 >= y1 {
            return;
        }
        let rect = [x0 as i32, y0 as i32, x1 as i32, y1 as i32];
        let si = SampleInfo::new(self.samples);
        let lo = c.tile_start[tile] as usize;
        let hi = c.tile_start[tile + 1] as usize;
        let list = &c.entries[(lo + seg.start as usize).min(hi)..(lo + seg.end as usize).min(hi)];
        let mut merge: Vec<(u32, u32, u32, u8)> = Vec::new();
        let mut i = 0;
        while i < list.len() {
            if let Some(ahead) = list.get(i + PREFETCH_AHEAD) {
                c.prefetch(ahead);
            }
            let e = list[i];
            let tri = c.base + e.tri;
            // With several samples, the fan pieces of one clipped triangle can each cover
            // some samples of a pixel on their shared diagonal: merge them into one
            // fragment (the pieces are consecutive, and share the source's planes).
            let mut j = i + 1;
            if e.info & PIECE != 0 && si.offs.len() > 1 {
                let source = c.meta[e.tri as usize].source;
                while j < list.len()
                    && list[j].info & PIECE != 0
                    && c.meta[list[j].tri as usize].source == source
                {
                    j += 1;
                }
            }
            let TriMeta {
                source,
                front_facing,
            } = c.meta[e.tri as usize];
            if j == i + 1 {
                entry_coverage(c, &e, rect, &si, |y, x0, x1, coverage| {
                    emit(Span {
                        y,
                        x0,
                        x1,
                        tri,
                        coverage,
                        source,
                        front_facing,
                    })
                });
            } else {
                // Each pixel takes the setup record of the first piece that covers it, so
                // that the result does not depend on which pieces reach the tile.
                merge.clear();
                for e in &list[i..j] {
                    let piece = c.base + e.tri;
                    entry_coverage(c, e, rect, &si, |y, x0, x1, m| {
                        merge.extend((x0..x1).map(|x| (y, x, piece, m)))
                    });
                }
                merge_pixels(&mut merge, |y, x, tri, coverage| {
                    emit(Span {
                        y,
                        x0: x,
                        x1: x + 1,
                        tri,
                        coverage,
                        source,
                        front_facing,
                    });
                });
            }
            i = j;
        }
    }
}

/// Entries ahead whose records [`Binned::raster_segment_spans`] prefetches: a tile's entries
/// are read in order, but the records they index (`meta`, `smalls`, `verts`) are scattered
/// over the whole chunk, a cache miss each on a large mesh.
const PREFETCH_AHEAD: usize = 8;

impl ChunkBins {
    /// Asks the cache for the records entry `e` indexes (a hint: no effect on results).
    #[inline(always)]
    fn prefetch(&self, e: &BinEntry) {
        prefetch(self.meta.as_ptr().wrapping_add(e.tri as usize));
        if e.info & SINGLE != 0 {
            return;
        }
        let index = (e.info & !FLAGS) as usize;
        if e.info & SMALL != 0 {
            prefetch(self.smalls.as_ptr().wrapping_add(index));
        } else {
            prefetch(self.verts.as_ptr().wrapping_add(index));
        }
    }
}

/// A unit of rasterization work: entries `start..end` of one chunk's list for one tile.
/// Segments of one tile, in order, are the tile's triangles in API order; different
/// segments of one tile can be rasterized and shaded on different threads at once.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Segment {
    pub tile: u32,
    pub chunk: u32,
    pub start: u32,
    pub end: u32,
}

/// Calls `f(y, x0, x1, mask)` for the runs of pixels of tile rectangle `rect`
/// (`[x0, y0, x1, y1)`) covered by one bin entry, in row-major order.
#[inline]
fn entry_coverage(
    c: &ChunkBins,
    e: &BinEntry,
    rect: [i32; 4],
    si: &SampleInfo,
    mut f: impl FnMut(u32, u32, u32, u8),
) {
    if e.info & SINGLE != 0 {
        let (x, y) = (
            rect[0] as u32 + (e.info & 0xff),
            rect[1] as u32 + ((e.info >> 8) & 0xff),
        );
        f(y, x, x + 1, (e.info >> 16) as u8);
        return;
    }
    if e.info & SMALL != 0 {
        c.smalls[(e.info & !FLAGS) as usize].runs(rect, |y, x0, x1| f(y, x0, x1, 1));
        return;
    }
    let v = &c.verts[(e.info & !FLAGS) as usize];
    let Some(r) = si.pixel_rect(bbox(v), rect[2], rect[3]) else {
        return;
    };
    let r = [r[0].max(rect[0]), r[1].max(rect[1]), r[2], r[3]];
    if r[0] <= r[2] && r[1] <= r[3] {
        coverage::raster(&Edges::new(v), si, r, f);
    }
}

// Recycled buffers (see [`super::pool`]).
static XY: Pool<[i32; 2]> = Pool::new();
static ZW: Pool<[f32; 2]> = Pool::new();
static TRIS: Pool<SetupTriangle> = Pool::new();
static PAIRS: Pool<(u32, BinEntry)> = Pool::new();
static ENTRIES: Pool<BinEntry> = Pool::new();
static STARTS: Pool<u32> = Pool::new();
static VERTS: Pool<[[i32; 2]; 3]> = Pool::new();
static SMALLS: Pool<SmallCoverage> = Pool::new();
static META: Pool<TriMeta> = Pool::new();

impl Drop for Binned {
    /// Hands the big buffers back to the pool for the next frame.
    fn drop(&mut self) {
        TRIS.give(std::mem::take(&mut self.tris));
        for c in self.chunks.drain(..) {
            ENTRIES.give_dirty(c.entries); // fully overwritten by the next scatter
            STARTS.give(c.tile_start);
            VERTS.give(c.verts);
            SMALLS.give(c.smalls);
            META.give(c.meta);
        }
    }
}

/// A projected vertex: snapped window position, window depth and `1/w`.
#[derive(Clone, Copy, Debug, Default)]
struct Snapped {
    x: i32,
    y: i32,
    z: f32,
    iw: f32,
}

const OUT: i32 = i32::MIN;

/// Viewport transform to fixed point. One function for every vertex, original or produced by
/// clipping, so equal inputs snap to equal outputs.
#[derive(Clone, Copy, Debug)]
struct Xform {
    /// `W * ONE / 2` and `H * ONE / 2`.
    sx: f64,
    sy: f64,
}

impl Xform {
    /// Window position (fixed point), window depth `(z/w + 1) / 2` and `1/w`.
    #[inline]
    fn project(&self, p: &[f64; 4]) -> Snapped {
        let [x, y, z, w] = *p;
        let iw = 1.0 / w;
        Snapped {
            x: round_fixed((x * iw + 1.0) * self.sx),
            y: round_fixed((1.0 - y * iw) * self.sy),
            z: (z * iw * 0.5 + 0.5) as f32,
            iw: iw as f32,
        }
    }
}

/// Round to nearest (ties up) into i32, clamped to [`COORD_LIMIT`] (NaN gives the lower
/// limit: never the `OUT` sentinel). Adding 2^31 makes the value positive so that truncation
/// is floor (faster than `f64::round` on baseline x86-64); no branches.
#[inline]
fn round_fixed(v: f64) -> i32 {
    const BIAS: f64 = 2_147_483_648.0;
    // Not `clamp`: that propagates NaN, and NaN would become the OUT sentinel.
    #[allow(clippy::manual_clamp)]
    let c = v.max(-COORD_LIMIT).min(COORD_LIMIT);
    ((c + (0.5 + BIAS)) as i64 - BIAS as i64) as i32
}

#[inline]
fn vec4_f64(p: Vec4) -> [f64; 4] {
    [p.x as f64, p.y as f64, p.z as f64, p.w as f64]
}

/// Depth plane and barycentric planes of a positively oriented snapped triangle, referred to
/// pixel `(rx, ry)`. `a[i]` holds vertex `i`'s window depth and the values of `b_k / w`
/// (`k = 0, 1, 2`); the result is the depth plane then the three barycentric planes.
///
/// The vertices are taken in canonical order (sorted by y, then x) so that the same three
/// vertices give bit-identical planes whatever their order (so the attributes may come in
/// any vertex order, as long as `v` comes in the same one). The four planes go through the
/// same f64 operations side by side ([`plane_values`]).
#[inline]
fn planes(v: &[[i32; 2]; 3], a: &[[f32; 4]; 3], rx: i32, ry: i32) -> [[f32; 3]; 4] {
    // (y, x) lexicographically, as one integer (|x| < 2^31).
    let key = |i: usize| ((v[i][1] as i64) << 32) + v[i][0] as i64;
    let (k0, k1, k2) = (key(0), key(1), key(2));
    let mut o = [0usize, 1, 2];
    let mut k = [k0, k1, k2];
    if k[1] < k[0] {
        o.swap(0, 1);
        k.swap(0, 1);
    }
    if k[2] < k[1] {
        o.swap(1, 2);
        k.swap(1, 2);
    }
    if k[1] < k[0] {
        o.swap(0, 1);
    }
    let s = 1.0 / ONE as f64;
    let [i0, i1, i2] = o;
    // Differences of snapped coordinates (below 2^31) scaled to pixels: exact, so the same
    // values as differences of the scaled coordinates.
    let d = |i: usize, j: usize, c: usize| (v[j][c] - v[i][c]) as f64 * s;
    let (dx1, dy1, dx2, dy2) = (d(i0, i1, 0), d(i0, i1, 1), d(i0, i2, 0), d(i0, i2, 1));
    let inv_d = 1.0 / (dx1 * dy2 - dx2 * dy1);
    // Offset of the reference pixel from the canonical first vertex (exact as well).
    let ox = ((rx << SUBPIXEL_BITS) - v[i0][0]) as f64 * s;
    let oy = ((ry << SUBPIXEL_BITS) - v[i0][1]) as f64 * s;
    // Coefficients of the attribute values at the three (canonical) vertices.
    let (cx1, cx2) = (dy2 * inv_d, -dy1 * inv_d);
    let (cy1, cy2) = (-dx2 * inv_d, dx1 * inv_d);
    plane_values([&a[i0], &a[i1], &a[i2]], [cx1, cx2, cy1, cy2, ox, oy])
}

/// The four planes `[a0 + gx ox + gy oy, gx, gy]` from the attribute values `a` at the three
/// canonical vertices and the coefficients `[cx1, cx2, cy1, cy2, ox, oy]`:
/// `gx = (a1 - a0) cx1 + (a2 - a0) cx2`, `gy` alike, all in f64.
#[cfg(any(test, not(target_arch = "x86_64")))]
#[inline]
fn plane_values_scalar(a: [&[f32; 4]; 3], c: [f64; 6]) -> [[f32; 3]; 4] {
    let [cx1, cx2, cy1, cy2, ox, oy] = c;
    let mut out = [[0.0f32; 3]; 4];
    for (k, out) in out.iter_mut().enumerate() {
        let (a0, a1, a2) = (a[0][k] as f64, a[1][k] as f64, a[2][k] as f64);
        let (da1, da2) = (a1 - a0, a2 - a0);
        let gx = da1 * cx1 + da2 * cx2;
        let gy = da1 * cy1 + da2 * cy2;
        *out = [(a0 + gx * ox + gy * oy) as f32, gx as f32, gy as f32];
    }
    out
}

#[cfg(not(target_arch = "x86_64"))]
#[inline]
fn plane_values(a: [&[f32; 4]; 3], c: [f64; 6]) -> [[f32; 3]; 4] {
    plane_values_scalar(a, c)
}

/// `plane_values_scalar` (the scalar reference, in tests and off x86) with two attributes
/// per SSE2 register: the same IEEE operations in the same order (Rust does not contract
/// `a * b + c`), so the same bits, for half the instructions (a large part of setting up a
/// small triangle).
#[cfg(target_arch = "x86_64")]
#[inline]
fn plane_values(a: [&[f32; 4]; 3], c: [f64; 6]) -> [[f32; 3]; 4] {
    use std::arch::x86_64::{
        _mm_add_pd, _mm_cvtpd_ps, _mm_cvtps_pd, _mm_loadu_ps, _mm_movehl_ps, _mm_movelh_ps,
        _mm_mul_pd, _mm_set1_pd, _mm_shuffle_ps, _mm_storeu_ps, _mm_sub_pd, _mm_unpackhi_ps,
        _mm_unpacklo_ps,
    };
    let mut out = [0.0f32; 12];
    // SAFETY: SSE2 is part of the x86_64 baseline; the loads read the three `[f32; 4]`
    // behind the references and the stores write the 12 floats of `out`, all in bounds.
    unsafe {
        let (cx1, cx2, cy1, cy2) = (
            _mm_set1_pd(c[0]),
            _mm_set1_pd(c[1]),
            _mm_set1_pd(c[2]),
            _mm_set1_pd(c[3]),
        );
        let (ox, oy) = (_mm_set1_pd(c[4]), _mm_set1_pd(c[5]));
        // Attributes 0, 1 (`lo`) and 2, 3 (`hi`) of each vertex, widened to f64.
        let wide = |a: &[f32; 4]| {
            let v = _mm_loadu_ps(a.as_ptr());
            (_mm_cvtps_pd(v), _mm_cvtps_pd(_mm_movehl_ps(v, v)))
        };
        let (a0, a1, a2) = (wide(a[0]), wide(a[1]), wide(a[2]));
        let half = |a0, a1, a2| {
            let (da1, da2) = (_mm_sub_pd(a1, a0), _mm_sub_pd(a2, a0));
            let gx = _mm_add_pd(_mm_mul_pd(da1, cx1), _mm_mul_pd(da2, cx2));
            let gy = _mm_add_pd(_mm_mul_pd(da1, cy1), _mm_mul_pd(da2, cy2));
            let c = _mm_add_pd(_mm_add_pd(a0, _mm_mul_pd(gx, ox)), _mm_mul_pd(gy, oy));
            (_mm_cvtpd_ps(c), _mm_cvtpd_ps(gx), _mm_cvtpd_ps(gy))
        };
        let (c_lo, gx_lo, gy_lo) = half(a0.0, a1.0, a2.0);
        let (c_hi, gx_hi, gy_hi) = half(a0.1, a1.1, a2.1);
        // [c, gx, gy] of the four attributes, then interleaved into `out`.
        let c = _mm_movelh_ps(c_lo, c_hi);
        let gx = _mm_movelh_ps(gx_lo, gx_hi);
        let gy = _mm_movelh_ps(gy_lo, gy_hi);
        let t0 = _mm_unpacklo_ps(c, gx); // c0 gx0 c1 gx1
        let t1 = _mm_unpackhi_ps(c, gx); // c2 gx2 c3 gx3
        let u0 = _mm_shuffle_ps::<0b11_10_00_00>(gy, t0); // gy0 gy0 c1 gx1
        let o0 = _mm_shuffle_ps::<0b10_00_01_00>(t0, u0); // c0 gx0 gy0 c1
        let u1 = _mm_shuffle_ps::<0b01_01_11_11>(t0, gy); // gx1 gx1 gy1 gy1
        let o1 = _mm_shuffle_ps::<0b01_00_10_00>(u1, t1); // gx1 gy1 c2 gx2
        let u2 = _mm_shuffle_ps::<0b11_10_11_10>(t1, gy); // c3 gx3 gy2 gy3
        let o2 = _mm_shuffle_ps::<0b11_01_00_10>(u2, u2); // gy2 c3 gx3 gy3
        _mm_storeu_ps(out.as_mut_ptr(), o0);
        _mm_storeu_ps(out.as_mut_ptr().add(4), o1);
        _mm_storeu_ps(out.as_mut_ptr().add(8), o2);
    }
    let p = |k: usize| [out[k], out[k + 1], out[k + 2]];
    [p(0), p(3), p(6), p(9)]
}

/// Everything a worker needs, shared read-only.
struct Ctx<'a> {
    positions: &'a [Vec4],
    indices: &'a [[u32; 3]],
    /// Step 1 output, per vertex: the snapped position, or `[OUT, outcode]` outside a clip
    /// plane (split from `zw` so that the hot reject loop reads half the memory).
    xy: &'a [[i32; 2]],
    /// Window depth and `1/w` per vertex.
    zw: &'a [[f32; 2]],
    planes: Planes,
    xf: Xform,
    si: SampleInfo,
    /// Viewport in pixels (clamped to [`MAX_VIEWPORT`]).
    w: i32,
    h: i32,
    /// log2 of the tile size.
    tile_shift: u32,
    tiles_x: u32,
    ntiles: usize,
    cull: CullMode,
    /// `FrontFace::Ccw`: front-facing when counter-clockwise on screen.
    ccw_front: bool,
    plane_setup: PlaneSetup,
    /// Set up for [`Prepared::setup_flat`]: each setup triangle's covered runs go straight
    /// to [`ChunkOut::spans`], in API order, instead of into per-tile bin entries.
    flat: bool,
}

/// Triangles per batch of the reject loop (a power of two).
const BATCH: usize = 256;

/// A triangle kept by [`Ctx::reject`]: its index, whether it is `special` (an index out of
/// range, or a vertex outside a clip plane: see [`Ctx::setup_special`]), and, when it is
/// not, its pixel rectangle. The flag spares setup a second bounds check of three indices
/// and three clip tests (about 20 instructions per kept triangle, for one store each in the
/// reject loop).
#[derive(Clone, Copy, Debug, Default)]
struct Kept {
    t: u32,
    special: bool,
    r: [i32; 4],
}

/// What one chunk of triangles produced.
struct ChunkOut {
    tris: Vec<SetupTriangle>,
    verts: Vec<[[i32; 2]; 3]>,
    smalls: Vec<SmallCoverage>,
    meta: Vec<TriMeta>,
    /// `(tile, entry)` in triangle order.
    bins: Vec<(u32, BinEntry)>,
    /// Unbinned ([`Ctx::flat`]): the covered runs, in triangle order.
    spans: Vec<Span>,
    /// Setup triangles so far (the next one's index).
    setups: u32,
    rejected: u64,
}

/// What setup found of a triangle's coverage.
enum SetupCoverage {
    /// One covered pixel and its sample mask.
    Single { x: i32, y: i32, mask: u8 },
    /// A small one-sample triangle's covered pixels.
    Small(SmallCoverage),
    /// Rasterized in the tiles from its vertices.
    Vertices,
}

/// Coverage of a tiny triangle (pixel rectangle of at most 2x2).
enum Tiny {
    Empty,
    Single(i32, i32, u8),
    Several,
}

impl Ctx<'_> {
    /// Facing from the snapped signed area (`a2 < 0`: counter-clockwise on screen, see
    /// [`coverage::area2`]); `None` when culled.
    #[inline]
    fn facing(&self, a2_negative: bool) -> Option<bool> {
        let front = a2_negative == self.ccw_front;
        match (self.cull, front) {
            (CullMode::Back, false) | (CullMode::Front, true) => None,
            _ => Some(front),
        }
    }

    /// Exact sample test for triangles whose pixel rectangle is at most 2x2: most triangles
    /// of a dense mesh whose bounding box reaches a sample still miss it, and are dropped here
    /// instead of costing a setup record, a bin entry and a rasterization; most others cover
    /// one pixel, whose mask then goes straight into the bin entry.
    #[inline]
    fn tiny(&self, e: &Edges, r: [i32; 4]) -> Tiny {
        let mut found = Tiny::Empty;
        for y in r[1]..=r[3] {
            for x in r[0]..=r[2] {
                let m = e.mask_at(
                    &self.si,
                    (x as i64) << SUBPIXEL_BITS,
                    (y as i64) << SUBPIXEL_BITS,
                );
                if m != 0 {
                    if let Tiny::Single(..) = found {
                        return Tiny::Several;
                    }
                    found = Tiny::Single(x, y, m);
                }
            }
        }
        found
    }

    /// Sets up a range of triangles, in batches: a branch-free reject pass first, then the
    /// full setup of the few that remain.
    ///
    /// `LEAN`: the context is flat, with one sample and no planes (counting passes, see
    /// [`Prepared::setup_flat`]). The setup path is then compiled apart, with the branches
    /// of the other configurations gone: fewer values live across the triangle loop, fewer
    /// kept on the stack (the 871K dragon @2048: 351 -> 318 M instructions in this loop,
    /// callgrind).
    fn run<const LEAN: bool>(&self, range: std::ops::Range<usize>, out: &mut ChunkOut) {
        debug_assert!(!LEAN || (self.flat && self.plane_setup == PlaneSetup::Skip));
        debug_assert!(!LEAN || self.si.offs.len() == 1);
        let mut keep = [Kept::default(); BATCH];
        let mut t = range.start;
        while t < range.end {
            let end = (t + BATCH).min(range.end);
            let n = if self.xy.is_empty() {
                0
            } else {
                self.reject(t..end, &mut keep)
            };
            if self.xy.is_empty() {
                out.rejected += (end - t) as u64; // every index is out of range
            }
            for k in &keep[..n] {
                self.setup::<LEAN>(k, out);
            }
            t = end;
        }
    }

    /// The hot loop over all triangles (`xy` not empty, `range.len() <= BATCH`): writes to
    /// `keep` the triangles whose snapped bounding box reaches a sample (or that need
    /// clipping or have bad indices, handled by [`Ctx::setup`]) and returns their number.
    ///
    /// Branch-free and minimal: whether a sub-pixel triangle's box reaches a sample is a
    /// coin toss that a branch predictor cannot learn, and without branches the CPU overlaps
    /// the vertex loads of many triangles. Everything else (area, culling, exact coverage) is
    /// done only for the triangles kept. The pixel rectangle computed here goes along with
    /// the triangle, so that setup does not compute it again.
    #[inline(never)]
    fn reject(&self, range: std::ops::Range<usize>, keep: &mut [Kept; BATCH]) -> usize {
        let xy = self.xy;
        let last = xy.len() - 1;
        let si = &self.si;
        let (w1, h1) = (self.w - 1, self.h - 1);
        let mut n = 0;
        for (t, tri) in range.clone().zip(&self.indices[range]) {
            let [ia, ib, ic] = *tri;
            let (ia, ib, ic) = (ia as usize, ib as usize, ic as usize);
            let bad_index = (ia > last) | (ib > last) | (ic > last);
            let (a, b, c) = (xy[ia.min(last)], xy[ib.min(last)], xy[ic.min(last)]);
            // OUT is i32::MIN: the minimum x is OUT iff a vertex needs clipping.
            let xmin = a[0].min(b[0]).min(c[0]);
            let special = bad_index | (xmin == OUT);
            // As [`SampleInfo::pixel_rect`]. Coordinates are within [`COORD_LIMIT`], so
            // nothing wraps, except with OUT: then the triangle is special, kept anyway, and
            // its rectangle unused.
            let x0 = xmin.wrapping_add(ONE - 1 - si.max_x) >> SUBPIXEL_BITS;
            let x1 = a[0].max(b[0]).max(c[0]).wrapping_sub(si.min_x) >> SUBPIXEL_BITS;
            let y0 = (a[1].min(b[1]).min(c[1]) + (ONE - 1 - si.max_y)) >> SUBPIXEL_BITS;
            let y1 = (a[1].max(b[1]).max(c[1]) - si.min_y) >> SUBPIXEL_BITS;
            let r = [x0.max(0), y0.max(0), x1.min(w1), y1.min(h1)];
            let reaches = (r[0] <= r[2]) & (r[1] <= r[3]);
            // `n < BATCH` (one per triangle of the batch at most): the mask only spares
            // the bounds check.
            keep[n & (BATCH - 1)] = Kept {
                t: t as u32,
                special,
                r,
            };
            n += usize::from(special | reaches);
        }
        n
    }

    /// Setup of a triangle that [`Ctx::reject`] kept as special: an index out of range
    /// (counted and dropped) or a vertex outside a clip plane ([`Ctx::clipped`]).
    #[cold]
    #[inline(never)]
    fn setup_special(&self, t: u32, out: &mut ChunkOut) {
        let [ia, ib, ic] = self.indices[t as usize];
        let (Some(&a), Some(&b), Some(&c)) = (
            self.xy.get(ia as usize),
            self.xy.get(ib as usize),
            self.xy.get(ic as usize),
        ) else {
            out.rejected += 1;
            return;
        };
        self.clipped(t, [ia, ib, ic], [a, b, c], out);
    }

    /// Full setup of one triangle that passed [`Ctx::reject`].
    #[inline]
    fn setup<const LEAN: bool>(&self, k: &Kept, out: &mut ChunkOut) {
        if k.special {
            self.setup_special(k.t, out);
            return;
        }
        let t = k.t as usize;
        // SAFETY: `reject` read `indices[t]` (`t` is in its range, within `indices`) and
        // found its three indices within `xy` (the triangle is not special).
        let ([ia, ib, ic], a, b, c) = unsafe {
            let i = *self.indices.get_unchecked(t);
            let xy = |j: u32| *self.xy.get_unchecked(j as usize);
            (i, xy(i[0]), xy(i[1]), xy(i[2]))
        };
        debug_assert!(a[0] != OUT && b[0] != OUT && c[0] != OUT);
        // Not special, so `reject` kept it for reaching a sample: `r` is its pixel rectangle.
        let r = k.r;
        let v = [a, b, c];
        let a2 = area2(&v);
        if a2 == 0 {
            return;
        }
        let Some(front) = self.facing(a2 < 0) else {
            return;
        };
        // Positively oriented for coverage. The planes do not depend on the vertex order
        // (see [`planes`]), so their attributes stay in input order: vertex `i` carries
        // `1/w` as `b_i / w`.
        let pv = v;
        let v = if a2 > 0 { v } else { [a, c, b] };
        let Some(cov) = self.coverage::<LEAN>(&v, r) else {
            return;
        };
        // Loaded only for the planes: three more scattered loads per triangle otherwise.
        let attrs = || {
            let [za, zb, zc] = [ia, ib, ic].map(|i| self.zw[i as usize]);
            [
                [za[0], za[1], 0.0, 0.0],
                [zb[0], 0.0, zb[1], 0.0],
                [zc[0], 0.0, 0.0, zc[1]],
            ]
        };
        self.finish::<LEAN>(out, t as u32, front, false, cov, v, r, (&pv, attrs));
    }

    /// Slow path: a vertex is outside a clip plane (or not finite).
    #[cold]
    fn clipped(&self, source: u32, idx: [u32; 3], s: [[i32; 2]; 3], out: &mut ChunkOut) {
        let oc = s.map(|s| if s[0] == OUT { s[1] as u32 } else { 0 });
        if (oc[0] | oc[1] | oc[2]) & NON_FINITE != 0 {
            out.rejected += 1;
            return;
        }
        if oc[0] & oc[1] & oc[2] != 0 {
            return; // entirely outside one plane
        }
        let tri = [0, 1, 2].map(|k| {
            let mut b = [0.0; 3];
            b[k] = 1.0;
            ClipVert {
                p: vec4_f64(self.positions[idx[k] as usize]),
                b,
            }
        });
        let poly = clip::clip_triangle(&self.planes, tri, oc[0] | oc[1] | oc[2]);
        let n = poly.n;
        if n < 3 {
            return;
        }
        let mut pts = [[0i64; 2]; MAX_POLY + 1];
        let mut proj = [Snapped::default(); MAX_POLY + 1];
        for j in 0..n {
            proj[j] = self.xf.project(&poly.v[j].p);
            pts[j] = [proj[j].x as i64, proj[j].y as i64];
        }
        // Facing from the whole snapped polygon (shoelace), so all pieces agree.
        let mut a2: i128 = 0;
        for j in 0..n {
            let (p, q) = (pts[j], pts[(j + 1) % n]);
            a2 += p[0] as i128 * q[1] as i128 - q[0] as i128 * p[1] as i128;
        }
        if a2 == 0 {
            return;
        }
        let Some(front) = self.facing(a2 < 0) else {
            return;
        };
        let mut hull = [0usize; MAX_POLY + 1];
        let m = clip::convex_hull(&pts[..n], &mut hull);
        let first_span = out.spans.len();
        for i in 1..m.saturating_sub(1) {
            let h = [hull[0], hull[i], hull[i + 1]];
            let v = h.map(|j| [proj[j].x, proj[j].y]);
            let Some(r) = self.si.pixel_rect(bbox(&v), self.w, self.h) else {
                continue;
            };
            if area2(&v) <= 0 {
                continue;
            }
            let Some(cov) = self.coverage::<false>(&v, r) else {
                continue;
            };
            let attrs = || {
                h.map(|j| {
                    let b = poly.v[j].b;
                    let iw = proj[j].iw as f64;
                    [
                        proj[j].z,
                        (b[0] * iw) as f32,
                        (b[1] * iw) as f32,
                        (b[2] * iw) as f32,
                    ]
                })
            };
            self.finish::<false>(out, source, front, m > 3, cov, v, r, (&v, attrs));
        }
        if self.flat && m > 3 && self.si.offs.len() > 1 {
            merge_piece_spans(&mut out.spans, first_span);
        }
    }

    /// Exact coverage of small triangles (pixel rectangle `r` of at most 8x8 with one
    /// sample, 2x2 with several): `None` when no sample is covered.
    // Always inlined: returned from a call, the enum went through the stack in narrow
    // stores read back as one wide load, a store-forwarding stall (a fifth of `chunk`'s
    // samples in `perf` on the 871K dragon at 2048).
    #[inline(always)]
    fn coverage<const LEAN: bool>(&self, v: &[[i32; 2]; 3], r: [i32; 4]) -> Option<SetupCoverage> {
        let single = |x: i32, y: i32, mask: u8| SetupCoverage::Single { x, y, mask };
        if r[0] == r[2] && r[1] == r[3] {
            let m = coverage::pixel_mask(v, &self.si, r[0], r[1]);
            return (m != 0).then(|| single(r[0], r[1], m));
        }
        let (w, h) = (r[2] - r[0], r[3] - r[1]);
        if (LEAN || self.si.offs.len() == 1) && w < 8 && h < 8 {
            let bits = if !coverage::block_fits(r, self.w, self.h) {
                // Clamped to the viewport (rare): the box may be too large for `i32`.
                coverage::block_mask_wide(&Edges::new(v), &self.si, r)
            } else if w < 4 && h < 4 {
                coverage::block_mask(v, &self.si, r)
            } else {
                coverage::block_mask8(v, &self.si, r)
            };
            // Not `count_ones`: without POPCNT (not in the x86_64 baseline) that is a dozen
            // instructions.
            return if bits == 0 {
                None
            } else if bits & (bits - 1) == 0 {
                let k = bits.trailing_zeros() as i32;
                Some(single(r[0] + k % 8, r[1] + k / 8, 1))
            } else {
                Some(SetupCoverage::Small(SmallCoverage {
                    x: r[0],
                    y: r[1],
                    bits,
                }))
            };
        }
        if w <= 1 && h <= 1 {
            return match self.tiny(&Edges::new(v), r) {
                Tiny::Empty => None,
                Tiny::Single(x, y, m) => Some(single(x, y, m)),
                Tiny::Several => Some(SetupCoverage::Vertices),
            };
        }
        Some(SetupCoverage::Vertices)
    }

    /// Stores the setup triangle and bins it into the tiles its
    /// pixel rectangle `r` touches (skipping, for large triangles, tiles that lie entirely
    /// outside one edge). `v` is positively oriented; the planes come from `pv`, the same
    /// vertices in the order of their attributes `attrs` (see [`planes`]).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn finish<const LEAN: bool>(
        &self,
        out: &mut ChunkOut,
        source: u32,
        front_facing: bool,
        piece: bool,
        cov: SetupCoverage,
        v: [[i32; 2]; 3],
        r: [i32; 4],
        (pv, attrs): (&[[i32; 2]; 3], impl FnOnce() -> [[f32; 4]; 3]),
    ) {
        let sh = self.tile_shift;
        let tri = out.setups;
        out.setups += 1;
        if !LEAN && !self.flat {
            out.meta.push(TriMeta {
                source,
                front_facing,
            });
        }
        if !LEAN && self.plane_setup == PlaneSetup::Compute {
            let [depth, b0, b1, b2] = planes(pv, &attrs(), r[0], r[1]);
            out.tris.push(SetupTriangle {
                source,
                front_facing,
                rx: r[0],
                ry: r[1],
                depth,
                bary: [b0, b1, b2],
            });
        }
        let piece = if piece { PIECE } else { 0 };
        if LEAN || self.flat {
            let spans = &mut out.spans;
            let mut emit = |y: u32, x0: u32, x1: u32, coverage: u8| {
                spans.push(Span {
                    y,
                    x0,
                    x1,
                    tri,
                    coverage,
                    source,
                    front_facing,
                })
            };
            match cov {
                SetupCoverage::Single { x, y, mask } => {
                    emit(y as u32, x as u32, x as u32 + 1, mask)
                }
                SetupCoverage::Small(small) => {
                    // At most one run per row of the block: room for all of them first, so
                    // that a run is seven stores, with no capacity check (more than a
                    // third of the instructions per run of the 871K dragon @2048).
                    spans.reserve(8);
                    let base = spans.len();
                    let room = &mut spans.spare_capacity_mut()[..8];
                    let mut n = 0;
                    small.convex_runs(|y, x0, x1| {
                        room[n & 7].write(Span {
                            y,
                            x0,
                            x1,
                            tri,
                            coverage: 1,
                            source,
                            front_facing,
                        });
                        n += 1;
                    });
                    debug_assert!(n <= 8);
                    // SAFETY: `convex_runs` calls back once per non-empty row of the 8-row
                    // block at most (it clears a row's byte as it emits its run), so
                    // `n <= 8` and the first `n` spare elements were written above.
                    unsafe { spans.set_len(base + n) };
                }
                // `r` is the pixel rectangle inside the viewport (inclusive).
                SetupCoverage::Vertices => coverage::raster(&Edges::new(&v), &self.si, r, emit),
            }
            return;
        }
        let (tx0, ty0, tx1, ty1) = (r[0] >> sh, r[1] >> sh, r[2] >> sh, r[3] >> sh);
        match cov {
            SetupCoverage::Single { x, y, mask } => {
                let tmask = (1 << sh) - 1;
                let info =
                    SINGLE | (mask as u32) << 16 | ((y & tmask) as u32) << 8 | (x & tmask) as u32;
                let tile = (y >> sh) as u32 * self.tiles_x + (x >> sh) as u32;
                // Only the tile of the covered pixel (the box may straddle tiles).
                out.bins.push((
                    tile,
                    BinEntry {
                        tri,
                        info: info | piece,
                    },
                ));
                return;
            }
            SetupCoverage::Small(small) => {
                out.smalls.push(small);
                let index = out.smalls.len() as u32 - 1;
                debug_assert!(index & FLAGS == 0, "a chunk of over 2^29 triangles");
                let info = index | SMALL | piece;
                if tx0 == tx1 && ty0 == ty1 {
                    // The whole pixel rectangle is in one tile (the common case).
                    out.bins.push((
                        ty0 as u32 * self.tiles_x + tx0 as u32,
                        BinEntry { tri, info },
                    ));
                    return;
                }
                // Only the tiles holding a covered pixel.
                for ty in ty0..=ty1 {
                    for tx in tx0..=tx1 {
                        let rect = [tx << sh, ty << sh, (tx + 1) << sh, (ty + 1) << sh];
                        let mut any = false;
                        small.runs(rect, |_, _, _| any = true);
                        if any {
                            out.bins.push((
                                ty as u32 * self.tiles_x + tx as u32,
                                BinEntry { tri, info },
                            ));
                        }
                    }
                }
                return;
            }
            SetupCoverage::Vertices => {}
        }
        out.verts.push(v);
        let index = out.verts.len() as u32 - 1;
        debug_assert!(index & FLAGS == 0, "a chunk of over 2^29 triangles");
        let info = index | piece;
        if tx0 == tx1 && ty0 == ty1 {
            out.bins.push((
                ty0 as u32 * self.tiles_x + tx0 as u32,
                BinEntry { tri, info },
            ));
            return;
        }
        let e = Edges::new(&v);
        let ts = 1 << sh;
        let one = ONE as i64;
        for ty in ty0..=ty1 {
            let y0 = (ty * ts) as i64 * one;
            let y1 = ((ty + 1) * ts).min(self.h) as i64 * one;
            for tx in tx0..=tx1 {
                let x0 = (tx * ts) as i64 * one;
                let x1 = ((tx + 1) * ts).min(self.w) as i64 * one;
                if !e.rect_outside(x0, y0, x1, y1) {
                    out.bins
                        .push((ty as u32 * self.tiles_x + tx as u32, BinEntry { tri, info }));
                }
            }
        }
    }

    /// Sets up one chunk of triangles and sorts its bin entries by tile (stable).
    fn chunk(&self, range: std::ops::Range<usize>) -> (Vec<SetupTriangle>, ChunkBins, u64) {
        let mut out = ChunkOut {
            tris: TRIS.take(),
            verts: VERTS.take(),
            smalls: SMALLS.take(),
            meta: META.take(),
            bins: PAIRS.take(),
            spans: Vec::new(),
            setups: 0,
            rejected: 0,
        };
        self.run::<false>(range, &mut out);
        let mut tile_start = STARTS.take();
        tile_start.resize(self.ntiles + 1, 0);
        for &(tile, _) in &out.bins {
            tile_start[tile as usize + 1] += 1;
        }
        for i in 0..self.ntiles {
            tile_start[i + 1] += tile_start[i];
        }
        let mut cursor = tile_start.clone();
        let mut entries = ENTRIES.take();
        entries.resize(out.bins.len(), BinEntry::default());
        for &(tile, e) in &out.bins {
            let k = &mut cursor[tile as usize];
            entries[*k as usize] = e;
            *k += 1;
        }
        PAIRS.give(out.bins);
        (
            out.tris,
            ChunkBins {
                base: 0,
                tile_start,
                entries,
                verts: out.verts,
                smalls: out.smalls,
                meta: out.meta,
            },
            out.rejected,
        )
    }
}

/// Runs `f(i)` for `i in 0..n` on up to `threads` threads (the calling thread included),
/// item `i` going to thread `i % threads`, and returns the results in index order.
fn par_map<T: Send>(n: usize, threads: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let threads = threads.clamp(1, n.max(1));
    if threads == 1 {
        return (0..n).map(f).collect();
    }
    let f = &f;
    let work = move |k: usize| {
        (k..n)
            .step_by(threads)
            .map(|i| (i, f(i)))
            .collect::<Vec<_>>()
    };
    let mut parts: Vec<Vec<(usize, T)>> = crate::sync::pool::broadcast(threads, work);
    let mut slots: Vec<Option<T>> = (0..n).map(|_| None).collect();
    for part in parts.iter_mut() {
        for (i, t) in part.drain(..) {
            slots[i] = Some(t);
        }
    }
    slots
        .into_iter()
        .map(|t| t.expect("every item computed"))
        .collect()
}

/// Step 1 for a slice of vertices.
fn project_vertices(
    planes: &Planes,
    xf: &Xform,
    src: &[Vec4],
    xy: &mut [[i32; 2]],
    zw: &mut [[f32; 2]],
) -> bool {
    let mut non_finite = false;
    for ((xy, zw), &p) in xy.iter_mut().zip(zw.iter_mut()).zip(src) {
        // Finite as f32 iff finite as f64: tested on the f32 bits (exponent not all ones),
        // a few instructions for the four instead of a few each.
        let finite = p.to_array().iter().fold(true, |ok, c| {
            ok & (c.to_bits() & 0x7f80_0000 != 0x7f80_0000)
        });
        non_finite |= !finite;
        let p = vec4_f64(p);
        let oc = if finite {
            planes.outcode_finite(&p)
        } else {
            NON_FINITE
        };
        if oc != 0 {
            *xy = [OUT, oc as i32];
            *zw = [0.0; 2];
        } else {
            let s = xf.project(&p);
            *xy = [s.x, s.y];
            *zw = [s.z, s.iw];
        }
    }
    non_finite
}

/// The tile size used for a requested one: rounded up to a power of two within
/// [`MIN_TILE`]..=[`MAX_TILE`] (so tile coordinates are shifts, and a pixel's position in its
/// tile fits in a byte of a bin entry).
pub fn effective_tile_size(requested: u32) -> u32 {
    requested.clamp(MIN_TILE, MAX_TILE).next_power_of_two()
}

/// Smallest tile size.
pub const MIN_TILE: u32 = 8;
/// Largest tile size.
pub const MAX_TILE: u32 = 256;

/// Clips, culls, snaps and bins triangles, with their planes ([`bin_triangles_with`] and
/// [`PlaneSetup::Compute`]). Uses up to `threads` threads.
pub fn bin_triangles(
    positions: &[Vec4],
    indices: &[[u32; 3]],
    state: &RasterState,
    viewport: Viewport,
    threads: usize,
) -> Binned {
    bin_triangles_with(
        positions,
        indices,
        state,
        viewport,
        threads,
        PlaneSetup::Compute,
    )
}

/// Clips, culls, snaps and bins triangles. Uses up to `threads` threads.
/// `positions` are clip-space vertex positions, `indices` the triangles in API order.
/// Triangles with a NaN or infinite coordinate are dropped (and counted in [`Binned::rejected`]),
/// so are triangles with an index out of range (the caller should validate meshes first).
pub fn bin_triangles_with(
    positions: &[Vec4],
    indices: &[[u32; 3]],
    state: &RasterState,
    viewport: Viewport,
    threads: usize,
    plane_setup: PlaneSetup,
) -> Binned {
    prepare(positions, indices, state, viewport, threads, plane_setup).bin(threads)
}

/// Triangles whose vertices are projected and snapped (step 1 of [`bin_triangles`]), ready
/// for setup: binned into tiles ([`Prepared::bin`]), or set up chunk by chunk and
/// rasterized straight away, unbinned ([`Prepared::setup_flat`]), when the order in which
/// the pixels of different triangles are visited does not matter.
pub struct Prepared<'a> {
    positions: &'a [Vec4],
    indices: &'a [[u32; 3]],
    /// Per vertex, as [`Ctx::xy`] and [`Ctx::zw`] (recycled buffers, given back on drop).
    xy: Vec<[i32; 2]>,
    zw: Vec<[f32; 2]>,
    planes: Planes,
    xf: Xform,
    samples: SampleCount,
    viewport: Viewport,
    tile_size: u32,
    cull: CullMode,
    ccw_front: bool,
    plane_setup: PlaneSetup,
    /// A vertex was NaN or infinite.
    non_finite: bool,
}

/// Projects and snaps every vertex (step 1 of [`bin_triangles`]), on up to `threads`
/// threads.
pub fn prepare<'a>(
    positions: &'a [Vec4],
    indices: &'a [[u32; 3]],
    state: &RasterState,
    viewport: Viewport,
    threads: usize,
    plane_setup: PlaneSetup,
) -> Prepared<'a> {
    let threads = threads.max(1);
    let w = viewport.width.min(MAX_VIEWPORT);
    let h = viewport.height.min(MAX_VIEWPORT);
    let planes = Planes::new(w.max(1), h.max(1));
    let xf = Xform {
        sx: viewport.width as f64 * (ONE / 2) as f64,
        sy: viewport.height as f64 * (ONE / 2) as f64,
    };
    // Recycled with stale contents: every element is overwritten below.
    let mut xy = XY.take();
    let mut zw = ZW.take();
    xy.resize(positions.len(), [0; 2]);
    zw.resize(positions.len(), [0.0; 2]);
    let vthreads = threads.min(positions.len() / 8192).max(1);
    let non_finite = if vthreads == 1 {
        project_vertices(&planes, &xf, positions, &mut xy, &mut zw)
    } else {
        let per = positions.len().div_ceil(vthreads);
        let parts: Vec<_> = xy
            .chunks_mut(per)
            .zip(zw.chunks_mut(per))
            .zip(positions.chunks(per))
            .collect();
        crate::sync::pool::broadcast_each(parts, |((xy, zw), src)| {
            project_vertices(&planes, &xf, src, xy, zw)
        })
        .contains(&true)
    };
    Prepared {
        positions,
        indices,
        xy,
        zw,
        planes,
        xf,
        samples: state.samples,
        viewport,
        tile_size: effective_tile_size(state.tile_size),
        cull: state.cull,
        ccw_front: state.front_face == FrontFace::Ccw,
        plane_setup,
        non_finite,
    }
}

impl Drop for Prepared<'_> {
    fn drop(&mut self) {
        XY.give_dirty(std::mem::take(&mut self.xy));
        ZW.give_dirty(std::mem::take(&mut self.zw));
    }
}

impl<'a> Prepared<'a> {
    /// Input triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len()
    }

    /// Whether every triangle is well formed: every vertex finite and every index in
    /// range. The unbinned path relies on it (a mesh that is not goes through
    /// [`Prepared::bin`], which counts and drops the bad triangles).
    /// Uses up to `threads` threads: the 871K-triangle dragon's indices are 10 MB, read
    /// once per draw.
    pub fn well_formed(&self, threads: usize) -> bool {
        /// Below this a thread costs more than it saves.
        const PER_THREAD: usize = 1 << 16;
        // A maximum over all indices: branch-free and vectorised.
        let max = crate::sync::pool::map_parts(self.indices, threads, PER_THREAD, |part| {
            part.iter()
                .fold(0u32, |m, t| m.max(t[0]).max(t[1]).max(t[2]))
        })
        .into_iter()
        .max()
        .unwrap_or(0);
        !self.non_finite && (self.indices.is_empty() || (max as usize) < self.positions.len())
    }

    fn ctx(&self, flat: bool) -> Ctx<'_> {
        let w = self.viewport.width.min(MAX_VIEWPORT);
        let h = self.viewport.height.min(MAX_VIEWPORT);
        let tiles_x = self.viewport.width.div_ceil(self.tile_size);
        let tiles_y = self.viewport.height.div_ceil(self.tile_size);
        Ctx {
            positions: self.positions,
            indices: self.indices,
            xy: &self.xy,
            zw: &self.zw,
            planes: self.planes,
            xf: self.xf,
            si: SampleInfo::new(self.samples),
            w: w as i32,
            h: h as i32,
            tile_shift: self.tile_size.trailing_zeros(),
            tiles_x,
            ntiles: tiles_x as usize * tiles_y as usize,
            cull: self.cull,
            ccw_front: self.ccw_front,
            plane_setup: self.plane_setup,
            flat,
        }
    }

    /// Sets up input triangles `range` (clipped, culled, with their coverage and, unless
    /// skipped, planes) and rasterizes them into `out`, unbinned: each setup triangle's
    /// covered runs go to [`FlatChunk::spans`], in API order. Setup indices (`Span::tri`)
    /// are relative to the chunk ([`FlatChunk::tris`]).
    pub fn setup_flat(&self, range: std::ops::Range<usize>, out: &mut FlatChunk) {
        let range = range.start.min(self.indices.len())..range.end.min(self.indices.len());
        let mut o = ChunkOut {
            tris: std::mem::take(&mut out.tris),
            verts: Vec::new(),
            smalls: Vec::new(),
            meta: Vec::new(),
            bins: Vec::new(),
            spans: std::mem::take(&mut out.spans),
            setups: 0,
            rejected: 0,
        };
        o.tris.clear();
        o.spans.clear();
        let ctx = self.ctx(true);
        if ctx.ntiles > 0 {
            if ctx.plane_setup == PlaneSetup::Skip && ctx.si.offs.len() == 1 {
                ctx.run::<true>(range, &mut o);
            } else {
                ctx.run::<false>(range, &mut o);
            }
        }
        out.tris = o.tris;
        out.spans = o.spans;
        out.rejected = o.rejected;
    }

    /// Steps 2 and 3 of [`bin_triangles`]: sets up and bins every triangle.
    pub fn bin(&self, threads: usize) -> Binned {
        let threads = threads.max(1);
        let (positions, indices, viewport) = (self.positions, self.indices, self.viewport);
        let ctx = self.ctx(false);
        let (tiles_x, ntiles) = (ctx.tiles_x, ctx.ntiles);
        let tiles_y = viewport.height.div_ceil(self.tile_size);
        let n = indices.len();
        // One contiguous chunk per thread: the first chunk's buffer becomes `tris` and only the
        // others are appended (copying setup records is a large part of the memory traffic).
        // Rejecting off-screen or sub-pixel triangles is cheap, so equal ranges balance well.
        // At most 2^25 input triangles a chunk: with clipping's fan pieces (at most
        // `MAX_POLY - 2` each) a chunk's setup indices stay below the bin entry's flag bits.
        let chunk = n.div_ceil(threads).clamp(4096, MAX_CHUNK);
        let nchunks = n.div_ceil(chunk);
        let empty = |rejected: u64| {
            let bins = ChunkBins {
                base: 0,
                tile_start: vec![0; ntiles + 1],
                entries: Vec::new(),
                verts: Vec::new(),
                smalls: Vec::new(),
                meta: Vec::new(),
            };
            (Vec::new(), bins, rejected)
        };
        let mut parts: Vec<(Vec<SetupTriangle>, ChunkBins, u64)> = if nchunks == 0 {
            vec![empty(0)]
        } else if ntiles == 0 {
            // Empty viewport: nothing is drawn, but bad input is still counted.
            let bad = indices
                .iter()
                .filter(|t| {
                    t.iter()
                        .any(|&i| !matches!(positions.get(i as usize), Some(p) if p.is_finite()))
                })
                .count();
            vec![empty(bad as u64)]
        } else {
            par_map(nchunks, threads, |c| {
                ctx.chunk(c * chunk..((c + 1) * chunk).min(n))
            })
        };

        // 3. Concatenate in chunk order (the first chunk's buffer is moved, not copied).
        // Setup indices run on across chunks (`meta` has one entry per setup triangle, `tris`
        // too unless the planes were skipped).
        let total: usize = parts.iter().map(|p| p.0.len()).sum();
        let mut rejected = 0;
        let mut tris = std::mem::take(&mut parts[0].0);
        tris.reserve(total - tris.len());
        let mut setup_count = 0u32;
        for (k, (t, bins, r)) in parts.iter_mut().enumerate() {
            rejected += *r;
            bins.base = setup_count;
            setup_count += bins.meta.len() as u32;
            if k > 0 {
                tris.extend_from_slice(t);
                TRIS.give(std::mem::take(t));
            }
        }
        debug_assert!(self.plane_setup == PlaneSetup::Skip || tris.len() == setup_count as usize);
        Binned {
            tris,
            setup_count,
            input_triangles: n,
            tiles_x,
            tiles_y,
            tile_size: self.tile_size,
            rejected,
            viewport,
            samples: self.samples,
            chunks: parts.into_iter().map(|p| p.1).collect(),
        }
    }
}

/// A chunk of triangles set up without binning ([`Prepared::setup_flat`]): a worker's
/// scratch, reused from chunk to chunk (small enough to stay in its cache).
#[derive(Default)]
pub struct FlatChunk {
    /// The setup records (empty when the planes were skipped), by chunk-relative setup
    /// index ([`Span::tri`]).
    pub tris: Vec<SetupTriangle>,
    /// The covered runs in API order (by setup triangle), each setup triangle's in
    /// row-major order: what [`Binned::raster_segment_spans`] gives tile by tile, over
    /// the whole viewport at once. With several samples, the fan pieces of a clipped
    /// triangle are merged per pixel (as there).
    pub spans: Vec<Span>,
    /// Input triangles dropped (never, for a [`Prepared::well_formed`] mesh).
    pub rejected: u64,
}

/// Merges the runs of a clipped triangle's fan pieces (`spans[start..]`) into one fragment
/// per pixel, in row-major order, with the setup index of the first piece that covers the
/// pixel: with several samples
/// two pieces can each cover some samples of a pixel on their shared diagonal (as
/// [`Binned::raster_segment_spans`] does within a tile).
#[cold]
fn merge_piece_spans(spans: &mut Vec<Span>, start: usize) {
    let Some(&first) = spans.get(start) else {
        return;
    };
    let mut pixels: Vec<(u32, u32, u32, u8)> = spans[start..]
        .iter()
        .flat_map(|s| (s.x0..s.x1).map(move |x| (s.y, x, s.tri, s.coverage)))
        .collect();
    spans.truncate(start);
    merge_pixels(&mut pixels, |y, x, tri, coverage| {
        spans.push(Span {
            y,
            x0: x,
            x1: x + 1,
            tri,
            coverage,
            ..first
        })
    });
}

/// Calls `f(y, x, tri, coverage)` once per pixel of `pixels` (`(y, x, setup index,
/// coverage)` of fan pieces), in row-major order, with the union of the pixel's coverage
/// and the lowest setup index among the pieces covering it.
fn merge_pixels(pixels: &mut [(u32, u32, u32, u8)], mut f: impl FnMut(u32, u32, u32, u8)) {
    pixels.sort_unstable_by_key(|&(y, x, tri, _)| (y, x, tri));
    let mut k = 0;
    while k < pixels.len() {
        let (y, x, tri, mut coverage) = pixels[k];
        k += 1;
        while k < pixels.len() && (pixels[k].0, pixels[k].1) == (y, x) {
            coverage |= pixels[k].3;
            k += 1;
        }
        f(y, x, tri, coverage);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_fixed_is_round_half_up_and_clamped() {
        assert_eq!(round_fixed(0.49), 0);
        assert_eq!(round_fixed(0.5), 1);
        assert_eq!(round_fixed(-0.5), 0);
        assert_eq!(round_fixed(-0.51), -1);
        assert_eq!(round_fixed(-1.5), -1);
        assert_eq!(round_fixed(1e300), COORD_LIMIT as i32);
        assert_eq!(round_fixed(-1e300), -(COORD_LIMIT as i32));
        assert_eq!(round_fixed(f64::NAN), -(COORD_LIMIT as i32));
    }

    #[test]
    fn planes_are_order_independent() {
        let v = [[100, 7], [900, 300], [-50, 800]];
        let a = [
            [0.25f32, 1.0, 0.0, 0.0],
            [0.75, 0.0, 0.5, 0.0],
            [0.5, 0.0, 0.0, 2.0],
        ];
        let p = planes(&v, &a, 0, 0);
        let q = planes(&[v[2], v[0], v[1]], &[a[2], a[0], a[1]], 0, 0);
        assert_eq!(p, q);
    }

    #[test]
    fn plane_values_match_scalar() {
        let mut seed = 3u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let m = ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 4.0;
            // Zeros of both signs too (their sign survives into the planes).
            match seed % 7 {
                0 => 0.0,
                1 => -0.0,
                _ => m * 10f64.powi((seed >> 3) as i32 % 9 - 4),
            }
        };
        for _ in 0..20000 {
            let a: [[f32; 4]; 3] = std::array::from_fn(|_| std::array::from_fn(|_| rnd() as f32));
            let c: [f64; 6] = std::array::from_fn(|_| rnd());
            let (p, q) = (
                plane_values([&a[0], &a[1], &a[2]], c),
                plane_values_scalar([&a[0], &a[1], &a[2]], c),
            );
            assert_eq!(
                p.map(|p| p.map(f32::to_bits)),
                q.map(|q| q.map(f32::to_bits))
            );
        }
    }

    #[test]
    fn setup_triangle_is_compact() {
        assert_eq!(std::mem::size_of::<SetupTriangle>(), 64);
    }
}
