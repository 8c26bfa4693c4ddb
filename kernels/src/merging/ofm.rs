//! Order-independent fragment merging (OFM) and the mix operator (Kim & Kye, "Z-Thickness
//! Blending: Effective Fragment Merging for Multi-Fragment Rendering", sections 3.2.2 and
//! 3.3.2, equations 6 to 8).
//!
//! Overlapping fragments are merged into one, with no subdivision: the merged band covers
//! both (depth = the larger depth, thickness down to the nearer front boundary, section 3.2),
//! and its visibility is the mix of theirs, in which every fragment counts equally whatever
//! its depth or arrival order:
//!
//! - equation 6: `A_acc = 1 - prod_i (1 - A_i)`;
//! - equation 7: `C_acc = (sum_i C_i / sum_i A_i) A_acc`;
//! - equation 8, the recurrence a store pass applies one fragment at a time, carrying
//!   `A_sum = sum_i A_i` in the record: `A~ = 1 - (1 - A_acc)(1 - A_new)`,
//!   `C~ = (C_acc / A_acc * A_sum + C_new) / (A_sum + A_new) * A~`.
//!
//! [`mix`] is equation 8 for two records that may both be merged already (a fragment that
//! bridges two stored ones merges all three): a record's colour sum is `C / A * A_sum`,
//! which for an original fragment (`A_sum = A`) is its `C`, as in the paper's recurrence.
//!
//! Mathematically the result depends on the set of fragments only. In floating point it does
//! not quite: `C / A * A_sum` and the product of `1 - A` round differently in each order. The
//! test `ofm_of_5_fragments_is_the_same_in_every_order` measures by how much.

use super::record::ZFrag;

/// A record's colour sum `sum_i C_i` as equation 8 recovers it: `C_acc / A_acc * A_sum`.
fn colour_sum(v: [f32; 4], a: f32, c: usize) -> f32 {
    if v[3] > 0.0 {
        v[c] / v[3] * a
    } else {
        0.0
    }
}

/// Equation 8: the visibility of records `acc` (visibility and `A_sum`) and `new` mixed.
pub fn mix(acc: [f32; 4], acc_sum: f32, new: [f32; 4], new_sum: f32) -> [f32; 4] {
    let alpha = 1.0 - (1.0 - acc[3]) * (1.0 - new[3]);
    let sum = acc_sum + new_sum;
    let mut out = [0.0, 0.0, 0.0, alpha];
    if sum > 0.0 {
        for (c, o) in out.iter_mut().enumerate().take(3) {
            *o = (colour_sum(acc, acc_sum, c) + colour_sum(new, new_sum, c)) / sum * alpha;
        }
    }
    out
}

/// OFM of two overlapping records (either order): one band covering both, visibility by the
/// mix operator, `A_sum` and the merged count added.
pub fn ofm(stored: &ZFrag, incoming: &ZFrag) -> ZFrag {
    let z = stored.z.max(incoming.z);
    ZFrag {
        z,
        t: z - stored.front().min(incoming.front()),
        v: mix(stored.v, stored.a, incoming.v, incoming.a),
        a: stored.a + incoming.a,
        n: stored.n + incoming.n,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Five overlapping fragments of different colours, opacities, depths and thicknesses.
    fn five() -> [ZFrag; 5] {
        [
            ZFrag::new(1.00, 0.30, [0.9, 0.1, 0.2], 0.3),
            ZFrag::new(1.10, 0.25, [0.2, 0.8, 0.3], 0.55),
            ZFrag::new(0.95, 0.20, [0.1, 0.3, 0.95], 0.7),
            ZFrag::new(1.20, 0.40, [0.6, 0.6, 0.1], 0.15),
            ZFrag::new(1.05, 0.35, [0.33, 0.21, 0.77], 0.9),
        ]
    }

    fn permutations(n: usize) -> Vec<Vec<usize>> {
        if n == 0 {
            return vec![vec![]];
        }
        let mut out = Vec::new();
        for p in permutations(n - 1) {
            for i in 0..n {
                let mut q = p.clone();
                q.insert(i, n - 1);
                out.push(q);
            }
        }
        out
    }

    /// Equations 6 and 7 directly, in f64: the exact mix of a set.
    fn exact(frags: &[ZFrag]) -> [f64; 4] {
        let alpha = 1.0 - frags.iter().map(|f| 1.0 - f.v[3] as f64).product::<f64>();
        let sa: f64 = frags.iter().map(|f| f.v[3] as f64).sum();
        let mut out = [0.0, 0.0, 0.0, alpha];
        for (c, o) in out.iter_mut().enumerate().take(3) {
            *o = frags.iter().map(|f| f.v[c] as f64).sum::<f64>() / sa * alpha;
        }
        out
    }

    /// Largest difference of two visibilities, channel by channel.
    fn diff(a: [f32; 4], b: [f32; 4]) -> f32 {
        (0..4).map(|c| (a[c] - b[c]).abs()).fold(0.0, f32::max)
    }

    #[test]
    fn ofm_of_5_fragments_is_the_same_in_every_order() {
        let frags = five();
        let perms = permutations(5);
        assert_eq!(perms.len(), 120);
        let merged: Vec<ZFrag> = perms
            .iter()
            .map(|p| {
                p[1..]
                    .iter()
                    .fold(frags[p[0]], |acc, &i| ofm(&acc, &frags[i]))
            })
            .collect();
        let first = merged[0];
        let mut worst = 0.0f32;
        for m in &merged {
            // The band, A_sum and count are order independent exactly (max, min, sums of
            // the same five values may round differently: compare A_sum loosely).
            assert_eq!((m.z, m.t, m.n), (first.z, first.t, first.n));
            assert!((m.a - first.a).abs() <= 2.0 * f32::EPSILON * m.a);
            worst = worst.max(diff(m.v, first.v));
        }
        // Measured: the mix is not bit-exactly associative in f32; the worst difference
        // between two orders of these five fragments is one ulp of 1 (1.19e-7).
        eprintln!("OFM, 120 orders of 5 fragments: worst visibility difference {worst:e}");
        assert!(worst <= 2.0 * f32::EPSILON, "worst difference {worst}");
        // And every order is the exact mix of equations 6 and 7 up to the same rounding.
        let e = exact(&frags);
        for m in &merged {
            for c in 0..4 {
                assert!((m.v[c] as f64 - e[c]).abs() < 1e-6, "{:?} vs {e:?}", m.v);
            }
        }
        assert_eq!(first.n, 5.0);
        assert_eq!(first.z, 1.2);
        assert!((first.t - (1.2 - 0.7)).abs() < 1e-6);
    }

    #[test]
    fn mixing_is_over_free_coplanar_averaging() {
        // Two coincident fragments: the opacity of both, the opacity-weighted average colour,
        // whichever is in front (the smooth blend of z-fighting surfaces, Figure 3).
        let r = ZFrag::new(1.0, 0.1, [1.0, 0.0, 0.0], 0.5);
        let b = ZFrag::new(1.0, 0.1, [0.0, 0.0, 1.0], 0.5);
        let m = ofm(&r, &b);
        assert_eq!(m.v, ofm(&b, &r).v);
        assert!((m.v[3] - 0.75).abs() < 1e-7);
        assert!((m.v[0] - 0.375).abs() < 1e-7 && (m.v[2] - 0.375).abs() < 1e-7);
        // Fully transparent records contribute nothing and divide by nothing.
        let clear = ZFrag::new(1.0, 0.1, [0.3, 0.3, 0.3], 0.0);
        assert_eq!(ofm(&clear, &clear).v, [0.0; 4]);
        assert_eq!(ofm(&r, &clear).v, r.v);
    }
}
