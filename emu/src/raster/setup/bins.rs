//! Triangles set up and binned into tiles ([`Binned`]), walked tile by tile in API order.

use super::*;
use crate::hint::prefetch;
use crate::raster::clip::MAX_POLY;
use crate::raster::coverage::{self, bbox, Edges, SampleInfo};
use crate::raster::pool::Pool;
use crate::raster::{Fragment, SampleCount, Span, Viewport};

/// Triangles set up and binned into tiles.
pub struct Binned {
    /// The setup records, by setup index; empty when the planes were skipped
    /// ([`PlaneSetup::Skip`]).
    pub tris: Vec<SetupTriangle>,
    /// Setup triangles (as many as `tris` holds when the planes were set up).
    pub(super) setup_count: u32,
    /// Input triangles.
    pub(super) input_triangles: usize,
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
    pub(super) chunks: Vec<ChunkBins>,
}

/// The tile lists of one chunk of input triangles: `entries[tile_start[t]..tile_start[t+1]]`
/// are tile `t`'s entries, ascending. Built by the worker that set the chunk up, so no global
/// scatter is needed; [`Binned::raster_tile`] walks the chunks in order.
pub(super) struct ChunkBins {
    /// Setup index of the chunk's first triangle.
    pub(super) base: u32,
    pub(super) tile_start: Vec<u32>,
    pub(super) entries: Vec<BinEntry>,
    /// Snapped vertices (sub-pixel units, y down, positively oriented: see
    /// [`coverage::area2`]) of the chunk's triangles that are rasterized in the tiles.
    pub(super) verts: Vec<[[i32; 2]; 3]>,
    /// Coverage of the chunk's small triangles, computed at setup (see [`SmallCoverage`]).
    pub(super) smalls: Vec<SmallCoverage>,
    /// Per setup triangle of the chunk (by `BinEntry::tri`): what shading needs of it
    /// besides coverage, kept apart from the 64-byte setup records.
    pub(super) meta: Vec<TriMeta>,
}

/// A setup triangle's source index and facing (see [`SetupTriangle`]).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct TriMeta {
    pub(super) source: u32,
    pub(super) front_facing: bool,
}

/// The coverage of a small one-sample triangle (pixel rectangle of at most 8x8, most
/// triangles of a dense mesh at high resolution), computed once at setup: bit `8 j + i` is
/// pixel `(x + i, y + j)`. Rasterizing it is then a walk over bits, with no edge set-up
/// and no per-pixel edge stepping, in every tile it is binned to.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct SmallCoverage {
    pub(super) x: i32,
    pub(super) y: i32,
    pub(super) bits: u64,
}

impl SmallCoverage {
    /// Calls `f(y, x0, x1)` for the covered run of each row with one, in order. The block
    /// must hold one run per row at most, as the coverage of a one-sample triangle does
    /// (the samples inside a convex region, along a line, are consecutive).
    #[inline(always)]
    pub(super) fn convex_runs(&self, mut f: impl FnMut(u32, u32, u32)) {
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
    pub(super) fn runs(&self, rect: [i32; 4], mut f: impl FnMut(u32, u32, u32)) {
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
pub(super) struct BinEntry {
    pub(super) tri: u32,
    pub(super) info: u32,
}

/// Flag of a precomputed single-pixel [`BinEntry`].
pub(super) const SINGLE: u32 = 1 << 31;
/// Flag of a [`BinEntry`] of one of several fan pieces of a clipped triangle.
pub(super) const PIECE: u32 = 1 << 30;
/// Most input triangles per setup chunk (see [`bin_triangles`]).
pub(super) const MAX_CHUNK: usize = 1 << 25;
const _: () = assert!(MAX_CHUNK * MAX_POLY < SMALL as usize);

/// Flag of a [`BinEntry`] whose coverage was computed at setup: `info` (without the flags)
/// indexes [`ChunkBins::smalls`].
pub(super) const SMALL: u32 = 1 << 29;
/// The flags of a [`BinEntry`]'s `info`.
pub(super) const FLAGS: u32 = SINGLE | PIECE | SMALL;

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
pub(super) const PREFETCH_AHEAD: usize = 8;

impl ChunkBins {
    /// Asks the cache for the records entry `e` indexes (a hint: no effect on results).
    #[inline(always)]
    pub(super) fn prefetch(&self, e: &BinEntry) {
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
pub(super) fn entry_coverage(
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
pub(super) static XY: Pool<[i32; 2]> = Pool::new();
pub(super) static ZW: Pool<[f32; 2]> = Pool::new();
pub(super) static TRIS: Pool<SetupTriangle> = Pool::new();
pub(super) static PAIRS: Pool<(u32, BinEntry)> = Pool::new();
pub(super) static ENTRIES: Pool<BinEntry> = Pool::new();
pub(super) static STARTS: Pool<u32> = Pool::new();
pub(super) static VERTS: Pool<[[i32; 2]; 3]> = Pool::new();
pub(super) static SMALLS: Pool<SmallCoverage> = Pool::new();
pub(super) static META: Pool<TriMeta> = Pool::new();

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
