//! Sample positions and per-sample coverage: integer edge functions with the top-left fill
//! rule, evaluated exactly at the samples in 8-bit sub-pixel fixed point.
//!
//! Why integers: with snapped vertices, an edge shared by two triangles gives edge functions
//! that are exact negatives of each other, so a sample lying exactly on the edge is decided by
//! the fill rule alone (`E > 0`, or `E == 0` on a top or left edge) and belongs to exactly one
//! of the two triangles. Floating-point edge functions cannot promise that.
use super::{SampleCount, SUBPIXEL_BITS};

/// One pixel in sub-pixel units.
pub(crate) const ONE: i32 = 1 << SUBPIXEL_BITS;

/// D3D11 standard sample offsets in 1/16 pixel from the pixel centre (y down).
const OFFSETS_1: [(i32, i32); 1] = [(0, 0)];
const OFFSETS_2: [(i32, i32); 2] = [(4, 4), (-4, -4)];
const OFFSETS_4: [(i32, i32); 4] = [(-2, -6), (6, -2), (-6, 2), (2, 6)];
const OFFSETS_8: [(i32, i32); 8] = [
    (1, -3),
    (-1, 3),
    (5, 1),
    (-3, -5),
    (-5, 5),
    (-7, -1),
    (3, 7),
    (7, -7),
];

/// Converts sixteenths of a pixel around the centre into sub-pixel units from the pixel's
/// top-left corner (exact: 1/16 pixel is 16 sub-pixel units).
const fn fixed<const N: usize>(o: [(i32, i32); N]) -> [(i32, i32); N] {
    let mut out = [(0, 0); N];
    let mut i = 0;
    while i < N {
        out[i] = (ONE / 2 + o[i].0 * (ONE / 16), ONE / 2 + o[i].1 * (ONE / 16));
        i += 1;
    }
    out
}

static FIXED_1: [(i32, i32); 1] = fixed(OFFSETS_1);
static FIXED_2: [(i32, i32); 2] = fixed(OFFSETS_2);
static FIXED_4: [(i32, i32); 4] = fixed(OFFSETS_4);
static FIXED_8: [(i32, i32); 8] = fixed(OFFSETS_8);

// The same positions in pixels from the top-left corner: (8 + o) / 16, written out (exact in f32).
static POS_1: [(f32, f32); 1] = [(0.5, 0.5)];
static POS_2: [(f32, f32); 2] = [(0.75, 0.75), (0.25, 0.25)];
static POS_4: [(f32, f32); 4] = [
    (0.375, 0.125),
    (0.875, 0.375),
    (0.125, 0.625),
    (0.625, 0.875),
];
static POS_8: [(f32, f32); 8] = [
    (0.5625, 0.3125),
    (0.4375, 0.6875),
    (0.8125, 0.5625),
    (0.3125, 0.1875),
    (0.1875, 0.8125),
    (0.0625, 0.4375),
    (0.6875, 0.9375),
    (0.9375, 0.0625),
];

pub(crate) fn sample_positions(s: SampleCount) -> &'static [(f32, f32)] {
    match s {
        SampleCount::X1 => &POS_1,
        SampleCount::X2 => &POS_2,
        SampleCount::X4 => &POS_4,
        SampleCount::X8 => &POS_8,
    }
}

/// Sample offsets in sub-pixel units from the pixel's top-left corner.
pub(crate) fn sample_offsets_fixed(s: SampleCount) -> &'static [(i32, i32)] {
    match s {
        SampleCount::X1 => &FIXED_1,
        SampleCount::X2 => &FIXED_2,
        SampleCount::X4 => &FIXED_4,
        SampleCount::X8 => &FIXED_8,
    }
}

/// The sample pattern and its extent inside the pixel, used to find the pixels whose samples
/// a bounding box can reach.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SampleInfo {
    pub offs: &'static [(i32, i32)],
    pub min_x: i32,
    pub max_x: i32,
    pub min_y: i32,
    pub max_y: i32,
}

impl SampleInfo {
    pub fn new(s: SampleCount) -> SampleInfo {
        let offs = sample_offsets_fixed(s);
        let mut si = SampleInfo {
            offs,
            min_x: ONE,
            max_x: 0,
            min_y: ONE,
            max_y: 0,
        };
        for &(x, y) in offs {
            si.min_x = si.min_x.min(x);
            si.max_x = si.max_x.max(x);
            si.min_y = si.min_y.min(y);
            si.max_y = si.max_y.max(y);
        }
        si
    }

    /// Inclusive pixel rectangle `[x0, y0, x1, y1]` of the pixels having a sample inside the
    /// fixed-point box `[xmin, xmax] x [ymin, ymax]`, clamped to `[0, w) x [0, h)`; `None` when
    /// empty. This is the cheap reject of sub-pixel triangles that fall between samples.
    #[inline]
    pub fn pixel_rect(&self, bb: [i32; 4], w: i32, h: i32) -> Option<[i32; 4]> {
        let [xmin, ymin, xmax, ymax] = bb;
        // Pixel p has samples at p*ONE + off; some sample is >= xmin iff p >= ceil((xmin - max_off)/ONE).
        let x0 = ((xmin - self.max_x + (ONE - 1)) >> SUBPIXEL_BITS).max(0);
        let x1 = ((xmax - self.min_x) >> SUBPIXEL_BITS).min(w - 1);
        let y0 = ((ymin - self.max_y + (ONE - 1)) >> SUBPIXEL_BITS).max(0);
        let y1 = ((ymax - self.min_y) >> SUBPIXEL_BITS).min(h - 1);
        if x0 > x1 || y0 > y1 {
            None
        } else {
            Some([x0, y0, x1, y1])
        }
    }
}

/// Fixed-point bounding box `[xmin, ymin, xmax, ymax]` of three vertices.
#[inline]
pub(crate) fn bbox(v: &[[i32; 2]; 3]) -> [i32; 4] {
    [
        v[0][0].min(v[1][0]).min(v[2][0]),
        v[0][1].min(v[1][1]).min(v[2][1]),
        v[0][0].max(v[1][0]).max(v[2][0]),
        v[0][1].max(v[1][1]).max(v[2][1]),
    ]
}

/// Twice the signed area of a fixed-point triangle in y-down screen space. Positive means the
/// vertices turn clockwise as seen on screen (counter-clockwise in the y-down frame's algebra),
/// which is clockwise in OpenGL's y-up window coordinates too: *back*-facing for
/// [`super::FrontFace::Ccw`].
#[inline]
pub(crate) fn area2(v: &[[i32; 2]; 3]) -> i64 {
    let (x0, y0) = (v[0][0] as i64, v[0][1] as i64);
    (v[1][0] as i64 - x0) * (v[2][1] as i64 - y0) - (v[1][1] as i64 - y0) * (v[2][0] as i64 - x0)
}

/// True if the edge from `p` to `q` of a positively oriented triangle is a top or a left edge.
///
/// Edge function `E(s) = (q-p) x (s-p)` is positive inside. In y-down screen space a
/// horizontal edge with the interior below it has `dy == 0, dx > 0` (top edge); an edge with the
/// interior to its right has `dE/dx = -dy > 0` (left edge).
#[inline]
pub(crate) fn is_top_left(dx: i64, dy: i64) -> bool {
    (dy < 0) | ((dy == 0) & (dx > 0))
}

/// The three edge functions `E_i(x, y) = a_i x + b_i y + c_i` (sub-pixel units) of a
/// positively oriented triangle, with the fill rule folded into `c`: a sample is inside iff all
/// three are `>= 0`. Edge `i` goes from vertex `i` to vertex `i+1`.
///
/// Magnitudes: coordinates are below 2^30 (guard band), so `a, b < 2^31`, products and `c`
/// below 2^62: no i64 overflow.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Edges {
    pub a: [i64; 3],
    pub b: [i64; 3],
    pub c: [i64; 3],
}

impl Edges {
    #[inline]
    pub fn new(v: &[[i32; 2]; 3]) -> Edges {
        let mut e = Edges {
            a: [0; 3],
            b: [0; 3],
            c: [0; 3],
        };
        for i in 0..3 {
            let p = v[i];
            let q = v[(i + 1) % 3];
            let (px, py) = (p[0] as i64, p[1] as i64);
            let dx = q[0] as i64 - px;
            let dy = q[1] as i64 - py;
            e.a[i] = -dy;
            e.b[i] = dx;
            e.c[i] = dy * px - dx * py - i64::from(!is_top_left(dx, dy));
        }
        e
    }

    #[inline]
    fn at(&self, x: i64, y: i64) -> [i64; 3] {
        [
            self.a[0] * x + self.b[0] * y + self.c[0],
            self.a[1] * x + self.b[1] * y + self.c[1],
            self.a[2] * x + self.b[2] * y + self.c[2],
        ]
    }

    /// True if no point of the fixed-point rectangle `[x0, x1] x [y0, y1]` is inside (some
    /// edge is negative over all of it): used to skip tiles that a large triangle's bounding
    /// box touches but the triangle does not.
    #[inline]
    pub fn rect_outside(&self, x0: i64, y0: i64, x1: i64, y1: i64) -> bool {
        (0..3).any(|i| {
            let x = if self.a[i] > 0 { x1 } else { x0 };
            let y = if self.b[i] > 0 { y1 } else { y0 };
            self.a[i] * x + self.b[i] * y + self.c[i] < 0
        })
    }

    /// Coverage mask of the pixel whose top-left corner is `(x, y)` (sub-pixel units).
    #[inline]
    pub fn mask_at(&self, si: &SampleInfo, x: i64, y: i64) -> u8 {
        let mut m = 0u8;
        for (s, &(ox, oy)) in si.offs.iter().enumerate() {
            let e = self.at(x + ox as i64, y + oy as i64);
            m |= u8::from((e[0] | e[1] | e[2]) >= 0) << s;
        }
        m
    }
}

/// Coverage mask of pixel `(px, py)` for a positively oriented triangle: the same edge
/// functions and fill rule as [`Edges`], evaluated relative to the pixel corner without
/// building the edge constants (the common case of a triangle whose box reaches one pixel).
#[inline]
pub(crate) fn pixel_mask(v: &[[i32; 2]; 3], si: &SampleInfo, px: i32, py: i32) -> u8 {
    let (ox, oy) = ((px as i64) << SUBPIXEL_BITS, (py as i64) << SUBPIXEL_BITS);
    let mut x = [0i64; 3];
    let mut y = [0i64; 3];
    for i in 0..3 {
        x[i] = v[i][0] as i64 - ox;
        y[i] = v[i][1] as i64 - oy;
    }
    let mut dx = [0i64; 3];
    let mut dy = [0i64; 3];
    let mut bias = [0i64; 3];
    for i in 0..3 {
        let j = (i + 1) % 3;
        dx[i] = x[j] - x[i];
        dy[i] = y[j] - y[i];
        bias[i] = i64::from(is_top_left(dx[i], dy[i])) - 1;
    }
    let mut m = 0u8;
    for (s, &(sx, sy)) in si.offs.iter().enumerate() {
        let (sx, sy) = (sx as i64, sy as i64);
        let e0 = dx[0] * (sy - y[0]) - dy[0] * (sx - x[0]) + bias[0];
        let e1 = dx[1] * (sy - y[1]) - dy[1] * (sx - x[1]) + bias[1];
        let e2 = dx[2] * (sy - y[2]) - dy[2] * (sx - x[2]) + bias[2];
        m |= u8::from((e0 | e1 | e2) >= 0) << s;
    }
    m
}

/// The covered run `start..end` (pixel offsets in `0..width`) of a row whose edge functions
/// are `v` at its first pixel and grow by `step` per pixel, or `None`. A pixel is covered
/// when all three are non-negative; each edge bounds the run from one side (it is linear
/// in x), so the run is the intersection of three half-lines, found with at most three
/// exact integer divisions instead of stepping across the row: the same pixels as the
/// stepping scan (test `row_run_is_the_stepping_scan`).
#[inline(always)]
fn row_run(v: [i64; 3], step: [i64; 3], width: i64) -> Option<(i64, i64)> {
    let (mut lo, mut hi) = (0i64, width);
    for i in 0..3 {
        let (v, s) = (v[i], step[i]);
        if v >= 0 {
            if s < 0 {
                // v + k s >= 0  <=>  k <= v / -s.
                hi = hi.min(v / -s + 1);
            }
        } else if s > 0 {
            // v + k s >= 0  <=>  k >= ceil(-v / s).
            lo = lo.max((-v + s - 1) / s);
        } else {
            return None;
        }
    }
    (lo < hi).then_some((lo, hi))
}

/// Calls `f(y, x0, x1, mask)` for every run `x0..x1` of row `y` of the inclusive pixel
/// rectangle `r` whose pixels have the same nonzero coverage `mask`, in row-major order.
/// Edge functions are stepped incrementally (exact integer additions, so stepping gives the
/// same values as direct evaluation).
///
/// With one sample a triangle covers one run per row (it is convex): the scan of a row
/// stops at the end of the run, and the consumer gets the run whole rather than a call per
/// pixel.
#[inline]
pub(crate) fn raster(
    e: &Edges,
    si: &SampleInfo,
    r: [i32; 4],
    mut f: impl FnMut(u32, u32, u32, u8),
) {
    let [x0, y0, x1, y1] = r;
    let step_x = [
        e.a[0] << SUBPIXEL_BITS,
        e.a[1] << SUBPIXEL_BITS,
        e.a[2] << SUBPIXEL_BITS,
    ];
    let step_y = [
        e.b[0] << SUBPIXEL_BITS,
        e.b[1] << SUBPIXEL_BITS,
        e.b[2] << SUBPIXEL_BITS,
    ];
    let bx = (x0 as i64) << SUBPIXEL_BITS;
    let by = (y0 as i64) << SUBPIXEL_BITS;
    if si.offs.len() == 1 {
        let (ox, oy) = si.offs[0];
        let mut row = e.at(bx + ox as i64, by + oy as i64);
        let width = (x1 - x0 + 1) as i64;
        for y in y0..=y1 {
            if let Some((start, end)) = row_run(row, step_x, width) {
                f(
                    y as u32,
                    (x0 as i64 + start) as u32,
                    (x0 as i64 + end) as u32,
                    1,
                );
            }
            row[0] += step_y[0];
            row[1] += step_y[1];
            row[2] += step_y[2];
        }
    } else {
        // Per-sample constant offsets from the pixel corner.
        let mut offs = [[0i64; 3]; 8];
        for (o, &(ox, oy)) in offs.iter_mut().zip(si.offs) {
            *o = [0, 1, 2].map(|i| e.a[i] * ox as i64 + e.b[i] * oy as i64);
        }
        let offs = &offs[..si.offs.len()];
        let mut row = e.at(bx, by);
        for y in y0..=y1 {
            let mut v = row;
            for x in x0..=x1 {
                let mut m = 0u8;
                for (s, o) in offs.iter().enumerate() {
                    let inside = ((v[0] + o[0]) | (v[1] + o[1]) | (v[2] + o[2])) >= 0;
                    m |= u8::from(inside) << s;
                }
                if m != 0 {
                    f(y as u32, x as u32, x as u32 + 1, m);
                }
                v[0] += step_x[0];
                v[1] += step_x[1];
                v[2] += step_x[2];
            }
            row[0] += step_y[0];
            row[1] += step_y[1];
            row[2] += step_y[2];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::block::*;
    use super::*;

    /// xorshift64*: deterministic test input, no dependency.
    fn xorshift(state: &mut u64) -> u64 {
        *state ^= *state >> 12;
        *state ^= *state << 25;
        *state ^= *state >> 27;
        state.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    #[test]
    fn fixed_offsets_match_float_positions() {
        for s in [
            SampleCount::X1,
            SampleCount::X2,
            SampleCount::X4,
            SampleCount::X8,
        ] {
            let f = sample_offsets_fixed(s);
            let p = sample_positions(s);
            assert_eq!(f.len(), s.count());
            for (&(fx, fy), &(px, py)) in f.iter().zip(p) {
                assert_eq!(fx as f32 / ONE as f32, px);
                assert_eq!(fy as f32 / ONE as f32, py);
            }
        }
    }

    #[test]
    fn top_left_classification() {
        // Positive triangle (0,0) (1,0) (0,1) in y-down space: edge 0 is the top edge, edge 2
        // (from (0,1) up to (0,0)) the left edge, edge 1 the hypotenuse on the bottom right.
        let v = [[0, 0], [ONE, 0], [0, ONE]];
        assert!(area2(&v) > 0);
        assert!(is_top_left(ONE as i64, 0));
        assert!(!is_top_left(-ONE as i64, ONE as i64));
        assert!(is_top_left(0, -ONE as i64));
        assert!(
            !is_top_left(-(ONE as i64), 0),
            "a bottom edge is not top-left"
        );
        assert!(!is_top_left(0, ONE as i64), "a right edge is not top-left");
    }

    #[test]
    fn shared_edge_functions_are_exact_negatives() {
        let t1 = [[10, 20], [500, 37], [33, 900]];
        let t2 = [[500, 37], [10, 20], [700, -50]];
        assert!(area2(&t1) > 0 && area2(&t2) > 0);
        let (e1, e2) = (Edges::new(&t1), Edges::new(&t2));
        // Edge 0 of t1 is A->B, edge 0 of t2 is B->A.
        assert_eq!(e1.a[0], -e2.a[0]);
        assert_eq!(e1.b[0], -e2.b[0]);
        // Biases differ by exactly one: the sum of the raw functions is zero.
        assert_eq!(e1.c[0] + e2.c[0], -1);
    }

    #[test]
    fn pixel_mask_matches_edges() {
        let mut seed = 7u64;
        let mut rnd = |n: i32| {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 33) % n as u64) as i32
        };
        for s in [SampleCount::X1, SampleCount::X4, SampleCount::X8] {
            let si = SampleInfo::new(s);
            for _ in 0..20000 {
                // Small triangles near pixel (3, 5), with coordinates often on the sample grid.
                let c = |r: &mut dyn FnMut(i32) -> i32| {
                    [
                        3 * ONE + r(3 * ONE / 16) * 16 - ONE,
                        5 * ONE + r(3 * ONE / 16) * 16 - ONE,
                    ]
                };
                let mut v = [c(&mut rnd), c(&mut rnd), c(&mut rnd)];
                let a = area2(&v);
                if a == 0 {
                    continue;
                }
                if a < 0 {
                    v.swap(1, 2);
                }
                let e = Edges::new(&v);
                for (px, py) in [(2, 4), (3, 5), (3, 4), (2, 5)] {
                    assert_eq!(
                        pixel_mask(&v, &si, px, py),
                        e.mask_at(&si, (px as i64) << 8, (py as i64) << 8),
                        "{v:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn block_mask_matches_scalar_and_wide() {
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut next = |n: i32| ((xorshift(&mut state) >> 33) % n as u64) as i32;
        let si = SampleInfo::new(SampleCount::X1);
        let (w, h) = (64, 64);
        let (mut blocks, mut blocks8) = (0, 0);
        for t in 0..800_000 {
            // Small triangles around pixel (20, 30): vertices on the sample grid or between
            // samples (every fourth on a coarse grid, for edges through sample centres and
            // horizontal or vertical edges), of every size an 8x8 rectangle takes.
            let ext = [ONE, 2 * ONE, 3 * ONE, 5 * ONE, 7 * ONE, 9 * ONE][t % 6];
            let grid = if t % 4 == 0 { ONE / 2 } else { 1 };
            let mut c = || {
                [
                    20 * ONE + next(ext / grid) * grid,
                    30 * ONE + next(ext / grid) * grid,
                ]
            };
            let mut v = [c(), c(), c()];
            let a = area2(&v);
            if a == 0 {
                continue;
            }
            if a < 0 {
                v.swap(1, 2);
            }
            let Some(r) = si.pixel_rect(bbox(&v), w, h) else {
                continue;
            };
            if r[2] - r[0] >= 8 || r[3] - r[1] >= 8 || !block_fits(r, w, h) {
                continue;
            }
            let wide = block_mask_wide(&Edges::new(&v), &si, r);
            assert_eq!(block_mask_scalar(&v, &si, r), wide, "{v:?} {r:?}");
            assert_eq!(block_mask8(&v, &si, r), wide, "{v:?} {r:?}");
            blocks8 += 1;
            if r[2] - r[0] < 4 && r[3] - r[1] < 4 {
                assert_eq!(block_mask(&v, &si, r), wide, "{v:?} {r:?}");
                blocks += 1;
            }
        }
        assert!(
            blocks > 200_000 && blocks8 > 400_000,
            "{blocks}, {blocks8} blocks tested"
        );
    }

    #[test]
    fn pixel_rect_rejects_between_centres() {
        let si = SampleInfo::new(SampleCount::X1);
        // A box strictly between centres 0.5 and 1.5.
        assert_eq!(
            si.pixel_rect([ONE / 2 + 1, 0, ONE + ONE / 2 - 1, ONE], 10, 10),
            None
        );
        // A box touching a centre includes it (the fill rule decides later).
        assert_eq!(
            si.pixel_rect([ONE / 2, ONE / 2, ONE / 2, ONE / 2], 10, 10),
            Some([0, 0, 0, 0])
        );
        // Negative coordinates round correctly.
        assert_eq!(
            si.pixel_rect([-ONE, -ONE, ONE / 2, ONE / 2], 10, 10),
            Some([0, 0, 0, 0])
        );
    }

    /// The stepping scan `row_run` replaced: skip to the run, then step to its end.
    fn stepping_scan(mut v: [i64; 3], s: [i64; 3], width: i64) -> Option<(i64, i64)> {
        let mut k = 0;
        while k < width && (v[0] | v[1] | v[2]) < 0 {
            (0..3).for_each(|i| v[i] += s[i]);
            k += 1;
        }
        let start = k;
        while k < width && (v[0] | v[1] | v[2]) >= 0 {
            (0..3).for_each(|i| v[i] += s[i]);
            k += 1;
        }
        (k > start).then_some((start, k))
    }

    #[test]
    fn row_run_is_the_stepping_scan() {
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = |bound: i64| (xorshift(&mut state) % (2 * bound as u64)) as i64 - bound;
        for t in 0..400_000 {
            // Small and large edge values and steps, zero steps included.
            let vb = if t % 2 == 0 { 1 << 12 } else { 1 << 40 };
            let sb = if t % 3 == 0 { 1 << 4 } else { 1 << 30 };
            let v = [next(vb), next(vb), next(vb)];
            let mut s = [next(sb), next(sb), next(sb)];
            if t % 7 == 0 {
                s[(t / 7) % 3] = 0;
            }
            let width = 1 + next(150).abs();
            assert_eq!(
                row_run(v, s, width),
                stepping_scan(v, s, width),
                "{v:?} {s:?} {width}"
            );
        }
    }
}
