//! Occupancy culling: concurrent fills of one pixel's map, then the count.

use fragrace_emu::kernel::FragInput;
use fragrace_emu::{Device, Fragment};
use fragrace_kernels::protocols::*;

use super::common::*;

// ---------------------------------------------------------------------------------------
// Occupancy culling ("Improving k-buffer methods via occupancy maps", section 2): concurrent
// fills of one pixel's map, then the count. The count's arithmetic is the same function the
// count kernel runs (`occupancy::bits`), applied here to the map the fills left.

use fragrace_kernels::occupancy::bits::{bucket, pixel_bound, BITS_PER_WORD};
use fragrace_kernels::occupancy::FillMode;

/// Fills one pixel's map (`d` words, range `[zn, zf]`) with one loom thread per fragment,
/// and returns the map and the count's bound for `k`.
fn occupancy_fill(frags: &[FragInput], d: u32, k: u32, mode: FillMode) -> (Vec<u32>, f32) {
    let (zn, zf) = (0.0, 1.0);
    let mut dev = Device::new();
    let map = dev.buffer::<u32>("occupancy-map", d as u64).unwrap();
    let near = dev.buffer::<f32>("occupancy-near", 1).unwrap();
    let far = dev.buffer::<f32>("occupancy-far", 1).unwrap();
    dev.memory.fill(near, zn).unwrap();
    dev.memory.fill(far, zf).unwrap();
    let fill = OccupancyFill {
        map,
        near,
        far,
        d,
        mode,
    };
    let (dev, _) = on_threads(dev, fill, frags, 1);
    let words = read(&dev, map);
    let bound = pixel_bound(&words, k, zn, zf);
    (words, bound)
}

/// The bits an exact fill sets.
fn exact_bits(frags: &[FragInput], d: u32) -> Vec<u32> {
    let mut w = vec![0u32; d as usize];
    for f in frags {
        let j = bucket(f.depth, 0.0, 1.0, d * BITS_PER_WORD);
        w[(j / BITS_PER_WORD) as usize] |= 1 << (j % BITS_PER_WORD);
    }
    w
}

#[test]
fn occupancy_atomic_fill_sets_every_bit_and_keeps_the_k_nearest() {
    // Three fragments in three sub-intervals of one word, one pair in the same word as
    // the third: the atomic ORs of every interleaving leave exactly the three bits, and the
    // count's bound passes the k = 2 nearest.
    model(3, || {
        let frags = stack(&[0.9, 0.05, 0.5]);
        let (words, bound) = occupancy_fill(&frags, 1, 2, FillMode::Atomic);
        assert_eq!(words, exact_bits(&frags, 1));
        for f in nearest(&frags, 2) {
            assert!(f.0 <= bound, "Lemma 2.1: {} culled by {bound}", f.0);
        }
        assert!(0.9 > bound, "the farthest fragment is culled");
    });
}

#[test]
fn loom_finds_the_plain_fill_losing_a_bit_and_lemma_2_1_still_holds() {
    // A plain read-OR-write fill loses a bit when two fragments of one word interleave;
    // the map then holds a subset of the true bits, so the k-th bit is at or beyond the
    // true one and the bound can only be farther: Lemma 2.1 holds in every interleaving.
    let hunt = Hunt::new("occupancy plain fill lost bit (2 invocations, bound 2)");
    let h = hunt.clone();
    model(3, move || {
        h.execution();
        let frags = stack(&[0.3, 0.1]);
        let (words, bound) = occupancy_fill(&frags, 1, 1, FillMode::Plain);
        let exact = exact_bits(&frags, 1);
        assert_eq!(words[0] & !exact[0], 0, "a plain fill never invents a bit");
        for f in nearest(&frags, 1) {
            assert!(f.0 <= bound, "Lemma 2.1: {} culled by {bound}", f.0);
        }
        h.saw(words != exact);
    });
    hunt.report();
}
