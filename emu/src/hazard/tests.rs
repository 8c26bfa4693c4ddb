//! The detector's ordering rules, step by step: a lock built from atomics orders its
//! section, a plain-store release does not, a failed compare-exchange acquires, the clocks
//! follow finish -> start across lanes, and the lost-update rule through atomics.

use super::{Detector, HazardCounts, InvocationId, LockKey, MAX_CLOCK_LANES};
use crate::memory::{Addr, OpKind};

/// The lock (or flag) word and a word of data.
const LOCK: Addr = Addr(0);
const X: Addr = Addr(1 << 32);

/// A detector with invocations `0..n` started in lanes `0..n` at step 0, and a step counter.
struct Run {
    d: Detector,
    step: u64,
}

impl Run {
    fn new(n: u64) -> Run {
        let mut d = Detector::new(4, 4);
        d.set_base(0);
        for i in 0..n {
            d.start(id(i), 0, i as usize);
        }
        Run { d, step: 1 }
    }
    /// Invocation `i` (in lane `i`) makes `op` on `addr`.
    fn op(&mut self, i: u64, op: OpKind, addr: Addr) -> &mut Run {
        self.read(i, op, addr, 0)
    }
    /// The same, reading `value` (an atomic access).
    fn read(&mut self, i: u64, op: OpKind, addr: Addr, value: u64) -> &mut Run {
        self.d
            .access(i as usize, i, addr, op, value, self.step, None, None);
        self.step += 1;
        self
    }
    fn counts(&self) -> HazardCounts {
        self.d.counts()
    }
}

fn id(seq: u64) -> InvocationId {
    InvocationId {
        seq,
        primitive: seq as u32,
        x: 0,
        y: 0,
    }
}

/// A takes the lock, writes X, releases with `release`; B takes the lock and reads X.
fn handoff(release: OpKind) -> HazardCounts {
    let mut r = Run::new(2);
    r.op(0, OpKind::CompareExchange, LOCK)
        .read(1, OpKind::AtomicLoad, LOCK, 1) // B's attempt fails: the lock is held
        .op(0, OpKind::Load, X)
        .op(0, OpKind::Store, X)
        .op(0, release, LOCK)
        .read(1, OpKind::CompareExchange, LOCK, 0)
        .op(1, OpKind::Load, X)
        .op(1, OpKind::Store, X)
        .op(1, OpKind::AtomicStore, LOCK);
    r.counts()
}

#[test]
fn a_lock_built_from_atomics_orders_its_section() {
    assert_eq!(handoff(OpKind::AtomicStore), HazardCounts::default());
}

#[test]
fn a_lock_released_by_a_plain_store_does_not() {
    let c = handoff(OpKind::Store);
    // X twice (B's load and store against A's store), and the lock word (A's plain
    // release against B's failed attempt, then B's compare-exchange against it).
    assert!(c.races >= 2, "{c:?}");
    assert_eq!(c.lost_updates, 0, "{c:?}");
}

#[test]
fn without_the_acquire_the_section_is_not_ordered() {
    // B reads X after A's release without touching the lock.
    let mut r = Run::new(2);
    r.op(0, OpKind::CompareExchange, LOCK)
        .op(0, OpKind::Store, X)
        .op(0, OpKind::AtomicStore, LOCK)
        .op(1, OpKind::Load, X);
    assert_eq!(r.counts().races, 1);
}

#[test]
fn a_failed_compare_exchange_acquires_what_it_read() {
    // A publishes X with a release store of a flag; B's failed compare-exchange reads the
    // flag (it is an atomic load to the detector) and then reads X: ordered.
    let mut r = Run::new(2);
    r.op(0, OpKind::Store, X)
        .op(0, OpKind::AtomicStore, LOCK)
        .op(1, OpKind::AtomicLoad, LOCK)
        .op(1, OpKind::Load, X);
    assert_eq!(r.counts(), HazardCounts::default());
}

#[test]
fn accesses_after_the_release_are_not_published() {
    // A releases, then writes X; B acquires A's release and reads X: a race.
    let mut r = Run::new(2);
    r.op(0, OpKind::AtomicStore, LOCK)
        .op(0, OpKind::Store, X)
        .op(1, OpKind::AtomicLoad, LOCK)
        .op(1, OpKind::Load, X);
    assert_eq!(r.counts().races, 1);
}

#[test]
fn a_plain_store_ends_the_release_sequence() {
    // A releases with an atomic store, C overwrites the word with a plain store, B reads
    // C's value: B did not synchronise with A.
    let mut r = Run::new(3);
    r.op(0, OpKind::Store, X)
        .op(0, OpKind::AtomicStore, LOCK)
        .op(2, OpKind::Store, LOCK)
        .op(1, OpKind::AtomicLoad, LOCK)
        .op(1, OpKind::Load, X);
    assert_eq!(r.counts().races, 1 + 1 + 1, "X, and the lock word twice");
}

#[test]
fn read_modify_writes_carry_the_release_sequence_on() {
    // A releases, C adds to the word (a read-modify-write), B reads C's value: B knows A.
    let mut r = Run::new(3);
    r.op(0, OpKind::Store, X)
        .op(0, OpKind::AtomicStore, LOCK)
        .op(2, OpKind::Add, LOCK)
        .op(1, OpKind::AtomicLoad, LOCK)
        .op(1, OpKind::Load, X);
    assert_eq!(r.counts(), HazardCounts::default());
}

#[test]
fn finish_then_start_is_ordered_through_the_clocks() {
    // A (lane 0) writes X and finishes; D starts in lane 1 after that and releases; B
    // (lane 2, in flight with A) acquires D's release and reads X: A -> D -> B.
    let mut r = Run::new(1);
    r.d.start(id(2), 0, 2);
    r.op(0, OpKind::Store, X);
    r.d.finish(0, r.step);
    r.d.start(id(1), r.step, 1);
    r.op(1, OpKind::AtomicStore, LOCK)
        .op(2, OpKind::AtomicLoad, LOCK)
        .op(2, OpKind::Load, X);
    assert_eq!(r.counts(), HazardCounts::default());
    // Without the acquire, B and A overlapped: a race.
    let mut r = Run::new(1);
    r.d.start(id(2), 0, 2);
    r.op(0, OpKind::Store, X);
    r.d.finish(0, r.step);
    r.op(2, OpKind::Load, X);
    assert_eq!(r.counts().races, 1);
}

#[test]
fn a_reused_lane_starts_past_its_predecessors_epochs() {
    // B acquires what A (lane 0) released, then E, started in lane 0 after A finished,
    // writes X: B's knowledge of lane 0 is A's, not E's.
    let mut r = Run::new(2);
    r.op(0, OpKind::AtomicStore, LOCK)
        .op(1, OpKind::AtomicLoad, LOCK);
    r.d.finish(0, r.step);
    r.d.start(id(2), r.step, 0);
    r.op(2, OpKind::Store, X).op(1, OpKind::Load, X);
    assert_eq!(r.counts().races, 1);
}

#[test]
fn atomic_load_then_store_over_another_write_is_a_lost_update() {
    // Check-then-act with atomics: both load the flag, B sets it, A sets it.
    let mut r = Run::new(2);
    r.op(0, OpKind::AtomicLoad, X)
        .op(1, OpKind::AtomicLoad, X)
        .op(1, OpKind::AtomicStore, X)
        .op(0, OpKind::AtomicStore, X);
    assert_eq!(
        r.counts(),
        HazardCounts {
            lost_updates: 1,
            races: 0,
            torn: 0
        }
    );
}

#[test]
fn a_store_after_taking_the_writers_lock_is_no_lost_update() {
    // A loads X (atomic), then takes the lock B released after writing X: B's write
    // happens before A's store.
    let mut r = Run::new(2);
    r.op(0, OpKind::AtomicLoad, X)
        .op(1, OpKind::CompareExchange, LOCK)
        .op(1, OpKind::AtomicStore, X)
        .op(1, OpKind::AtomicStore, LOCK)
        .op(0, OpKind::CompareExchange, LOCK)
        .op(0, OpKind::AtomicStore, X);
    assert_eq!(r.counts(), HazardCounts::default());
    // The same with an interlock section around both writes (the k+-buffer's bound).
    let mut r = Run::new(2);
    let section = Some(LockKey::new(0, 0xff));
    r.d.access(0, 0, X, OpKind::AtomicLoad, 0, 1, None, None);
    r.d.access(1, 1, X, OpKind::AtomicStore, 0, 2, section, None);
    r.d.access(0, 0, X, OpKind::AtomicStore, 0, 3, section, None);
    assert_eq!(r.counts(), HazardCounts::default());
}

#[test]
fn plain_lost_updates_are_reported_as_before_even_when_ordered() {
    // Plain load, a foreign write published to us by a lock handoff, plain store: the
    // stale value overwrites it (the pattern, whatever the ordering).
    let mut r = Run::new(2);
    r.op(0, OpKind::Load, X)
        .op(1, OpKind::Store, X)
        .op(1, OpKind::AtomicStore, LOCK)
        .op(0, OpKind::AtomicLoad, LOCK)
        .op(0, OpKind::Store, X);
    assert_eq!(r.counts().lost_updates, 1);
    assert_eq!(r.counts().races, 1, "A's load against B's store");
}

#[test]
fn lanes_past_the_clocks_are_ordered_by_lifetimes_only() {
    // Invocations in lanes beyond MAX_CLOCK_LANES get no clock: the lock orders nothing.
    let (a, b) = (MAX_CLOCK_LANES as u64, MAX_CLOCK_LANES as u64 + 1);
    let mut d = Detector::new(4, 4);
    d.set_base(0);
    d.start(id(a), 0, a as usize);
    d.start(id(b), 0, b as usize);
    let mut step = 1;
    let mut op = |i: u64, o: OpKind, addr: Addr| {
        d.access(i as usize, i, addr, o, 0, step, None, None);
        step += 1;
    };
    op(a, OpKind::CompareExchange, LOCK);
    op(a, OpKind::Store, X);
    op(a, OpKind::AtomicStore, LOCK);
    op(b, OpKind::CompareExchange, LOCK);
    op(b, OpKind::Load, X);
    assert_eq!(d.counts().races, 1);
}

#[test]
fn a_compare_exchange_that_validates_a_value_that_came_back_is_aba() {
    // A loads the head (node 1); B swings it to 2 and back to 1; A's compare-exchange
    // expecting 1 succeeds: a lost update of B's changes.
    const HEAD: Addr = LOCK;
    let mut r = Run::new(2);
    r.read(0, OpKind::AtomicLoad, HEAD, 1)
        .read(1, OpKind::AtomicLoad, HEAD, 1)
        .read(1, OpKind::CompareExchange, HEAD, 1)
        .read(1, OpKind::CompareExchange, HEAD, 2)
        .read(0, OpKind::CompareExchange, HEAD, 1);
    assert_eq!(r.counts().lost_updates, 1);
    // A retry loop: A's first exchange fails (it reads 2, an atomic load), the retry
    // succeeds on what it read: no report.
    let mut r = Run::new(2);
    r.read(0, OpKind::AtomicLoad, HEAD, 1)
        .read(1, OpKind::CompareExchange, HEAD, 1)
        .read(0, OpKind::AtomicLoad, HEAD, 2)
        .read(0, OpKind::CompareExchange, HEAD, 2);
    assert_eq!(r.counts(), HazardCounts::default());
    // A spinlock: A's attempt fails reading 1 (held), B releases, A's next attempt
    // succeeds on 0, which is not what A read: no report.
    let mut r = Run::new(2);
    r.read(1, OpKind::CompareExchange, LOCK, 0)
        .read(0, OpKind::AtomicLoad, LOCK, 1)
        .read(1, OpKind::AtomicStore, LOCK, 1)
        .read(0, OpKind::CompareExchange, LOCK, 0);
    assert_eq!(r.counts(), HazardCounts::default());
}

#[test]
fn lost_updates_are_found_among_many_loads_of_an_invocation() {
    // A loads 40 words (past the short list an invocation's loads start in), B writes
    // some of them, then A stores to each: a lost update exactly where B wrote between.
    let word = |i: u32| Addr::new(2, i * 7);
    let written = [3u32, 8, 9, 31, 39];
    let mut r = Run::new(2);
    for i in 0..40 {
        r.op(0, OpKind::Load, word(i));
    }
    for &i in &written {
        r.op(1, OpKind::AtomicStore, word(i));
    }
    // (A load again after B's write: the latest load is the one that counts.)
    r.op(0, OpKind::Load, word(9));
    for i in 0..40 {
        r.op(0, OpKind::Store, word(i));
    }
    let c = r.counts();
    assert_eq!(c.lost_updates, written.len() as u64 - 1, "{c:?}");
}

#[test]
fn hotspots_off_change_no_hazard_and_report_no_hotspot() {
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};
    // Random passes (invocations started and finished in 3 lanes, every kind of access on
    // 4 words, some in a critical section) through two detectors, hotspots kept and not:
    // the same hazards, in the same order; only the first reports hotspots.
    let ops = [
        OpKind::Load,
        OpKind::Store,
        OpKind::AtomicLoad,
        OpKind::AtomicStore,
        OpKind::Add,
        OpKind::Exchange,
        OpKind::CompareExchange,
    ];
    let mut found = 0;
    for seed in 0..40 {
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut kept = Detector::new(4, 4);
        let mut off = Detector::new(4, 4);
        off.keep_hotspots(false);
        for d in [&mut kept, &mut off] {
            d.set_base(0);
        }
        let (mut lanes, mut next) = ([None::<u64>; 3], 0u64);
        for step in 0..200 {
            let lane = rng.gen_range(0..3);
            let seq = match lanes[lane] {
                Some(seq) if rng.gen_bool(0.1) => {
                    kept.finish(seq, step);
                    off.finish(seq, step);
                    lanes[lane] = None;
                    continue;
                }
                Some(seq) => seq,
                None => {
                    let seq = next;
                    next += 1;
                    kept.start(id(seq), step, lane);
                    off.start(id(seq), step, lane);
                    lanes[lane] = Some(seq);
                    seq
                }
            };
            let (op, addr) = (
                ops[rng.gen_range(0..ops.len())],
                Addr::new(1, rng.gen_range(0..4)),
            );
            let value = rng.gen_range(0..3);
            let lock = rng.gen_bool(0.3).then(|| LockKey::new(0, 0xff));
            kept.access(lane, seq, addr, op, value, step, lock, None);
            off.access(lane, seq, addr, op, value, step, lock, None);
        }
        assert_eq!(kept.counts(), off.counts(), "seed {seed}");
        let name = |b: u32| b.to_string();
        assert_eq!(kept.hazards(name), off.hazards(name), "seed {seed}");
        assert!(!kept.hotspots(4).is_empty());
        assert!(off.hotspots(4).is_empty());
        found += kept.counts().total();
    }
    assert!(found > 0, "the passes found hazards to compare");
}
