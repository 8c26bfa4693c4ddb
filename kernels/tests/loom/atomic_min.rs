//! The atomic-min k-buffer chains (32- and 64-bit, and the 32-bit claim pass).

use fragrace_emu::kernel::FragInput;
use fragrace_emu::{Device, Fragment};
use fragrace_kernels::common::EMPTY;
use fragrace_kernels::protocols::*;

use super::common::*;

// ------------------------------------------------------------------------------------------
// Atomic-min k-buffers.
// ------------------------------------------------------------------------------------------

fn key32(d: f32) -> u32 {
    (d + 0.0).to_bits()
}

fn key64(d: f32, prim: u32) -> u64 {
    ((key32(d) as u64) << 32) | prim as u64
}

/// `kb-atomic32`'s depth pass (k = 2) on loom; returns the keys and the census count.
fn chain32(frags: &[FragInput]) -> (Vec<u32>, u32, u32) {
    let k = 2;
    let mut dev = Device::new();
    let key = dev.buffer::<u32>("kb-key", k as u64).unwrap();
    dev.memory.fill(key, EMPTY).unwrap();
    let census = Census {
        count: dev.buffer::<u32>("kb-count", 1).unwrap(),
        negative: dev.buffer::<u32>("kb-negative-depths", 1).unwrap(),
    };
    let (dev, _) = on_threads(dev, Depth32 { key, k, census }, frags, 1);
    (
        read(&dev, key),
        read(&dev, census.count)[0],
        read(&dev, census.negative)[0],
    )
}

/// The k smallest of `keys`, ascending, padded with `empty`.
fn k_smallest<T: Ord + Copy>(mut keys: Vec<T>, k: usize, empty: T) -> Vec<T> {
    keys.sort();
    keys.resize(keys.len().max(k), empty);
    keys.truncate(k);
    keys
}

#[test]
fn atomic_min_chain_32_keeps_the_k_smallest_keys() {
    model(3, || {
        let frags = stack(&[0.5, 0.25, 0.75]);
        let (keys, count, negative) = chain32(&frags);
        assert_eq!(keys, vec![key32(0.25), key32(0.5)]);
        assert_eq!((count, negative), (3, 0));
    });
}

#[test]
fn atomic_min_chain_32_keeps_equal_depths_as_separate_slots() {
    model(3, || {
        let frags = stack(&[0.5, 0.75, 0.5]);
        let (keys, count, _) = chain32(&frags);
        assert_eq!(keys, vec![key32(0.5), key32(0.5)]);
        assert_eq!(count, 3);
    });
}

#[test]
fn atomic32_claim_pass_gives_each_kept_slot_one_coplanar_fragment() {
    // Depth pass on the ordered executor, claim pass on loom: three coplanar fragments race
    // for the two slots of their depth by compare-exchange. Each slot ends claimed by exactly
    // one of them, never the same one twice, and the third is counted as unclaimed.
    model(3, || {
        let k = 2;
        let frags = stack(&[0.5, 0.5, 0.5]);
        let mut dev = Device::new();
        let key = dev.buffer::<u32>("kb-key", k as u64).unwrap();
        let prim = dev.buffer::<u32>("kb-prim", k as u64).unwrap();
        let unclaimed = dev.buffer::<u32>("kb-unclaimed", 1).unwrap();
        dev.memory.fill(key, EMPTY).unwrap();
        dev.memory.fill(prim, EMPTY).unwrap();
        let census = Census {
            count: dev.buffer::<u32>("kb-count", 1).unwrap(),
            negative: dev.buffer::<u32>("kb-negative-depths", 1).unwrap(),
        };
        ordered(&dev, &Depth32 { key, k, census }, &frags, 1);
        assert_eq!(read(&dev, key), vec![key32(0.5); 2]);
        let claim = Claim32 {
            key,
            prim,
            k,
            unclaimed,
        };
        let (dev, _) = on_threads(dev, claim, &frags, 1);
        let p = read(&dev, prim);
        assert!(p.iter().all(|&p| p < 3), "{p:?}");
        assert_ne!(p[0], p[1], "one fragment claimed two slots");
        assert_eq!(read(&dev, unclaimed)[0], 1);
    });
}

#[test]
fn atomic_min_chain_64_keeps_the_k_smallest_keys() {
    model(3, || {
        let k = 2;
        let frags = stack(&[0.5, 0.5, 0.25]);
        let mut dev = Device::new();
        let key = dev.buffer::<u64>("kb-key64", k as u64).unwrap();
        dev.memory.fill(key, u64::MAX).unwrap();
        let census = Census {
            count: dev.buffer::<u32>("kb-count", 1).unwrap(),
            negative: dev.buffer::<u32>("kb-negative-depths", 1).unwrap(),
        };
        let (dev, _) = on_threads(dev, Store64 { key, k, census }, &frags, 1);
        let all = frags
            .iter()
            .map(|f| key64(f.depth, f.primitive_id))
            .collect();
        assert_eq!(read(&dev, key), k_smallest(all, k as usize, u64::MAX));
        assert_eq!(read(&dev, key), vec![key64(0.25, 2), key64(0.5, 0)]);
        assert_eq!(read(&dev, census.count)[0], 3);
    });
}
