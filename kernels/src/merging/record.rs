//! The fragment record of the z-thickness model (Kim & Kye, "Z-Thickness Blending: Effective
//! Fragment Merging for Multi-Fragment Rendering", sections 3 and 3.3.2, Algorithm 1): depth
//! `z` of the surface (the band's back boundary), thickness `t`, visibility `v` (opacity and
//! opacity-weighted colour, "visibility represents the opacity and alpha-multiplied colour",
//! section 3), and the accumulated opacity sum `a` of equation 8 (`A_sum`, the paper's
//! `.a`). We add `n`, the number of original fragments merged into the record, as
//! instrumentation: the algorithms' invariants account for every fragment with it.
//!
//! Also the over operator (front-to-back blending of premultiplied visibilities, \[PD84\] in
//! the paper) and the composite of merged records over the background.

use crate::common::prim_rgb;

/// A fragment of the z-thickness model, possibly merged from several.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ZFrag {
    /// View depth of the surface: the band's back boundary.
    pub z: f32,
    /// z-thickness: the band spans `[z - t, z]`.
    pub t: f32,
    /// Visibility: opacity-weighted colour and opacity `[C_r, C_g, C_b, A]`.
    pub v: [f32; 4],
    /// `A_sum` of equation 8: the sum of the merged fragments' opacities.
    pub a: f32,
    /// Original fragments merged into this one (instrumentation).
    pub n: f32,
}

/// Words of a record in a kernel's `f32` buffer: z, t, v (4), a, n.
pub const WORDS: u32 = 8;

impl ZFrag {
    /// An empty slot: nothing merged, infinitely far (sorts last, overlaps nothing).
    pub const EMPTY: ZFrag = ZFrag {
        z: f32::INFINITY,
        t: 0.0,
        v: [0.0; 4],
        a: 0.0,
        n: 0.0,
    };

    /// One original fragment: colour `rgb` (not premultiplied) at opacity `alpha`.
    pub fn new(z: f32, t: f32, rgb: [f32; 3], alpha: f32) -> ZFrag {
        ZFrag {
            z,
            t,
            v: [rgb[0] * alpha, rgb[1] * alpha, rgb[2] * alpha, alpha],
            a: alpha,
            n: 1.0,
        }
    }

    /// One original fragment of primitive `prim` (the truth's colour of it) at opacity `alpha`.
    pub fn of_primitive(z: f32, t: f32, prim: u32, alpha: f32) -> ZFrag {
        let c = prim_rgb(prim);
        ZFrag::new(z, t, [c[0], c[1], c[2]], alpha)
    }

    /// Nothing merged: an empty slot (as [`ZFrag::EMPTY`] or zeroed memory).
    pub fn is_empty(&self) -> bool {
        self.n == 0.0
    }

    /// The band's front boundary.
    pub fn front(&self) -> f32 {
        self.z - self.t
    }

    /// Whether the two bands overlap: their open intervals `(z - t, z)` intersect. Bands of
    /// zero thickness overlap nothing, so coplanar fragments merge only with a thickness.
    pub fn overlaps(&self, o: &ZFrag) -> bool {
        self.front() < o.z && o.front() < self.z
    }

    pub fn to_words(&self) -> [f32; WORDS as usize] {
        [
            self.z, self.t, self.v[0], self.v[1], self.v[2], self.v[3], self.a, self.n,
        ]
    }

    pub fn from_words(w: &[f32]) -> ZFrag {
        ZFrag {
            z: w[0],
            t: w[1],
            v: [w[2], w[3], w[4], w[5]],
            a: w[6],
            n: w[7],
        }
    }
}

/// The over operator on premultiplied visibilities, `front` in front of `back`:
/// `front + (1 - A_front) back` (Algorithm 1, line 15).
pub fn over(front: [f32; 4], back: [f32; 4]) -> [f32; 4] {
    let k = 1.0 - front[3];
    [
        front[0] + k * back[0],
        front[1] + k * back[1],
        front[2] + k * back[2],
        front[3] + k * back[3],
    ]
}

/// Algorithm 1, line 23: the visibilities of `frags` (front to back) composited with the over
/// operator, then over `background`. RGBA as the other resolves write it (alpha = coverage).
pub fn composite(frags: &[ZFrag], background: [f32; 3]) -> [f32; 4] {
    let acc = frags.iter().fold([0.0; 4], |acc, f| over(acc, f.v));
    let k = 1.0 - acc[3];
    [
        acc[0] + k * background[0],
        acc[1] + k * background[1],
        acc[2] + k * background[2],
        acc[3],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algo::CapturedFrag;
    use crate::common::composite_frags;

    #[test]
    fn records_round_trip_and_empty_slots_overlap_nothing() {
        let f = ZFrag::of_primitive(2.0, 0.5, 7, 0.3);
        assert_eq!(ZFrag::from_words(&f.to_words()), f);
        assert!(!ZFrag::EMPTY.overlaps(&f) && !f.overlaps(&ZFrag::EMPTY));
        let g = ZFrag { z: 1.6, ..f };
        assert!(f.overlaps(&g) && g.overlaps(&f));
        // Touching bands do not overlap; zero-thickness coplanar fragments neither.
        let h = ZFrag { z: 1.5, ..f };
        assert!(!f.overlaps(&h));
        let thin = ZFrag { t: 0.0, ..f };
        assert!(!thin.overlaps(&thin));
    }

    #[test]
    fn the_composite_of_single_fragments_is_the_truths() {
        let prims = [3u32, 9, 1, 12];
        let frags: Vec<ZFrag> = prims
            .iter()
            .enumerate()
            .map(|(i, &p)| ZFrag::of_primitive(i as f32, 0.0, p, 0.3))
            .collect();
        let truth: Vec<CapturedFrag> = prims
            .iter()
            .enumerate()
            .map(|(i, &p)| CapturedFrag {
                depth: i as f32,
                prim: p,
            })
            .collect();
        let bg = [1.0, 0.5, 0.0];
        let (a, b) = (composite(&frags, bg), composite_frags(&truth, 0.3, bg));
        for c in 0..4 {
            assert!((a[c] - b[c]).abs() < 1e-6, "{a:?} vs {b:?}");
        }
    }
}
