//! Homogeneous clipping against the near and far planes, `w > epsilon`, and guard-band planes
//! for x and y, plus the convex hull used to fan the clipped polygon.
//!
//! Why a guard band instead of full x/y clipping: clipping against the viewport edges would
//! create new vertices (and rounding) along the screen border for most border-crossing
//! triangles. The guard band is so wide (±2^20 pixels) that only triangles reaching far off
//! screen, usually near the eye, are clipped for x/y, and it bounds fixed-point coordinates so
//! that i64 edge functions never overflow.
//!
//! Why clipping stays watertight: every intersection point is computed from the edge's inside
//! vertex towards its outside vertex (`p_in + t (p_out - p_in)`, `t = d_in / (d_in - d_out)`),
//! so two triangles sharing a clipped edge compute bit-identical points in both polygons, whatever
//! their windings.

/// Guard band in pixels: window coordinates of clipped vertices stay within `[-L, L]`, i.e.
/// 2^28 sub-pixel units, so edge function terms stay below 2^62.
pub(crate) const GUARD_PIXELS: f64 = (1u32 << 20) as f64;

/// Smallest `w` kept: the plane `w >= W_EPSILON` keeps divisions by `w` finite.
pub(crate) const W_EPSILON: f64 = 1e-7;

/// Number of clip planes.
pub(crate) const PLANES: usize = 7;

/// Outcode bit of a vertex with a NaN or infinite coordinate (above the plane bits).
pub(crate) const NON_FINITE: u32 = 1 << PLANES;

/// The seven clip planes as coefficients of `w` in the x and y guard-band planes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Planes {
    kx_lo: f64,
    kx_hi: f64,
    ky_lo: f64,
    ky_hi: f64,
}

impl Planes {
    /// Planes for a viewport of `width x height` pixels (both > 0).
    pub fn new(width: u32, height: u32) -> Planes {
        let w = (width as f64).min(GUARD_PIXELS);
        let h = (height as f64).min(GUARD_PIXELS);
        Planes {
            // x_win >= -L  <=>  x_ndc >= -(2L/W + 1);  x_win <= L  <=>  x_ndc <= 2L/W - 1.
            kx_lo: 2.0 * GUARD_PIXELS / w + 1.0,
            kx_hi: 2.0 * GUARD_PIXELS / w - 1.0,
            // y_win = (1 - y_ndc) H / 2:  y_win >= -L  <=>  y_ndc <= 2L/H + 1, and so on.
            ky_lo: 2.0 * GUARD_PIXELS / h + 1.0,
            ky_hi: 2.0 * GUARD_PIXELS / h - 1.0,
        }
    }

    /// Signed distance of `p = (x, y, z, w)` to plane `i` (inside when `>= 0`).
    #[inline]
    pub fn dist(&self, i: usize, p: &[f64; 4]) -> f64 {
        let [x, y, z, w] = *p;
        match i {
            0 => w - W_EPSILON,
            1 => w + z,
            2 => w - z,
            3 => x + self.kx_lo * w,
            4 => self.kx_hi * w - x,
            5 => self.ky_lo * w - y,
            _ => y + self.ky_hi * w,
        }
    }

    /// [`Planes::outcode_finite`], or [`NON_FINITE`] for NaN or infinite input (setup tests
    /// finiteness on the f32 input instead).
    #[cfg(test)]
    #[inline]
    pub fn outcode(&self, p: &[f64; 4]) -> u32 {
        let [x, y, z, w] = *p;
        if !(x.is_finite() && y.is_finite() && z.is_finite() && w.is_finite()) {
            return NON_FINITE;
        }
        self.outcode_finite(p)
    }

    /// Bit `i` set when the finite point `p` is outside plane `i`. Written out plane by
    /// plane (the same expressions as [`Planes::dist`], so a vertex is classified
    /// identically here and by the clipper).
    #[inline]
    pub fn outcode_finite(&self, p: &[f64; 4]) -> u32 {
        let [x, y, z, w] = *p;
        u32::from(w - W_EPSILON < 0.0)
            | u32::from(w + z < 0.0) << 1
            | u32::from(w - z < 0.0) << 2
            | u32::from(x + self.kx_lo * w < 0.0) << 3
            | u32::from(self.kx_hi * w - x < 0.0) << 4
            | u32::from(self.ky_lo * w - y < 0.0) << 5
            | u32::from(y + self.ky_hi * w < 0.0) << 6
    }
}

/// A polygon vertex: clip-space position and barycentric weights of the source triangle.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct ClipVert {
    pub p: [f64; 4],
    pub b: [f64; 3],
}

/// Largest clipped polygon: a triangle gains at most one vertex per plane.
pub(crate) const MAX_POLY: usize = 3 + PLANES;

/// A small fixed-capacity polygon (no heap).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Poly {
    pub v: [ClipVert; MAX_POLY + 1],
    pub n: usize,
}

impl Poly {
    fn push(&mut self, c: ClipVert) {
        // Capacity holds by construction; stay in bounds even if it did not.
        if self.n < self.v.len() {
            self.v[self.n] = c;
            self.n += 1;
        }
    }
}

fn lerp(a: &ClipVert, b: &ClipVert, t: f64) -> ClipVert {
    let mut r = ClipVert::default();
    for k in 0..4 {
        r.p[k] = a.p[k] + t * (b.p[k] - a.p[k]);
    }
    for k in 0..3 {
        r.b[k] = a.b[k] + t * (b.b[k] - a.b[k]);
    }
    r
}

/// Sutherland-Hodgman clipping of a triangle against the planes in `mask` (bit per plane).
/// Returns the clipped convex polygon (fewer than 3 vertices if nothing is left).
pub(crate) fn clip_triangle(planes: &Planes, tri: [ClipVert; 3], mask: u32) -> Poly {
    let mut cur = Poly {
        v: [ClipVert::default(); MAX_POLY + 1],
        n: 0,
    };
    for c in tri {
        cur.push(c);
    }
    for i in 0..PLANES {
        if mask & (1 << i) == 0 {
            continue;
        }
        let mut next = Poly {
            v: [ClipVert::default(); MAX_POLY + 1],
            n: 0,
        };
        let n = cur.n;
        for j in 0..n {
            let a = &cur.v[j];
            let b = &cur.v[(j + 1) % n];
            let da = planes.dist(i, &a.p);
            let db = planes.dist(i, &b.p);
            if da >= 0.0 {
                next.push(*a);
            }
            if (da >= 0.0) != (db >= 0.0) {
                // From the inside vertex to the outside one (see the module docs). When the
                // inside vertex lies on the plane (d == 0) it is the intersection itself and
                // is (or will be) in the polygon already.
                let (pin, din, pout, dout) = if da >= 0.0 {
                    (a, da, b, db)
                } else {
                    (b, db, a, da)
                };
                if din > 0.0 {
                    next.push(lerp(pin, pout, din / (din - dout)));
                }
            }
        }
        cur = next;
        if cur.n < 3 {
            break;
        }
    }
    cur
}

/// Cross product of `(a - o)` and `(b - o)` in i64 (coordinates below 2^30 in magnitude).
#[inline]
fn cross(o: [i64; 2], a: [i64; 2], b: [i64; 2]) -> i64 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

/// Strict convex hull (Andrew's monotone chain, collinear and duplicate points dropped) of the
/// snapped polygon vertices `pts`. Writes indices into `pts`, positively oriented (the sign
/// of [`super::coverage::area2`]), and returns their number.
///
/// Why a hull: snapping can make a thin clipped polygon slightly non-convex, and a fan of a
/// non-convex polygon has overlapping (flipped) pieces: duplicate fragments of one source
/// triangle. A fan of a strictly convex polygon never overlaps and its pieces share their
/// diagonals exactly, so the fill rule covers every sample once.
pub(crate) fn convex_hull(pts: &[[i64; 2]], out: &mut [usize; MAX_POLY + 1]) -> usize {
    let n = pts.len().min(MAX_POLY + 1);
    let mut order = [0usize; MAX_POLY + 1];
    for (i, o) in order.iter_mut().enumerate().take(n) {
        *o = i;
    }
    order[..n].sort_unstable_by_key(|&i| (pts[i][0], pts[i][1]));
    // Lower and upper chains into a buffer of 2n.
    let mut hull = [0usize; 2 * (MAX_POLY + 1)];
    let mut k = 0usize;
    for &i in &order[..n] {
        while k >= 2 && cross(pts[hull[k - 2]], pts[hull[k - 1]], pts[i]) <= 0 {
            k -= 1;
        }
        hull[k] = i;
        k += 1;
    }
    let lower = k + 1;
    for &i in order[..n].iter().rev().skip(1) {
        while k >= lower && cross(pts[hull[k - 2]], pts[hull[k - 1]], pts[i]) <= 0 {
            k -= 1;
        }
        hull[k] = i;
        k += 1;
    }
    // The last point repeats the first.
    let m = k.saturating_sub(1);
    if m < 3 {
        return 0;
    }
    out[..m].copy_from_slice(&hull[..m]);
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cv(x: f64, y: f64, z: f64, w: f64, k: usize) -> ClipVert {
        let mut b = [0.0; 3];
        b[k] = 1.0;
        ClipVert { p: [x, y, z, w], b }
    }

    #[test]
    fn outcode_matches_dist() {
        let pl = Planes::new(640, 480);
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 2.0
        };
        for _ in 0..10000 {
            let s = [1.0, 10.0, 1e4][(rnd().abs() * 2.99) as usize];
            let p = [rnd() * s * 1e4, rnd() * s * 1e4, rnd() * s, rnd() * s];
            let oc = pl.outcode(&p);
            for i in 0..PLANES {
                assert_eq!(oc & (1 << i) != 0, pl.dist(i, &p) < 0.0);
            }
        }
        assert_eq!(pl.outcode(&[f64::NAN, 0.0, 0.0, 1.0]), NON_FINITE);
    }

    #[test]
    fn near_plane_clip_keeps_inside_part() {
        let pl = Planes::new(100, 100);
        // One vertex behind the near plane (z < -w).
        let t = [
            cv(0.0, 0.0, -2.0, 1.0, 0),
            cv(1.0, 0.0, 0.0, 1.0, 1),
            cv(0.0, 1.0, 0.0, 1.0, 2),
        ];
        let p = clip_triangle(&pl, t, 0b10);
        assert_eq!(p.n, 4);
        for v in &p.v[..p.n] {
            assert!(pl.dist(1, &v.p) >= -1e-12);
            let s: f64 = v.b.iter().sum();
            assert!((s - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn shared_edge_intersections_are_identical() {
        let pl = Planes::new(100, 100);
        let a = cv(0.3, 0.1, 0.5, 1.0, 0);
        let b = cv(-0.7, 0.4, -3.0, 1.0, 1);
        let c1 = cv(0.9, -0.8, 0.0, 1.0, 2);
        let c2 = cv(-0.9, 0.8, 0.2, 1.0, 2);
        let p1 = clip_triangle(&pl, [a, b, c1], 0b10);
        let p2 = clip_triangle(&pl, [b, a, c2], 0b10);
        let find = |p: &Poly| {
            p.v[..p.n]
                .iter()
                .filter(|v| v.b[0] != 1.0 && v.b[1] != 0.0 && v.b[2] == 0.0)
                .map(|v| v.p)
                .collect::<Vec<_>>()
        };
        let i1 = find(&p1);
        let i2 = find(&p2);
        assert_eq!(i1.len(), 1);
        assert_eq!(i1, i2);
    }

    #[test]
    fn hull_drops_collinear_and_reflex() {
        let pts = [
            [0, 0],
            [10, 0],
            [20, 0],
            [20, 20],
            [10, 11],
            [10, 9],
            [0, 20],
        ];
        let mut out = [0; MAX_POLY + 1];
        let m = convex_hull(&pts, &mut out);
        let mut got: Vec<usize> = out[..m].to_vec();
        got.sort();
        assert_eq!(got, vec![0, 2, 3, 6]);
        // Degenerate input.
        assert_eq!(convex_hull(&[[0, 0], [1, 1], [2, 2]], &mut out), 0);
    }
}
