//! Step 2 of setup, per chunk of triangles: snapping, the bounding-box sample test, area,
//! facing and culling, the exact test of tiny triangles, clipping, planes and tile bins.

use super::*;
use crate::raster::block;
use crate::raster::clip::{self, ClipVert, Planes, MAX_POLY, NON_FINITE};
use crate::raster::coverage::{self, area2, bbox, Edges, SampleInfo, ONE};
use crate::raster::{CullMode, Span, SUBPIXEL_BITS};
use glam::Vec4;

#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Snapped {
    pub(super) x: i32,
    pub(super) y: i32,
    pub(super) z: f32,
    pub(super) iw: f32,
}

pub(super) const OUT: i32 = i32::MIN;

/// Viewport transform to fixed point. One function for every vertex, original or produced by
/// clipping, so equal inputs snap to equal outputs.
#[derive(Clone, Copy, Debug)]
pub(super) struct Xform {
    /// `W * ONE / 2` and `H * ONE / 2`.
    pub(super) sx: f64,
    pub(super) sy: f64,
}

impl Xform {
    /// Window position (fixed point), window depth `(z/w + 1) / 2` and `1/w`.
    #[inline]
    pub(super) fn project(&self, p: &[f64; 4]) -> Snapped {
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
pub(super) fn round_fixed(v: f64) -> i32 {
    const BIAS: f64 = 2_147_483_648.0;
    // Not `clamp`: that propagates NaN, and NaN would become the OUT sentinel.
    #[allow(clippy::manual_clamp)]
    let c = v.max(-COORD_LIMIT).min(COORD_LIMIT);
    ((c + (0.5 + BIAS)) as i64 - BIAS as i64) as i32
}

#[inline]
pub(super) fn vec4_f64(p: Vec4) -> [f64; 4] {
    [p.x as f64, p.y as f64, p.z as f64, p.w as f64]
}

/// Everything a worker needs, shared read-only.
pub(super) struct Ctx<'a> {
    pub(super) positions: &'a [Vec4],
    pub(super) indices: &'a [[u32; 3]],
    /// Step 1 output, per vertex: the snapped position, or `[OUT, outcode]` outside a clip
    /// plane (split from `zw` so that the hot reject loop reads half the memory).
    pub(super) xy: &'a [[i32; 2]],
    /// Window depth and `1/w` per vertex.
    pub(super) zw: &'a [[f32; 2]],
    pub(super) planes: Planes,
    pub(super) xf: Xform,
    pub(super) si: SampleInfo,
    /// Viewport in pixels (clamped to [`MAX_VIEWPORT`]).
    pub(super) w: i32,
    pub(super) h: i32,
    /// log2 of the tile size.
    pub(super) tile_shift: u32,
    pub(super) tiles_x: u32,
    pub(super) ntiles: usize,
    pub(super) cull: CullMode,
    /// `FrontFace::Ccw`: front-facing when counter-clockwise on screen.
    pub(super) ccw_front: bool,
    pub(super) plane_setup: PlaneSetup,
    /// Set up for [`Prepared::setup_flat`]: each setup triangle's covered runs go straight
    /// to [`ChunkOut::spans`], in API order, instead of into per-tile bin entries.
    pub(super) flat: bool,
}

/// Triangles per batch of the reject loop (a power of two).
pub(super) const BATCH: usize = 256;

/// A triangle kept by [`Ctx::reject`]: its index, whether it is `special` (an index out of
/// range, or a vertex outside a clip plane: see [`Ctx::setup_special`]), and, when it is
/// not, its pixel rectangle. The flag spares setup a second bounds check of three indices
/// and three clip tests (about 20 instructions per kept triangle, for one store each in the
/// reject loop).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Kept {
    pub(super) t: u32,
    pub(super) special: bool,
    pub(super) r: [i32; 4],
}

/// What one chunk of triangles produced.
pub(super) struct ChunkOut {
    pub(super) tris: Vec<SetupTriangle>,
    pub(super) verts: Vec<[[i32; 2]; 3]>,
    pub(super) smalls: Vec<SmallCoverage>,
    pub(super) meta: Vec<TriMeta>,
    /// `(tile, entry)` in triangle order.
    pub(super) bins: Vec<(u32, BinEntry)>,
    /// Unbinned ([`Ctx::flat`]): the covered runs, in triangle order.
    pub(super) spans: Vec<Span>,
    /// Setup triangles so far (the next one's index).
    pub(super) setups: u32,
    pub(super) rejected: u64,
}

/// What setup found of a triangle's coverage.
pub(super) enum SetupCoverage {
    /// One covered pixel and its sample mask.
    Single { x: i32, y: i32, mask: u8 },
    /// A small one-sample triangle's covered pixels.
    Small(SmallCoverage),
    /// Rasterized in the tiles from its vertices.
    Vertices,
}

/// Coverage of a tiny triangle (pixel rectangle of at most 2x2).
pub(super) enum Tiny {
    Empty,
    Single(i32, i32, u8),
    Several,
}

impl Ctx<'_> {
    /// Facing from the snapped signed area (`a2 < 0`: counter-clockwise on screen, see
    /// [`coverage::area2`]); `None` when culled.
    #[inline]
    pub(super) fn facing(&self, a2_negative: bool) -> Option<bool> {
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
    pub(super) fn tiny(&self, e: &Edges, r: [i32; 4]) -> Tiny {
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
    pub(super) fn run<const LEAN: bool>(&self, range: std::ops::Range<usize>, out: &mut ChunkOut) {
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
    pub(super) fn reject(&self, range: std::ops::Range<usize>, keep: &mut [Kept; BATCH]) -> usize {
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
    pub(super) fn setup_special(&self, t: u32, out: &mut ChunkOut) {
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
    pub(super) fn setup<const LEAN: bool>(&self, k: &Kept, out: &mut ChunkOut) {
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
    pub(super) fn clipped(&self, source: u32, idx: [u32; 3], s: [[i32; 2]; 3], out: &mut ChunkOut) {
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
    pub(super) fn coverage<const LEAN: bool>(
        &self,
        v: &[[i32; 2]; 3],
        r: [i32; 4],
    ) -> Option<SetupCoverage> {
        let single = |x: i32, y: i32, mask: u8| SetupCoverage::Single { x, y, mask };
        if r[0] == r[2] && r[1] == r[3] {
            let m = coverage::pixel_mask(v, &self.si, r[0], r[1]);
            return (m != 0).then(|| single(r[0], r[1], m));
        }
        let (w, h) = (r[2] - r[0], r[3] - r[1]);
        if (LEAN || self.si.offs.len() == 1) && w < 8 && h < 8 {
            let bits = if !block::block_fits(r, self.w, self.h) {
                // Clamped to the viewport (rare): the box may be too large for `i32`.
                block::block_mask_wide(&Edges::new(v), &self.si, r)
            } else if w < 4 && h < 4 {
                block::block_mask(v, &self.si, r)
            } else {
                block::block_mask8(v, &self.si, r)
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
    pub(super) fn finish<const LEAN: bool>(
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
    pub(super) fn chunk(
        &self,
        range: std::ops::Range<usize>,
    ) -> (Vec<SetupTriangle>, ChunkBins, u64) {
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
