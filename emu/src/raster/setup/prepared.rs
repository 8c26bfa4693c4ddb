//! Projected and snapped triangles ([`Prepared`]), binned ([`Prepared::bin`]) or set up
//! chunk by chunk without bins ([`Prepared::setup_flat`]).

use super::*;
use crate::raster::clip::Planes;
use crate::raster::coverage::{SampleInfo, ONE};
use crate::raster::{CullMode, FrontFace, RasterState, SampleCount, Span, Viewport};
use glam::Vec4;

/// Triangles whose vertices are projected and snapped (step 1 of [`super::bin_triangles`]), ready
/// for setup: binned into tiles ([`Prepared::bin`]), or set up chunk by chunk and
/// rasterized straight away, unbinned ([`Prepared::setup_flat`]), when the order in which
/// the pixels of different triangles are visited does not matter.
pub struct Prepared<'a> {
    pub(super) positions: &'a [Vec4],
    pub(super) indices: &'a [[u32; 3]],
    /// Per vertex, as [`Ctx::xy`] and [`Ctx::zw`] (recycled buffers, given back on drop).
    pub(super) xy: Vec<[i32; 2]>,
    pub(super) zw: Vec<[f32; 2]>,
    pub(super) planes: Planes,
    pub(super) xf: Xform,
    pub(super) samples: SampleCount,
    pub(super) viewport: Viewport,
    pub(super) tile_size: u32,
    pub(super) cull: CullMode,
    pub(super) ccw_front: bool,
    pub(super) plane_setup: PlaneSetup,
    /// A vertex was NaN or infinite.
    pub(super) non_finite: bool,
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
    let non_finite = project_all(&planes, &xf, positions, threads, &mut xy, &mut zw);
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

/// Projected vertices kept from a [`Prepared`] ([`Prepared::into_projected`]), to prepare
/// another draw of the same clip-space positions into the same viewport without
/// projecting them again ([`prepare_projected`]).
pub struct Projected {
    xy: Vec<[i32; 2]>,
    zw: Vec<[f32; 2]>,
    non_finite: bool,
    viewport: Viewport,
}

impl Projected {
    /// The viewport they were projected into.
    pub fn viewport(&self) -> Viewport {
        self.viewport
    }
}

impl Drop for Projected {
    fn drop(&mut self) {
        XY.give_dirty(std::mem::take(&mut self.xy));
        ZW.give_dirty(std::mem::take(&mut self.zw));
    }
}

/// [`prepare`] with the vertices already projected: `projected` must come from a
/// [`Prepared`] of the same `positions` (same values) into `viewport` (checked: a different
/// viewport or vertex count projects again).
pub fn prepare_projected<'a>(
    positions: &'a [Vec4],
    indices: &'a [[u32; 3]],
    state: &RasterState,
    viewport: Viewport,
    threads: usize,
    plane_setup: PlaneSetup,
    mut projected: Projected,
) -> Prepared<'a> {
    if projected.viewport != viewport || projected.xy.len() != positions.len() {
        return prepare(positions, indices, state, viewport, threads, plane_setup);
    }
    let w = viewport.width.min(MAX_VIEWPORT);
    let h = viewport.height.min(MAX_VIEWPORT);
    Prepared {
        positions,
        indices,
        xy: std::mem::take(&mut projected.xy),
        zw: std::mem::take(&mut projected.zw),
        planes: Planes::new(w.max(1), h.max(1)),
        xf: Xform {
            sx: viewport.width as f64 * (ONE / 2) as f64,
            sy: viewport.height as f64 * (ONE / 2) as f64,
        },
        samples: state.samples,
        viewport,
        tile_size: effective_tile_size(state.tile_size),
        cull: state.cull,
        ccw_front: state.front_face == FrontFace::Ccw,
        plane_setup,
        non_finite: projected.non_finite,
    }
}

/// Projects and snaps every vertex into `xy` and `zw` (as long as `positions`), on up to
/// `threads` threads; returns whether a vertex was NaN or infinite.
fn project_all(
    planes: &Planes,
    xf: &Xform,
    positions: &[Vec4],
    threads: usize,
    xy: &mut [[i32; 2]],
    zw: &mut [[f32; 2]],
) -> bool {
    let vthreads = threads.max(1).min(positions.len() / 8192).max(1);
    if vthreads == 1 {
        project_vertices(planes, xf, positions, xy, zw)
    } else {
        let per = positions.len().div_ceil(vthreads);
        let parts: Vec<_> = xy
            .chunks_mut(per)
            .zip(zw.chunks_mut(per))
            .zip(positions.chunks(per))
            .collect();
        crate::sync::pool::broadcast_each(parts, |((xy, zw), src)| {
            project_vertices(planes, xf, src, xy, zw)
        })
        .contains(&true)
    }
}

impl Drop for Prepared<'_> {
    fn drop(&mut self) {
        XY.give_dirty(std::mem::take(&mut self.xy));
        ZW.give_dirty(std::mem::take(&mut self.zw));
    }
}

impl<'a> Prepared<'a> {
    /// The projected vertices, kept for another draw of the same positions
    /// ([`prepare_projected`]).
    pub fn into_projected(mut self) -> Projected {
        Projected {
            xy: std::mem::take(&mut self.xy),
            zw: std::mem::take(&mut self.zw),
            non_finite: self.non_finite,
            viewport: self.viewport,
        }
    }

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

    pub(super) fn ctx(&self, flat: bool) -> Ctx<'_> {
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
pub(super) fn merge_piece_spans(spans: &mut Vec<Span>, start: usize) {
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
pub(super) fn merge_pixels(
    pixels: &mut [(u32, u32, u32, u8)],
    mut f: impl FnMut(u32, u32, u32, u8),
) {
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
