//! The setup record of a triangle ([`SetupTriangle`]): its depth and barycentric planes,
//! computed bit-identically whatever the order of its vertices.

use crate::raster::coverage::ONE;
use crate::raster::SUBPIXEL_BITS;

/// A triangle after clipping and snapping, ready to rasterize.
///
/// 64 bytes, aligned to 64 (one cache line each in an array: a record that straddled two
/// lines cost a fragment two misses where the records come from memory, as a binned
/// pass's over a large mesh), no heap: the depth plane and three barycentric planes, each
/// relative to a reference pixel inside the viewport. The snapped vertices, needed only to
/// rasterize triangles larger than a pixel, live in the tile bins instead.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(align(64))]
pub struct SetupTriangle {
    /// Index of the input triangle (into `indices`) this comes from (several setup triangles share one
    /// source when clipping split it).
    pub source: u32,
    pub front_facing: bool,
    /// Reference pixel of the planes: the top-left corner of the pixels the triangle's
    /// bounding box reaches (clamped to the viewport), so plane evaluations stay short-range.
    pub(super) rx: i32,
    pub(super) ry: i32,
    /// Depth plane: `z(x, y) = depth[0] + depth[1] (x - rx) + depth[2] (y - ry)`, pixels.
    pub(super) depth: [f32; 3],
    /// Planes (same form) of `b_k / w`: the weight of source vertex `k` divided by clip `w`.
    /// Both are linear in screen space; normalising them gives perspective-correct
    /// barycentrics of the *source* triangle, also for the pieces of a clipped one.
    pub(super) bary: [[f32; 3]; 3],
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

    /// [`SetupTriangle::depth_at`] at the centre of pixel `(x, y)`, bit for bit: `x + 0.5` is
    /// exact in `f32` below 2^23 (frames are at most `MAX_DIMENSION` = 16384 pixels a side),
    /// and `(x + 0.5) - rx` is exact in `f64`, as `(x - rx) + 0.5` is, from integers. Taking
    /// the integers apart keeps the two coordinates in scalar registers: the packed form
    /// loaded `(x, y)` as one 8-byte word, which the store buffer cannot forward from the
    /// two 4-byte stores that wrote them just before (the executor writes `x` per pixel).
    #[inline]
    pub fn depth_at_center(&self, x: u32, y: u32) -> f32 {
        let z = eval(
            &self.depth,
            (i64::from(x) - i64::from(self.rx)) as f64 + 0.5,
            (i64::from(y) - i64::from(self.ry)) as f64 + 0.5,
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
pub(super) fn eval(p: &[f32; 3], dx: f64, dy: f64) -> f64 {
    p[0] as f64 + p[1] as f64 * dx + p[2] as f64 * dy
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
pub(super) fn planes(v: &[[i32; 2]; 3], a: &[[f32; 4]; 3], rx: i32, ry: i32) -> [[f32; 3]; 4] {
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
pub(super) fn plane_values_scalar(a: [&[f32; 4]; 3], c: [f64; 6]) -> [[f32; 3]; 4] {
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
pub(super) fn plane_values(a: [&[f32; 4]; 3], c: [f64; 6]) -> [[f32; 3]; 4] {
    plane_values_scalar(a, c)
}

/// `plane_values_scalar` (the scalar reference, in tests and off x86) with two attributes
/// per SSE2 register: the same IEEE operations in the same order (Rust does not contract
/// `a * b + c`), so the same bits, for half the instructions (a large part of setting up a
/// small triangle).
#[cfg(target_arch = "x86_64")]
#[inline]
pub(super) fn plane_values(a: [&[f32; 4]; 3], c: [f64; 6]) -> [[f32; 3]; 4] {
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
