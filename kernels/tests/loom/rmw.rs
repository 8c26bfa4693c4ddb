//! Read-modify-write k-buffers: racy (`kb-rmw`), under a spinlock, under pixel interlock.

use fragrace_emu::kernel::FragInput;
use fragrace_emu::{Buf, Device, Fragment, FragmentKernel, InterlockMode, KernelInfo};
use fragrace_kernels::protocols::*;

use super::common::*;

// ------------------------------------------------------------------------------------------
// Read-modify-write k-buffers: racy (kb-rmw), under a spinlock, under pixel interlock.
// ------------------------------------------------------------------------------------------

/// The occupied slots (depth, primitive) of pixel 0.
fn slots(dev: &Device, kb: SplitSlots) -> Vec<(f32, u32)> {
    read(dev, kb.depth)
        .into_iter()
        .zip(read(dev, kb.prim))
        .filter(|&(d, _)| d != f32::INFINITY)
        .collect()
}

#[test]
fn loom_finds_the_rmw_k_buffer_losing_a_fragment() {
    // Two fragments of one pixel both load the empty slots, insert themselves, and store all
    // k back: the second store overwrites the first (the read-modify-write hazard).
    let hunt = Hunt::new("kb-rmw lost fragment (2 invocations, bound 2)");
    let h = hunt.clone();
    model(3, move || {
        h.execution();
        let k = 2;
        let frags = stack(&[0.5, 0.25]);
        let mut dev = Device::new();
        let kb = SplitSlots::new(&mut dev, 1, k).unwrap();
        let (dev, _) = on_threads(dev, RmwStore { kb, k }, &frags, 1);
        let s = slots(&dev, kb);
        // Whatever survives is one of the fragments, in order.
        assert!(!s.is_empty() && s.len() <= 2);
        h.saw(s != nearest(&frags, 2));
    });
    hunt.report();
}

struct Spin {
    kb: SplitSlots,
    lock: Buf<u32>,
    gave_up: Buf<u32>,
    entries: Buf<u32>,
}

fn spin_setup(k: u32) -> (Device, Spin) {
    let mut dev = Device::new();
    let kb = SplitSlots::new(&mut dev, 1, k).unwrap();
    let lock = dev.buffer::<u32>("kb-lock", 1).unwrap();
    let gave_up = dev.buffer::<u32>("kb-gave-up", 1).unwrap();
    let entries = dev.buffer::<u32>("kb-entries", 1).unwrap();
    (
        dev,
        Spin {
            kb,
            lock,
            gave_up,
            entries,
        },
    )
}

/// `kb-spinlock`'s capture on loom with spin cap `cap`; returns (slots, entries, give-ups).
fn spinlock(frags: &[FragInput], cap: u32) -> (Vec<(f32, u32)>, u32, u32) {
    let k = frags.len() as u32; // room for all: nothing is evicted
    let (dev, s) = spin_setup(k);
    let kernel = SpinStore {
        kb: s.kb,
        k,
        lock: s.lock,
        cap,
        gave_up: s.gave_up,
        entries: s.entries,
    };
    let (dev, _) = on_threads(dev, kernel, frags, 1);
    assert_eq!(read(&dev, s.lock)[0], 0, "the lock was left held");
    (
        slots(&dev, s.kb),
        read(&dev, s.entries)[0],
        read(&dev, s.gave_up)[0],
    )
}

#[test]
fn spinlock_excludes_and_loses_nothing_silently() {
    // Mutual exclusion: the plain read-modify-write of `entries` inside the lock never loses
    // an increment, and the slots (room for every fragment) hold exactly the fragments that
    // got the lock; every other fragment is counted as a give-up. (That no fragment gives up
    // cannot be claimed for any cap: loom's scheduler is not fair, and a lock holder that is
    // preempted lets the spinner burn its whole cap, which the next test shows.)
    model(3, || {
        let frags = stack(&[0.5, 0.25, 0.75]);
        let (s, entries, gave_up) = spinlock(&frags, 3);
        assert_eq!(entries + gave_up, 3);
        assert_eq!(s.len() as u32, entries, "{s:?}");
        let mut kept = s.clone();
        kept.sort_by(|a, b| a.0.total_cmp(&b.0));
        assert_eq!(kept, s, "slots out of order");
        for x in &s {
            assert!(nearest(&frags, 3).contains(x));
        }
    });
}

#[test]
fn loom_finds_a_spinlock_dropping_a_fragment_at_its_cap() {
    let hunt = Hunt::new("kb-spinlock drop at cap 1 (2 invocations, bound 2)");
    let h = hunt.clone();
    model(3, move || {
        h.execution();
        let frags = stack(&[0.5, 0.25]);
        let (s, entries, gave_up) = spinlock(&frags, 1);
        assert_eq!(entries + gave_up, 2, "a fragment was lost silently");
        assert_eq!(s.len() as u32, entries);
        h.saw(gave_up > 0);
    });
    hunt.report();
}

/// `kb-spinlock`'s protocol with the release written as a plain (relaxed) store instead of
/// a release store: the next holder's compare-exchange reads the 0 but does not
/// synchronise with the previous holder's writes, so its plain loads may see stale values
/// (a known hazard, docs/hazards.md: "release by a plain store with no barrier"). Not one of the algorithms: the
/// bug, written out for loom (the counter inside the lock is `kb-spinlock`'s `entries`).
struct PlainReleaseSpin {
    s: Spin,
    cap: u32,
}

impl FragmentKernel for PlainReleaseSpin {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("spinlock-plain-release")
    }
    async fn shade(&self, f: impl Fragment) {
        let s = &self.s;
        let mut attempts = 0;
        while f.atomic_compare_exchange(s.lock, 0, 0, 1).await.is_err() {
            attempts += 1;
            if attempts >= self.cap {
                f.atomic_add(s.gave_up, 0, 1).await;
                return;
            }
        }
        let e = f.load(s.entries, 0).await;
        f.store(s.entries, 0, e + 1).await;
        f.store(s.lock, 0, 0).await; // the bug: `atomic_store` (release) in kb-spinlock
    }
}

#[test]
fn loom_finds_the_lost_update_of_a_spinlock_released_by_a_plain_store() {
    let hunt = Hunt::new("spinlock with a plain release (2 invocations, bound 2)");
    let h = hunt.clone();
    model(3, move || {
        h.execution();
        let (dev, s) = spin_setup(1);
        let (entries, gave_up) = (s.entries, s.gave_up);
        let kernel = PlainReleaseSpin { s, cap: 3 };
        let (dev, _) = on_threads(dev, kernel, &stack(&[0.5, 0.25]), 1);
        h.saw(read(&dev, entries)[0] + read(&dev, gave_up)[0] != 2);
    });
    hunt.report();
}

fn interlock_k_buffer(mode: InterlockMode) {
    model(3, move || {
        let k = 2;
        let frags = stack(&[0.5, 0.25]);
        let mut dev = Device::new();
        let kb = SplitSlots::new(&mut dev, 1, k).unwrap();
        let last = dev.buffer::<u32>("kb-last", 1).unwrap();
        let entries = dev.buffer::<u32>("kb-entries", 1).unwrap();
        let out_of_order = dev.buffer::<u32>("kb-out-of-order", 1).unwrap();
        let kernel = InterlockStore {
            kb,
            k,
            mode,
            last,
            entries,
            out_of_order,
        };
        let (dev, _) = on_threads(dev, kernel, &frags, 1);
        assert_eq!(slots(&dev, kb), nearest(&frags, k as usize));
        assert_eq!(read(&dev, entries)[0], 2, "mutual exclusion");
        if mode.ordered {
            assert_eq!(read(&dev, out_of_order)[0], 0, "entered out of API order");
            assert_eq!(
                read(&dev, last)[0],
                2,
                "the last entrant is the last primitive"
            );
        }
    });
}

#[test]
fn ordered_interlock_k_buffer_is_exact_and_in_api_order() {
    interlock_k_buffer(InterlockMode::ORDERED);
}

#[test]
fn unordered_interlock_k_buffer_is_exact() {
    interlock_k_buffer(InterlockMode::UNORDERED);
}
