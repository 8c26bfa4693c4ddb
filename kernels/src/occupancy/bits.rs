//! The arithmetic of an occupancy map, as pure functions shared by the fill and count
//! kernels and by the host-side checks (occupancy-fragment-culling paper, section 2).
//!
//! A pixel's depth range `[zn, zf]` is cut into `S = 32 d` uniform sub-intervals, bit `j` of
//! the pixel's `d` words standing for sub-interval `j`. Everything here is monotone in the
//! depth, which is what makes the culling test agree with the fill exactly:
//!
//! - [`bucket`] maps a depth to its sub-interval, clamped to `[0, S - 1]`: a depth outside
//!   the range (a bounding volume that misses by a rounding step, a near plane cutting the
//!   hull) lands in the first or last sub-interval, never nowhere, so every fragment sets a
//!   bit and the proof of Lemma 2.1 holds whatever range was used;
//! - [`kth_bucket`] is the count pass: Brian Kernighan's loop (`b & (b - 1)` clears the
//!   lowest set bit) over the words until `k` bits are counted, O(k) bit steps;
//! - [`bucket_bound`] turns the sub-interval found into the depth written to the depth
//!   buffer: the largest depth whose bucket is at most that sub-interval. The peel pass's
//!   early `LEQUAL` test then passes a fragment exactly when its bucket is at or before the
//!   k-th occupied one. The paper writes the sub-interval's upper end `zn + (i+1)(zf-zn)/S`;
//!   in floating point that value can round to either side of a fragment that the fill put
//!   in bucket `i`, so the bound is found by bisection on the same [`bucket`] function.

/// Sub-intervals per 32-bit word.
pub const BITS_PER_WORD: u32 = 32;

/// The depth written where nothing is culled (the far plane: every fragment passes
/// `LEQUAL`, as clipping keeps window depths in `[0, 1]`).
pub const NO_CULLING: f32 = 1.0;

/// The culling test: a fragment at `depth` passes its pixel's `bound` as the peel pass's
/// early `LEQUAL` depth test lets it through (`depth <= bound`; a NaN on either side fails).
/// The oracle and kernels that test the bound themselves use this one definition.
pub fn passes(depth: f32, bound: f32) -> bool {
    depth <= bound
}

/// The sub-interval of depth `z` in `[zn, zf]` cut into `s` parts, clamped to `[0, s - 1]`.
/// An empty or inverted range (`zf <= zn`, or a NaN) puts everything in sub-interval 0.
#[inline(always)]
pub fn bucket(z: f32, zn: f32, zf: f32, s: u32) -> u32 {
    let width = zf - zn;
    // NaN compares as not greater: an empty, inverted or NaN range is one sub-interval.
    if width.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return 0;
    }
    let t = (z - zn) / width * s as f32;
    if t.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        0
    } else if t >= (s - 1) as f32 {
        s - 1
    } else {
        t as u32
    }
}

/// The count pass on one pixel's words: the sub-interval holding the `k`-th set bit, by
/// Kernighan's loop, or `None` when fewer than `k` bits are set (no culling for the pixel).
/// `k` must be at least 1.
pub fn kth_bucket(words: &[u32], k: u32) -> Option<u32> {
    let mut counter = 0;
    for (w, &word) in words.iter().enumerate() {
        if let Some(j) = count_word(word, k, &mut counter) {
            return Some(w as u32 * BITS_PER_WORD + j);
        }
    }
    None
}

/// One word of the count pass: Kernighan's loop (`b & (b - 1)` clears the lowest set bit)
/// adds the word's set bits to `counter` one by one; when it reaches `k`, the position of
/// that bit within the word. The count kernel runs it word by word as it loads them.
#[inline(always)]
pub fn count_word(word: u32, k: u32, counter: &mut u32) -> Option<u32> {
    let mut b = word;
    while b != 0 {
        *counter += 1;
        if *counter == k {
            return Some(b.trailing_zeros());
        }
        b &= b - 1;
    }
    None
}

/// The largest depth in `[0, 1]` whose [`bucket`] is at most `i` (1.0 when every depth is).
/// Bisection over the bit patterns of non-negative floats, whose order is the floats'.
pub fn bucket_bound(i: u32, zn: f32, zf: f32, s: u32) -> f32 {
    let one = NO_CULLING.to_bits();
    if bucket(NO_CULLING, zn, zf, s) <= i {
        return NO_CULLING;
    }
    // Invariant: bucket(lo) <= i < bucket(hi). bucket(0) is 0 unless zn < 0, and window
    // depths are never negative; a negative zn still satisfies it for i >= bucket(0).
    let (mut lo, mut hi) = (0u32, one);
    if bucket(0.0, zn, zf, s) > i {
        return 0.0;
    }
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if bucket(f32::from_bits(mid), zn, zf, s) <= i {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    f32::from_bits(lo)
}

/// The culling bound of one pixel from its words and range: [`bucket_bound`] of the
/// [`kth_bucket`], or [`NO_CULLING`].
pub fn pixel_bound(words: &[u32], k: u32, zn: f32, zf: f32) -> f32 {
    let s = words.len() as u32 * BITS_PER_WORD;
    match kth_bucket(words, k) {
        Some(i) => bucket_bound(i, zn, zf, s),
        None => NO_CULLING,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_kth_bit_in_the_first_word() {
        // Bits 1, 4, 9 set: the 2nd is bit 4.
        assert_eq!(kth_bucket(&[0b10_0001_0010, 0], 2), Some(4));
        assert_eq!(kth_bucket(&[0b10_0001_0010, 0], 1), Some(1));
        assert_eq!(kth_bucket(&[0b10_0001_0010, 0], 3), Some(9));
    }

    #[test]
    fn the_kth_bit_across_a_word_boundary() {
        // Bits 30, 31 of word 0 and bit 0 of word 1.
        let words = [3 << 30, 1, 0];
        assert_eq!(kth_bucket(&words, 2), Some(31));
        assert_eq!(kth_bucket(&words, 3), Some(32));
    }

    #[test]
    fn the_kth_bit_in_the_last_word() {
        let words = [1, 0, 0, 1 << 31];
        assert_eq!(kth_bucket(&words, 2), Some(127));
    }

    #[test]
    fn fewer_than_k_bits_means_no_culling() {
        let words = [1, 0, 1 << 7];
        assert_eq!(kth_bucket(&words, 3), None);
        assert_eq!(pixel_bound(&words, 3, 0.2, 0.8), NO_CULLING);
        assert_eq!(kth_bucket(&[0; 4], 1), None);
    }

    #[test]
    fn buckets_are_clamped_and_monotone() {
        let (zn, zf, s) = (0.25, 0.75, 64);
        assert_eq!(bucket(0.0, zn, zf, s), 0);
        assert_eq!(bucket(0.25, zn, zf, s), 0);
        assert_eq!(bucket(0.75, zn, zf, s), 63);
        assert_eq!(bucket(1.0, zn, zf, s), 63);
        assert_eq!(bucket(0.5, zn, zf, s), 32);
        // Empty, inverted and NaN ranges: one sub-interval.
        assert_eq!(bucket(0.5, 0.5, 0.5, s), 0);
        assert_eq!(bucket(0.5, 0.9, 0.1, s), 0);
        assert_eq!(bucket(0.5, f32::NAN, 0.1, s), 0);
        let mut last = 0;
        for i in 0..=10_000 {
            let b = bucket(i as f32 / 10_000.0, zn, zf, s);
            assert!(b >= last, "not monotone at {i}");
            last = b;
        }
    }

    #[test]
    fn the_bound_is_exactly_the_last_depth_of_its_bucket() {
        let (zn, zf, s) = (0.1f32, 0.9f32, 96);
        for i in 0..s - 1 {
            let b = bucket_bound(i, zn, zf, s);
            assert!(
                bucket(b, zn, zf, s) <= i,
                "bucket {i}: bound {b} is past it"
            );
            let next = f32::from_bits(b.to_bits() + 1);
            assert!(
                bucket(next, zn, zf, s) > i,
                "bucket {i}: bound {b} is not the last"
            );
        }
        assert_eq!(bucket_bound(s - 1, zn, zf, s), NO_CULLING);
    }

    /// Lemma 2.1 on random pixels: whatever the depths, the k nearest pass the test
    /// `z <= bound`; and losing bits (a racy fill) only moves the bound farther.
    #[test]
    fn lemma_2_1_holds_and_lost_bits_only_move_the_bound_farther() {
        let mut state = 0x9e37_79b9_u32;
        let mut rnd = move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state
        };
        for case in 0..2000 {
            let d = 1 + rnd() % 4;
            let k = 1 + rnd() % 12;
            let n = 1 + rnd() % 40;
            let mut zs: Vec<f32> = (0..n)
                .map(|_| (rnd() % 1_000_000) as f32 / 1_000_000.0)
                .collect();
            if case % 3 == 0 {
                // Coplanar clusters.
                for z in zs.iter_mut() {
                    *z = (*z * 4.0).floor() / 4.0;
                }
            }
            let zn = zs.iter().copied().fold(f32::INFINITY, f32::min);
            let zf = zs.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            let s = d * BITS_PER_WORD;
            let mut words = vec![0u32; d as usize];
            for &z in &zs {
                let j = bucket(z, zn, zf, s);
                words[(j / 32) as usize] |= 1 << (j % 32);
            }
            let bound = pixel_bound(&words, k, zn, zf);
            zs.sort_by(f32::total_cmp);
            for z in zs.iter().take(k as usize) {
                assert!(
                    *z <= bound,
                    "case {case}: a k-nearest depth {z} is culled by {bound}"
                );
            }
            // Lose a random subset of the bits.
            let lossy: Vec<u32> = words.iter().map(|w| w & rnd()).collect();
            assert!(pixel_bound(&lossy, k, zn, zf) >= bound, "case {case}");
        }
    }
}
