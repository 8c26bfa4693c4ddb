//! Algorithm 1 of Kim & Kye, "Z-Thickness Blending: Effective Fragment Merging for
//! Multi-Fragment Rendering" (section 4.1.1, "Output fragments (resolve pass)"), with the
//! tail handling of section 4.1.2: N fragments sorted in depth order out to at most M,
//! merging overlapping neighbours with SFM, in one linear sweep. Once M - 1 fragments are
//! out, every later fragment is folded into the last one (lines 14-18): the over operator on
//! the visibilities, the band stretched to the later fragment's depth, `A_sum` added.

use super::record::{over, ZFrag};
use super::sfm::sfm;

/// Algorithm 1: `input` (sorted by depth `z`) merged into at most `m` (>= 1) fragments,
/// appended to `out` front to back.
pub fn output_fragments(input: &[ZFrag], m: usize, beta: f32, out: &mut Vec<ZFrag>) {
    let m = m.max(1);
    let start = out.len();
    let Some(&first) = input.first() else {
        return;
    };
    let mut fi = Some(first); // line 3
    for i in 0..input.len() {
        // line 4
        let Some(mut cur) = fi else { break };
        let fnext = input.get(i + 1).copied(); // lines 5-7
        let fmerge = match fnext {
            Some(next) if cur.overlaps(&next) => Some(sfm(&cur, &next, beta)), // lines 8-9
            _ => None,
        };
        match fmerge {
            None if out.len() - start < m - 1 => {
                // lines 11-13
                out.push(cur);
                fi = fnext;
            }
            None => {
                if let Some(next) = fnext {
                    // lines 14-18: tail handling
                    cur.v = over(cur.v, next.v);
                    cur.t += next.z - cur.z; // t := fnext.z - fi.z + fi.t
                    cur.z = next.z;
                    cur.a += next.a;
                    cur.n += next.n;
                }
                fi = Some(cur);
            }
            Some(merged) => fi = Some(merged), // line 20
        }
    }
    if let Some(last) = fi {
        // lines 21-22
        out.push(last);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::merging::record::composite;

    fn frag(z: f32, t: f32, c: f32) -> ZFrag {
        ZFrag::new(z, t, [c, 1.0 - c, 0.5], 0.35)
    }

    #[test]
    fn separate_fragments_pass_through_and_overlaps_merge() {
        let input = [
            frag(1.0, 0.1, 0.1),
            frag(2.0, 0.1, 0.2),
            frag(3.0, 0.1, 0.3),
        ];
        let mut out = Vec::new();
        output_fragments(&input, 8, 0.0, &mut out);
        assert_eq!(out, input);
        // 1.0 and 1.05 overlap (thickness 0.1): one fragment out of them.
        let input = [
            frag(1.0, 0.1, 0.1),
            frag(1.05, 0.1, 0.2),
            frag(3.0, 0.1, 0.3),
        ];
        out.clear();
        output_fragments(&input, 8, 0.0, &mut out);
        assert_eq!(out.len(), 2);
        assert_eq!(out[0], sfm(&input[0], &input[1], 0.0));
        assert_eq!(out[1], input[2]);
        assert_eq!(out.iter().map(|f| f.n).sum::<f32>(), 3.0);
    }

    #[test]
    fn a_chain_of_overlaps_merges_into_one() {
        let input: Vec<ZFrag> = (0..6)
            .map(|i| frag(1.0 + 0.05 * i as f32, 0.1, 0.1))
            .collect();
        let mut out = Vec::new();
        output_fragments(&input, 4, 0.0, &mut out);
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].n, 6.0);
        assert!((out[0].front() - 0.9).abs() < 1e-6 && out[0].z == input[5].z);
    }

    #[test]
    fn tail_handling_keeps_the_composite_of_everything() {
        // 10 separate fragments into M = 3: two out as they are, the rest folded into the
        // tail with the over operator, so the composite of the 3 is that of all 10.
        let input: Vec<ZFrag> = (0..10)
            .map(|i| frag(1.0 + i as f32, 0.0, i as f32 / 10.0))
            .collect();
        let mut out = Vec::new();
        output_fragments(&input, 3, 0.0, &mut out);
        assert_eq!(out.len(), 3);
        assert_eq!(&out[..2], &input[..2]);
        let tail = out[2];
        assert_eq!((tail.z, tail.t, tail.n), (10.0, 7.0, 8.0));
        assert!((tail.a - 8.0 * 0.35).abs() < 1e-5);
        let bg = [1.0, 1.0, 1.0];
        let (a, b) = (composite(&out, bg), composite(&input, bg));
        for c in 0..4 {
            assert!((a[c] - b[c]).abs() < 1e-6, "{a:?} vs {b:?}");
        }
        // M = 1: everything is the tail.
        out.clear();
        output_fragments(&input, 1, 0.0, &mut out);
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].n, 10.0);
        out.clear();
        output_fragments(&[], 3, 0.0, &mut out);
        assert!(out.is_empty());
    }
}
