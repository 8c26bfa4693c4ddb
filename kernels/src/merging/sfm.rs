//! Smooth fragment merging (SFM) and visibility subdivision (Kim & Kye, "Z-Thickness
//! Blending: Effective Fragment Merging for Multi-Fragment Rendering", sections 3.2.1 and
//! 3.3.1, equations 1 to 5).
//!
//! A fragment's band is a homogeneous medium, so its visibility can be cut along z:
//!
//! - equations 1-2: the opacity accumulated over depth `z` of a medium of thickness `d` and
//!   opacity `A_d` is `1 - (1 - A_d)^(z / d)`;
//! - equation 4: blended with the linear approximation `z / d * A_d` by β (0: exact optics,
//!   1: linear, smoother transitions);
//! - equation 3: the colour follows the opacity, `C(z) = C_d A(z) / A_d`;
//! - equation 5: the back part is what the over operator needs to give back the whole:
//!   `(C_b, A_b) = ((C_d, A_d) - (C(z), A(z))) / (1 - A(z))`.
//!
//! SFM of two overlapping fragments, sorted in depth order: both bands are cut at every
//! z-boundary of either (at most three pieces, section 3.2.1), the pieces where both media
//! are present are combined with the mix operator (section 3.3.2: "completely overlapping
//! fragments ... contribute equally"; the red rectangles of Figure 5), and the pieces are
//! composited front to back with the over operator into one fragment that covers both bands
//! (section 3.2: the larger depth, a thickness covering both).
//!
//! The paper leaves open how the fully overlapping pieces are combined in SFM; the mix
//! operator is our reading of Figure 5 and section 3.3.2, and it makes SFM symmetric in
//! coincident fragments (z-fighting surfaces blend, whatever their order).

use super::ofm::mix;
use super::record::{over, ZFrag};

/// Equation 4 (with equation 2): the opacity over depth `z` into a medium of thickness `d`
/// and opacity `ad`.
pub fn partial_opacity(ad: f32, z: f32, d: f32, beta: f32) -> f32 {
    if z <= 0.0 || d <= 0.0 {
        return if z >= d { ad } else { 0.0 };
    }
    if z >= d {
        return ad;
    }
    let r = z / d;
    beta * r * ad + (1.0 - beta) * (1.0 - (1.0 - ad).powf(r))
}

/// Equations 3 and 4: the visibility of the front `z` of a medium `v` of thickness `d`.
pub fn front_part(v: [f32; 4], z: f32, d: f32, beta: f32) -> [f32; 4] {
    let a = partial_opacity(v[3], z, d, beta);
    let k = if v[3] > 0.0 { a / v[3] } else { 0.0 };
    [v[0] * k, v[1] * k, v[2] * k, a]
}

/// Equation 5: the visibility of what lies behind `front` in the medium `v`.
pub fn back_part(v: [f32; 4], front: [f32; 4]) -> [f32; 4] {
    let rest = 1.0 - front[3];
    if rest <= 0.0 {
        return [0.0; 4];
    }
    [
        (v[0] - front[0]) / rest,
        (v[1] - front[1]) / rest,
        (v[2] - front[2]) / rest,
        (v[3] - front[3]) / rest,
    ]
}

/// A band being cut into pieces from the front: what is left of it.
struct Medium {
    /// Front boundary of what is left.
    from: f32,
    /// Back boundary.
    to: f32,
    v: [f32; 4],
}

impl Medium {
    fn of(f: &ZFrag) -> Medium {
        Medium {
            from: f.front(),
            to: f.z,
            v: f.v,
        }
    }

    /// The piece from the current front to `until`, cut off (the whole rest at the back
    /// boundary, so that the pieces give back the band exactly).
    fn cut(&mut self, until: f32, beta: f32) -> [f32; 4] {
        if until <= self.from {
            return [0.0; 4];
        }
        if until >= self.to {
            self.from = self.to;
            return std::mem::replace(&mut self.v, [0.0; 4]);
        }
        let front = front_part(self.v, until - self.from, self.to - self.from, beta);
        self.v = back_part(self.v, front);
        self.from = until;
        front
    }

    fn covers(&self, lo: f32, hi: f32) -> bool {
        self.from <= lo && hi <= self.to && lo < hi
    }
}

/// SFM of two overlapping fragments in depth order (`near.z <= far.z`): one fragment covering
/// both bands, its visibility the over-composite of the cut pieces (mixed where both media
/// are present).
pub fn sfm(near: &ZFrag, far: &ZFrag, beta: f32) -> ZFrag {
    let mut m = [Medium::of(near), Medium::of(far)];
    let mut cuts = [near.front(), near.z, far.front(), far.z];
    cuts.sort_by(f32::total_cmp);
    let mut acc = [0.0f32; 4];
    for w in cuts.windows(2) {
        let (lo, hi) = (w[0], w[1]);
        if lo >= hi {
            continue;
        }
        let inside = [m[0].covers(lo, hi), m[1].covers(lo, hi)];
        let pieces = [m[0].cut(hi, beta), m[1].cut(hi, beta)];
        let piece = match inside {
            [true, true] => mix(pieces[0], pieces[0][3], pieces[1], pieces[1][3]),
            [true, false] => pieces[0],
            [false, true] => pieces[1],
            [false, false] => continue,
        };
        acc = over(acc, piece);
    }
    let z = near.z.max(far.z);
    ZFrag {
        z,
        t: z - near.front().min(far.front()),
        v: acc,
        a: near.a + far.a,
        n: near.n + far.n,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f32; 4], b: [f32; 4], tol: f32) -> bool {
        (0..4).all(|c| (a[c] - b[c]).abs() <= tol)
    }

    #[test]
    fn subdivision_gives_back_the_fragment_for_every_beta() {
        // Equation 5 makes over(front, back) the original whatever equation 4's beta.
        let v = [0.5 * 0.7, 0.2 * 0.7, 0.9 * 0.7, 0.7];
        for beta in [0.0, 0.3, 0.6, 1.0] {
            for z in [0.1, 0.5, 0.93] {
                let f = front_part(v, z, 1.0, beta);
                let b = back_part(v, f);
                assert!(close(over(f, b), v, 1e-6), "beta {beta} z {z}");
            }
        }
        // beta = 0 is exact optics: two halves are the same medium (equation 2).
        let f = front_part(v, 0.5, 1.0, 0.0);
        let b = back_part(v, f);
        assert!(close(f, b, 1e-6), "{f:?} {b:?}");
        // beta = 1 is linear in z.
        assert!((partial_opacity(0.7, 0.25, 1.0, 1.0) - 0.175).abs() < 1e-7);
    }

    #[test]
    fn sfm_of_coincident_fragments_is_their_mix_in_either_order() {
        let r = ZFrag::new(1.0, 0.2, [1.0, 0.0, 0.0], 0.5);
        let b = ZFrag::new(1.0, 0.2, [0.0, 0.0, 1.0], 0.5);
        let rb = sfm(&r, &b, 0.0);
        let br = sfm(&b, &r, 0.0);
        assert!(close(rb.v, br.v, 1e-6));
        assert!(close(rb.v, mix(r.v, r.a, b.v, b.a), 1e-6));
        assert_eq!((rb.z, rb.n), (1.0, 2.0));
        assert!((rb.t - 0.2).abs() < 1e-6);
    }

    #[test]
    fn sfm_tends_to_the_over_composite_as_the_overlap_vanishes() {
        // Two bands of thickness t behind each other, 1 apart: they overlap by t - 1. As
        // the overlap goes to 0 the SFM visibility goes to over(near, far), for every beta.
        let near = ZFrag::new(1.0, 0.0, [0.9, 0.2, 0.1], 0.4);
        let far = ZFrag::new(2.0, 0.0, [0.1, 0.3, 0.8], 0.6);
        let want = over(near.v, far.v);
        for beta in [0.0, 0.5, 1.0] {
            let mut last = f32::INFINITY;
            for overlap in [0.5f32, 0.1, 1e-2, 1e-3, 1e-4] {
                let t = 1.0 + overlap;
                let (n, f) = (ZFrag { t, ..near }, ZFrag { t, ..far });
                assert!(n.overlaps(&f));
                let got = sfm(&n, &f, beta);
                let err = (0..4)
                    .map(|c| (got.v[c] - want[c]).abs())
                    .fold(0.0, f32::max);
                assert!(
                    err <= last + 1e-6,
                    "beta {beta}: not converging ({err} after {last})"
                );
                last = err;
            }
            assert!(last < 1e-3, "beta {beta}: {last}");
        }
    }

    #[test]
    fn sfm_of_a_band_inside_another_cuts_it_in_three() {
        // far [0, 10] contains near [4, 6]: far's pieces [0,4], [4,6] (mixed with near),
        // [6,10]. With a transparent inner band the result is the outer band itself.
        let outer = ZFrag::new(10.0, 10.0, [0.2, 0.4, 0.6], 0.8);
        let clear = ZFrag::new(6.0, 2.0, [1.0, 1.0, 1.0], 0.0);
        let m = sfm(&clear, &outer, 0.0);
        assert!(close(m.v, outer.v, 1e-6), "{:?} vs {:?}", m.v, outer.v);
        assert_eq!((m.z, m.t), (10.0, 10.0));
        // An opaque inner band hides what is behind it: only the front 4 of the outer shows.
        let opaque = ZFrag::new(6.0, 2.0, [1.0, 1.0, 1.0], 1.0);
        let m = sfm(&opaque, &outer, 0.0);
        let front = front_part(outer.v, 4.0, 10.0, 0.0);
        let middle = front_part(back_part(outer.v, front), 2.0, 6.0, 0.0);
        assert!((m.v[3] - 1.0).abs() < 1e-6);
        let want = over(front, mix(middle, middle[3], opaque.v, opaque.a));
        assert!(close(m.v, want, 1e-5), "{:?} vs {want:?}", m.v);
    }
}
