//! loom models of the memory facade and the interlock protocols: the same code the
//! executors run, under every interleaving loom explores.
//!
//! Run with `RUSTFLAGS="--cfg loom" cargo test -p fragrace-emu --release --test loom`.
#![cfg(loom)]

use std::sync::atomic::{AtomicBool, Ordering::Relaxed};

use fragrace_emu::exec::run_on_threads;
use fragrace_emu::kernel::FragInput;
use fragrace_emu::sync::Arc;
use fragrace_emu::{Buf, Fragment, FragmentKernel, InterlockMode, KernelInfo, Memory};

fn frag(seq: u64, x: u32, ticket: u32) -> FragInput {
    FragInput {
        seq,
        x,
        y: 0,
        primitive_id: seq as u32,
        ticket,
        tri: u32::MAX,
        coverage: 1,
        ..Default::default()
    }
}

fn model(f: impl Fn() + Sync + Send + 'static) {
    let mut b = loom::model::Builder::new();
    b.preemption_bound = Some(3);
    b.max_branches = 1_000_000;
    b.check(f);
}

struct Add {
    c: Buf<u32>,
    plain: bool,
}
impl FragmentKernel for Add {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("add")
    }
    async fn shade(&self, f: impl Fragment) {
        if self.plain {
            let v = f.load(self.c, 0).await;
            f.store(self.c, 0, v + 1).await;
        } else {
            f.atomic_add(self.c, 0, 1).await;
        }
    }
}

fn counter(plain: bool, n: u64) -> u32 {
    let mut mem = Memory::new();
    let c = mem.create::<u32>("c", 1).unwrap();
    let mem = Arc::new(mem);
    let frags = (0..n).map(|i| frag(i, i as u32, 0)).collect();
    run_on_threads(Arc::new(Add { c, plain }), mem.clone(), frags, 4, 1, 1000);
    mem.read(c).unwrap()[0]
}

#[test]
fn atomic_add_never_loses_an_update() {
    model(|| assert_eq!(counter(false, 3), 3));
}

static LOST: AtomicBool = AtomicBool::new(false);

#[test]
fn loom_finds_the_lost_update_of_a_plain_read_modify_write() {
    LOST.store(false, Relaxed);
    model(|| {
        if counter(true, 2) == 1 {
            LOST.store(true, Relaxed);
        }
    });
    assert!(
        LOST.load(Relaxed),
        "loom must find the interleaving that loses an update"
    );
}

/// Inside the critical section: a plain read-modify-write of a per-pixel counter plus a
/// log of who entered, in order.
struct Critical {
    count: Buf<u32>,
    log: Buf<u32>,
    mode: InterlockMode,
}
impl FragmentKernel for Critical {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("critical").with_interlock(self.mode)
    }
    async fn shade(&self, f: impl Fragment) {
        f.interlock_begin().await;
        let v = f.load(self.count, 0).await;
        f.store(self.log, v, f.primitive_id()).await;
        f.store(self.count, 0, v + 1).await;
        f.interlock_end().await;
    }
}

fn critical(mode: InterlockMode, n: u32) -> (u32, Vec<u32>) {
    let mut mem = Memory::new();
    let count = mem.create::<u32>("count", 1).unwrap();
    let log = mem.create::<u32>("log", n as u64).unwrap();
    let mem = Arc::new(mem);
    // All on pixel (0, 0), tickets in API order.
    let frags = (0..n).map(|i| frag(i as u64, 0, i)).collect();
    let out = run_on_threads(
        Arc::new(Critical { count, log, mode }),
        mem.clone(),
        frags,
        1,
        1,
        10_000,
    );
    assert!(out.iter().all(|o| o.fault.is_none()), "{out:?}");
    (mem.read(count).unwrap()[0], mem.read(log).unwrap())
}

#[test]
fn unordered_interlock_is_mutually_exclusive() {
    model(|| {
        let (c, mut log) = critical(InterlockMode::UNORDERED, 2);
        assert_eq!(c, 2);
        log.sort();
        assert_eq!(log, vec![0, 1]);
    });
}

#[test]
fn ordered_interlock_enters_in_primitive_order() {
    model(|| {
        let (c, log) = critical(InterlockMode::ORDERED, 2);
        assert_eq!(c, 2);
        assert_eq!(log, vec![0, 1]);
    });
}

static UNORDERED_SEEN: AtomicBool = AtomicBool::new(false);

#[test]
fn unordered_interlock_admits_any_order() {
    UNORDERED_SEEN.store(false, Relaxed);
    model(|| {
        let (_, log) = critical(InterlockMode::UNORDERED, 2);
        if log == vec![1, 0] {
            UNORDERED_SEEN.store(true, Relaxed);
        }
    });
    assert!(UNORDERED_SEEN.load(Relaxed));
}

/// Ordered interlock where the first fragment never enters (it discards early): it must
/// still pass its turn, or the second waits forever.
struct SkipFirst {
    count: Buf<u32>,
}
impl FragmentKernel for SkipFirst {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("skip-first").with_interlock(InterlockMode::ORDERED)
    }
    async fn shade(&self, f: impl Fragment) {
        if f.primitive_id() == 0 {
            f.discard();
            return;
        }
        f.interlock_begin().await;
        let v = f.load(self.count, 0).await;
        f.store(self.count, 0, v + 1).await;
        f.interlock_end().await;
    }
}

#[test]
fn ordered_interlock_passes_the_turn_of_fragments_that_never_enter() {
    model(|| {
        let mut mem = Memory::new();
        let count = mem.create::<u32>("count", 1).unwrap();
        let mem = Arc::new(mem);
        let frags = (0..2).map(|i| frag(i as u64, 0, i)).collect();
        let out = run_on_threads(
            Arc::new(SkipFirst { count }),
            mem.clone(),
            frags,
            1,
            1,
            10_000,
        );
        assert!(out.iter().all(|o| o.fault.is_none()));
        assert_eq!(mem.read(count).unwrap()[0], 1);
    });
}

/// The split work queue of the passes (`sync::split`): an owner taking its part's front
/// and a thief taking its back never both take one index, and none is lost.
#[test]
fn split_range_hands_out_every_index_once() {
    use fragrace_emu::sync::split::SplitRange;
    model(|| {
        let r = Arc::new(SplitRange::new(3, 2));
        let thief = {
            let r = r.clone();
            loom::thread::spawn(move || std::iter::from_fn(|| r.next(1)).collect::<Vec<_>>())
        };
        let mut all: Vec<usize> = std::iter::from_fn(|| r.next(0)).collect();
        all.extend(thief.join().unwrap());
        all.sort_unstable();
        assert_eq!(all, vec![0, 1, 2]);
    });
}
