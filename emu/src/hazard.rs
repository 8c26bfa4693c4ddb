//! The hazard detector of the `scheduled` executor. It sees every step in the order the
//! schedule ran them and reports:
//! - **lost updates**: A loads X, another invocation B writes X, then A stores X (B's write
//!   is overwritten by a value computed from a stale read). With a plain load and a plain
//!   store, always; when either is atomic (an atomicity violation: check-then-act written
//!   as an atomic load and an atomic store), only if B's write does not happen before A's
//!   store (see below), so that a store made after taking a lock B released is not one;
//! - **data races**: conflicting accesses to X (at least one a write, at least one plain)
//!   by two invocations, neither happening before the other, and not both inside critical
//!   sections that exclude each other (interlock of the same pixel; per-sample interlock
//!   only when the two share a covered sample: see [`LockKey`]);
//! - **torn records**: another invocation writes a word of a multi-word record while A is
//!   part-way through loading it ([`crate::Frag::load_record`]).
//!
//! Happens-before ([`clock`]): program order, release -> acquire through atomics (as the
//! emulator's acquire-release atomics order them), and finish -> start (an invocation that
//! finished before another started). So a plain section under a lock built from atomics
//! (compare-exchange acquire, atomic-store release) is ordered; one released by a plain
//! store is not. Atomic-vs-atomic is never a race here (it is what atomics are for); the
//! atomicity violations other than the load-then-store above show up in the algorithms'
//! invariant oracles. This module knows nothing of kernels or policies: the executor feeds
//! it steps.

mod clock;
mod loads;
mod reads;
mod table;

use crate::memory::{Addr, OpKind};
pub use clock::MAX_CLOCK_LANES;
use clock::{Clocks, NO_CLOCK, NO_LANE, UNTRACKED};
use loads::Loads;
use reads::Reads;
use table::AddrTable;
use table::FastMap;

/// The kinds of hazard.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
pub enum HazardKind {
    LostUpdate,
    Race,
    Torn,
}

impl HazardKind {
    pub fn name(self) -> &'static str {
        match self {
            HazardKind::LostUpdate => "lost-update",
            HazardKind::Race => "race",
            HazardKind::Torn => "torn",
        }
    }
}

/// One invocation, as named in a report.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct InvocationId {
    /// Position in API order within the pass.
    pub seq: u64,
    pub primitive: u32,
    pub x: u32,
    pub y: u32,
}

/// One hazard found.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Hazard {
    pub kind: HazardKind,
    pub buffer: String,
    pub index: u32,
    /// The invocation whose access completed the hazard (e.g. the stale store).
    pub victim: InvocationId,
    /// The other invocation (e.g. the write that was lost).
    pub other: InvocationId,
    /// Step (position in the schedule) at which it completed.
    pub step: u64,
}

/// Hazard counts of a pass.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct HazardCounts {
    pub lost_updates: u64,
    pub races: u64,
    pub torn: u64,
}

impl HazardCounts {
    pub fn total(&self) -> u64 {
        self.lost_updates + self.races + self.torn
    }
    pub fn add(&mut self, o: &HazardCounts) {
        self.lost_updates += o.lost_updates;
        self.races += o.races;
        self.torn += o.torn;
    }
    fn bump(&mut self, k: HazardKind) {
        match k {
            HazardKind::LostUpdate => self.lost_updates += 1,
            HazardKind::Race => self.races += 1,
            HazardKind::Torn => self.torn += 1,
        }
    }
}

#[derive(Clone, Copy)]
struct Access {
    seq: u64,
    step: u64,
    /// The interlock section held at the time (a [`LockKey`]), [`NO_LOCK`] if none (not an
    /// `Option`: this keeps an access at 32 bytes, and `Option<Access>` too).
    lock: u64,
    /// The invocation's epoch at the access, and its lane ([`clock`]; `UNTRACKED` and
    /// `NO_LANE` outside the clocks).
    epoch: u32,
    lane: u16,
    plain: bool,
}

const NO_LOCK: u64 = u64::MAX;

/// The interlock critical section an access was made in: its pixel and the samples it
/// holds (all eight for per-pixel interlock). Two accesses are ordered by interlock iff
/// both were made inside sections of the same pixel that share a sample: per-sample
/// sections of fragments with disjoint coverage run at the same time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LockKey(u64);

impl LockKey {
    pub fn new(pixel: usize, samples: u8) -> LockKey {
        LockKey((pixel as u64) << 8 | samples as u64)
    }
}

/// Whether two accesses' sections (raw [`LockKey`]s or [`NO_LOCK`]) order them.
#[inline]
fn same_section(a: u64, b: u64) -> bool {
    (a >> 8 == b >> 8) & (a & b & 0xff != 0) & (a != NO_LOCK) & (b != NO_LOCK)
}

#[derive(Default)]
struct AddrState {
    addr: Addr,
    last_write: Option<Access>,
    /// The release clock of the word ([`clock::NO_CLOCK`] until an atomic writes it), and
    /// whether its current value carries it (written by an atomic, not by a plain store).
    clock: u32,
    synced: bool,
    /// Reads since the last write (one entry per invocation, latest).
    reads: Reads,
    /// In-flight invocations that touched it, as a set of detector lanes (see
    /// [`Detector::lanes`]): lanes 0..64 in `touch`, the rest in `touch_hi`.
    touch: u64,
    touch_hi: Vec<u64>,
    /// Members of that set (for peak concurrency).
    live: u32,
    accesses: u64,
    peak: u32,
}

impl AddrState {
    /// The state of a fresh `addr`, keeping the allocations of what it held before.
    #[inline]
    fn renew(&mut self, addr: Addr) {
        self.addr = addr;
        self.last_write = None;
        self.clock = NO_CLOCK;
        self.synced = false;
        self.reads.clear();
        self.touch = 0;
        // (Guarded: even an empty `fill` is a call to memset, which showed in profiles.)
        if !self.touch_hi.is_empty() {
            self.touch_hi.fill(0);
        }
        self.live = 0;
        self.accesses = 0;
        self.peak = 0;
    }

    /// Adds `lane` to the touchers; returns false if it was there.
    #[inline]
    fn touch(&mut self, lane: u32) -> bool {
        if lane >= 64 {
            return self.touch_high(lane);
        }
        let bit = 1u64 << lane;
        if self.touch & bit != 0 {
            return false;
        }
        self.touch |= bit;
        self.live += 1;
        true
    }

    /// [`AddrState::touch`] for lanes past the first 64 (windows over 64).
    #[cold]
    fn touch_high(&mut self, lane: u32) -> bool {
        let (word, bit) = (lane as usize / 64, 1u64 << (lane % 64));
        if self.touch_hi.len() < word {
            self.touch_hi.resize(word, 0);
        }
        let w = &mut self.touch_hi[word - 1];
        if *w & bit != 0 {
            return false;
        }
        *w |= bit;
        self.live += 1;
        true
    }

    fn untouch(&mut self, lane: u32) {
        let (word, bit) = (lane as usize / 64, 1u64 << (lane % 64));
        let w = if word == 0 {
            &mut self.touch
        } else {
            &mut self.touch_hi[word - 1]
        };
        debug_assert!(*w & bit != 0);
        *w &= !bit;
        self.live -= 1;
    }
}

/// What the detector keeps of an invocation for the whole pass (its lifetime decides
/// races with accesses that outlive it).
#[derive(Default, Clone, Copy)]
struct InvState {
    id: Option<InvocationId>,
    start: u64,
    end: Option<u64>,
    /// Its lane while in flight.
    lane: u32,
}

/// What the detector keeps of an invocation only while it is in flight. Lanes are reused
/// (at most the executor's window are live at once), so their vectors are allocated once.
#[derive(Default)]
struct Lane {
    /// This invocation's latest load (plain or atomic, the latter including a failed
    /// compare-exchange) per address.
    loads: Loads,
    /// Slab entries whose toucher set holds this lane (cleared when it finishes).
    touched: Vec<u32>,
    /// An open record load: (base, len, interrupted by (who, step)).
    record: Option<OpenRecord>,
}

/// An invocation's latest load of an address.
#[derive(Clone, Copy)]
struct Load {
    addr: Addr,
    step: u64,
    /// The value it read (atomic loads; 0 for plain ones).
    value: u64,
    plain: bool,
}

/// An open record load: (base, len, interrupted by (who, step)).
type OpenRecord = (Addr, u32, Option<(u64, u64)>);

/// A hazard as recorded (buffer by id; named when read out).
#[derive(Clone, Copy)]
struct RawHazard {
    kind: HazardKind,
    addr: Addr,
    victim: InvocationId,
    other: InvocationId,
    step: u64,
}

/// Counting and keeping hazards (apart from the per-address state, so a report can be
/// made while that state is borrowed).
struct Reports {
    counts: HazardCounts,
    hazards: Vec<RawHazard>,
    /// Per-pixel hazard counts (row-major).
    heat: Vec<u32>,
    width: u32,
    /// How many hazards are kept in detail (all are counted).
    keep: usize,
    /// Pairs already reported, so a spin loop is one hazard, not thousands.
    seen: FastMap<(u8, u64, u64, u64), ()>,
}

/// The invocations of a pass, indexed by `seq - base`.
struct Invs {
    all: Vec<InvState>,
    base: Option<u64>,
}

impl Invs {
    #[inline]
    fn get(&self, seq: u64) -> Option<&InvState> {
        let i = seq.checked_sub(self.base?)? as usize;
        self.all.get(i).filter(|s| s.id.is_some())
    }

    #[inline]
    fn get_mut(&mut self, seq: u64) -> Option<&mut InvState> {
        let i = seq.checked_sub(self.base?)? as usize;
        self.all.get_mut(i).filter(|s| s.id.is_some())
    }

    /// The lane of `seq` if it is in flight.
    #[inline]
    fn lane(&self, seq: u64) -> Option<u32> {
        self.get(seq).filter(|s| s.end.is_none()).map(|s| s.lane)
    }

    /// Whether invocations `a` and `b` overlapped in time (neither finished before the
    /// other started).
    #[inline]
    fn overlapped(&self, a: u64, b: u64) -> bool {
        match (self.get(a), self.get(b)) {
            (Some(x), Some(y)) => {
                x.end.is_none_or(|e| e > y.start) && y.end.is_none_or(|e| e > x.start)
            }
            _ => false,
        }
    }
}

impl Reports {
    fn report(
        &mut self,
        invs: &Invs,
        kind: HazardKind,
        addr: Addr,
        victim: u64,
        other: u64,
        step: u64,
    ) {
        let key = (kind as u8, addr.0, victim.min(other), victim.max(other));
        if self.seen.insert(key, ()).is_some() {
            return;
        }
        self.counts.bump(kind);
        let (Some(v), Some(o)) = (
            invs.get(victim).and_then(|s| s.id),
            invs.get(other).and_then(|s| s.id),
        ) else {
            return;
        };
        if let Some(h) = self.heat.get_mut((v.y * self.width + v.x) as usize) {
            *h += 1;
        }
        if self.hazards.len() < self.keep {
            self.hazards.push(RawHazard {
                kind,
                addr,
                victim: v,
                other: o,
                step,
            });
        }
    }
}

/// Watches the steps of one scheduled pass. Reusable: [`Detector::reset`] keeps every
/// allocation, so exploring many schedules of a small model allocates nothing per run.
///
/// Cost per access is a few loads and compares: the address table is a generation-tagged
/// open-addressing table, the in-flight invocations that touched an address are a bitset
/// over *lanes* (dense ids the detector gives invocations while they are in flight, reused
/// after they finish), and per-invocation scratch lives in those lanes.
pub struct Detector {
    invs: Invs,
    /// Per lane (see above).
    lanes: Vec<Lane>,
    table: AddrTable,
    /// `slab[..slab_len]` are the addresses touched in this pass.
    slab: Vec<AddrState>,
    slab_len: usize,
    rep: Reports,
    /// Invocations with an open record load (few at a time).
    open_records: Vec<u64>,
    /// Happens-before through atomics.
    clocks: Clocks,
    /// Whether to count accesses and peak concurrency per address ([`Detector::hotspots`]).
    hotspots: bool,
}

impl Detector {
    /// A detector for a `width` x `height` pass.
    pub fn new(width: u32, height: u32) -> Detector {
        Detector {
            invs: Invs {
                all: Vec::new(),
                base: None,
            },
            lanes: Vec::new(),
            table: AddrTable::new(),
            slab: Vec::new(),
            slab_len: 0,
            rep: Reports {
                counts: HazardCounts::default(),
                hazards: Vec::new(),
                heat: vec![0; width as usize * height as usize],
                width,
                keep: 256,
                seen: FastMap::default(),
            },
            open_records: Vec::new(),
            clocks: Clocks::new(),
            hotspots: true,
        }
    }

    /// Whether to keep the per-address statistics of [`Detector::hotspots`] (on by default).
    /// Off, an access skips them (the access count, the toucher set, the peak) and so does
    /// an invocation's finish (leaving the toucher sets), and `hotspots` reports nothing:
    /// an exploration shows its executions no hotspots, and they were an eighth of its
    /// detector's instructions. The hazards found are the same either way.
    pub fn keep_hotspots(&mut self, keep: bool) {
        self.hotspots = keep;
    }

    /// Forgets everything, keeping allocations.
    pub fn reset(&mut self, width: u32, height: u32) {
        // Only the invocations of the last run were set (the vector is as long as the
        // longest run; clearing the rest would cost as much again).
        for s in &mut self.invs.all {
            if s.id.is_none() {
                continue;
            }
            *s = InvState::default();
        }
        self.invs.base = None;
        self.table.clear();
        // (The slab's states are reset when they are taken again, in `slot`: walking them
        // all here touched every cache line of the last pass's addresses once more.)
        self.slab_len = 0;
        for l in &mut self.lanes {
            l.loads.clear();
            l.touched.clear();
            l.record = None;
        }
        let n = width as usize * height as usize;
        if self.rep.heat.len() != n {
            self.rep.heat = vec![0; n];
        } else if self.rep.counts.total() > 0 {
            // Heat is only ever bumped with a count: no hazard, nothing to clear.
            self.rep.heat.fill(0);
        }
        self.rep.counts = HazardCounts::default();
        self.rep.hazards.clear();
        self.rep.width = width;
        if !self.rep.seen.is_empty() {
            self.rep.seen.clear();
        }
        self.open_records.clear();
        self.clocks.reset();
    }

    /// How many invocations and addresses its allocations hold (the larger), which
    /// [`Detector::reset`] walks: a kept detector that grew past what its user wants to
    /// walk is better dropped.
    pub fn retained(&self) -> usize {
        // (The address index's entries are 8 bytes, an address's state about 200: the
        // index counts for a sixteenth.)
        self.invs
            .all
            .len()
            .max(self.slab.len())
            .max(self.table.retained() / 16)
    }

    /// Sets the smallest `seq` this run will admit (invocations are indexed from it).
    pub fn set_base(&mut self, base: u64) {
        self.invs.base = Some(base);
    }

    /// An invocation was admitted at `step` (its `seq` at least the base, see
    /// [`Detector::set_base`]; without a base, the first admitted sets it) into `lane`:
    /// the executor's slot, which no other invocation in flight holds.
    #[inline]
    pub fn start(&mut self, id: InvocationId, step: u64, lane: usize) {
        let base = *self.invs.base.get_or_insert(id.seq);
        let Some(i) = id.seq.checked_sub(base).map(|i| i as usize) else {
            return;
        };
        if self.invs.all.len() <= i {
            self.invs.all.resize(i + 1, InvState::default());
        }
        if self.lanes.len() <= lane {
            self.lanes.resize_with(lane + 1, Lane::default);
        }
        // (Normally empty: it was cleared when its last invocation finished.)
        let l = &self.lanes[lane];
        if !l.touched.is_empty() || !l.loads.is_empty() || l.record.is_some() {
            self.clear_lane(lane as u32);
        }
        self.clocks.ensure(lane);
        if self.clocks.tracked(Some(lane as u32)).is_some() {
            self.clocks.start(lane);
        }
        let lane = lane as u32;
        self.invs.all[i] = InvState {
            id: Some(id),
            start: step,
            end: None,
            lane,
        };
    }

    /// Forgets what a lane holds (its loads, open record, and its place in the toucher
    /// sets of the addresses it touched).
    #[inline(always)]
    fn clear_lane(&mut self, lane: u32) {
        let l = &mut self.lanes[lane as usize];
        for &a in &l.touched {
            self.slab[a as usize].untouch(lane);
        }
        l.touched.clear();
        l.loads.clear();
        l.record = None;
    }

    /// An invocation finished (or was dropped after a fault) at `step`.
    #[inline]
    pub fn finish(&mut self, seq: u64, step: u64) {
        // (One lookup: its lane, if it was in flight, and its end.)
        let lane = self.invs.get_mut(seq).and_then(|s| {
            let lane = s.end.is_none().then_some(s.lane);
            s.end = Some(step);
            lane
        });
        if let Some(l) = lane {
            self.clear_lane(l);
        }
        if let Some(l) = self.clocks.tracked(lane) {
            self.clocks.finish(l);
        }
        if !self.open_records.is_empty() {
            self.open_records.retain(|&o| o != seq);
        }
    }

    /// The slab index of `addr`, creating its state on first touch.
    #[inline]
    fn slot(&mut self, addr: Addr) -> usize {
        let (i, fresh) = self.table.get_or_insert(addr.0, self.slab_len as u32);
        if fresh {
            if self.slab.len() <= self.slab_len {
                self.slab.push(AddrState::default());
            }
            self.slab[self.slab_len].renew(addr);
            self.slab_len += 1;
        }
        i as usize
    }

    /// A memory access at `step` by `seq`, started in `lane` (see [`Detector::start`]);
    /// `lock` is the interlock section it holds, if any; `record` is `(base, len, word)` for
    /// record accesses; `read` is the value an atomic load or a compare-exchange read (the
    /// word before it; 0 for other operations). A compare-exchange that did not write (it failed) is an
    /// [`OpKind::AtomicLoad`]: it read the word, and acquires as one.
    #[allow(clippy::too_many_arguments)] // one call site, in the executor's hot loop
    #[inline]
    pub fn access(
        &mut self,
        lane: usize,
        seq: u64,
        addr: Addr,
        op: OpKind,
        read: u64,
        step: u64,
        lock: Option<LockKey>,
        record: Option<(Addr, u32, u32)>,
    ) {
        let plain = op.is_plain();
        let write = op.is_write();
        let lock = lock.map_or(NO_LOCK, |l| l.0);
        let slot = self.slot(addr);
        // The lane only counts if `seq` is the invocation started in it and in flight.
        let lane = (self.invs.lane(seq) == Some(lane as u32)).then_some(lane as u32);
        let Detector {
            invs,
            lanes,
            slab,
            rep,
            clocks,
            ..
        } = self;
        let me_clock = clocks.tracked(lane);
        let st = &mut slab[slot];
        // An atomic read of a released value acquires it (before the access: a
        // read-modify-write's own accesses come after its read). An atomic store reads
        // nothing.
        let atomic_read = !plain & (op != OpKind::AtomicStore);
        if let (true, true, Some(l)) = (atomic_read, st.synced, me_clock) {
            clocks.acquire(l, st.clock);
        }
        let me = Access {
            seq,
            step,
            lock,
            epoch: me_clock.map_or(UNTRACKED, |l| clocks.epoch(l)),
            lane: me_clock.map_or(NO_LANE, |l| l as u16),
            plain,
        };
        if self.hotspots {
            st.accesses += 1;
            // Peak concurrency: in-flight invocations that touched it, this one included.
            if let Some(l) = lane {
                if st.touch(l) {
                    lanes[l as usize].touched.push(slot as u32);
                }
            }
            st.peak = st.peak.max(st.live);
        }
        // Whether access `c` happens before this one or excludes it: same critical section,
        // synchronised through atomics, or made by an invocation whose lifetime did not
        // overlap ours (the clocks know that too, except outside them).
        let ordered = |c: &Access| {
            same_section(c.lock, lock)
                || clocks.knows(me_clock, c.lane, c.epoch)
                || !invs.overlapped(c.seq, seq)
        };
        // Races: conflicts with the last write and, for a write, with the reads since it,
        // in that order (the order hazards are reported in).
        // (Conditions combined with `&` and `|`: one rarely taken branch, where `&&` made
        // several that random schedules mispredict.)
        let prev_write = st.last_write;
        if let Some(w) = &prev_write {
            if (w.seq != seq) & (plain | w.plain) && !ordered(w) {
                rep.report(invs, HazardKind::Race, addr, seq, w.seq, step);
            }
        }
        if write {
            for r in st.reads.first.iter().chain(&st.reads.rest) {
                if (r.seq != seq) & (plain | r.plain) && !ordered(r) {
                    rep.report(invs, HazardKind::Race, addr, seq, r.seq, step);
                }
            }
            st.reads.clear();
            st.last_write = Some(me);
        } else {
            st.reads.replace(me);
        }
        // Lost update: my store after my load, with another's write between (when the load
        // or the store is atomic, a write that does not happen before the store); and ABA:
        // my compare-exchange succeeds on the value I loaded although another invocation
        // wrote the word since (the value went and came back: the exchange validated a
        // stale read).
        if let Some(l) = lane {
            let loads = &mut lanes[l as usize].loads;
            let since_my_load =
                |ld: &Load| prev_write.filter(|w| (w.seq != seq) & (w.step > ld.step));
            match op {
                OpKind::Store | OpKind::AtomicStore => {
                    let my_load = loads.get(addr);
                    if let Some(w) = my_load.and_then(since_my_load) {
                        let both_plain = my_load.is_some_and(|l| l.plain) & plain;
                        if both_plain || !ordered(&w) {
                            rep.report(invs, HazardKind::LostUpdate, addr, seq, w.seq, step);
                        }
                    }
                }
                OpKind::CompareExchange => {
                    let my_load = loads.get(addr).filter(|l| !l.plain);
                    if let Some(w) = my_load.filter(|l| l.value == read).and_then(since_my_load) {
                        rep.report(invs, HazardKind::LostUpdate, addr, seq, w.seq, step);
                    }
                }
                OpKind::Load | OpKind::AtomicLoad => {
                    let now = Load {
                        addr,
                        step,
                        value: read,
                        plain,
                    };
                    loads.set(now);
                }
                _ => {}
            }
        }
        // Atomic writes release (a read-modify-write after acquiring: the release sequence
        // goes on); a plain store ends the word's release sequence.
        if write {
            st.synced = match me_clock {
                Some(l) if !plain => {
                    clocks.release(l, &mut st.clock);
                    true
                }
                _ => false,
            };
        }
        // Torn records: my record load interrupted by another's write.
        if let (Some((base, len, word)), OpKind::Load, Some(l)) = (record, op, lane) {
            let open = &mut lanes[l as usize].record;
            if word == 0 && len > 1 {
                *open = Some((base, len, None));
                if !self.open_records.contains(&seq) {
                    self.open_records.push(seq);
                }
            } else if let Some((b, _, hit)) = *open {
                if b == base && word + 1 == len {
                    *open = None;
                    self.open_records.retain(|&o| o != seq);
                    if let Some((other, _)) = hit {
                        self.rep
                            .report(&self.invs, HazardKind::Torn, base, seq, other, step);
                    }
                }
            }
        }
        if write {
            for &other in &self.open_records {
                if other == seq {
                    continue;
                }
                let Some(l) = self.invs.lane(other) else {
                    continue;
                };
                if let Some((base, len, hit @ None)) = &mut self.lanes[l as usize].record {
                    if base.buffer() == addr.buffer()
                        && addr.index() >= base.index()
                        && addr.index() < base.index().saturating_add(*len)
                    {
                        *hit = Some((seq, step));
                    }
                }
            }
        }
    }

    pub fn counts(&self) -> HazardCounts {
        self.rep.counts
    }

    /// Hazards per pixel (row-major), taken out (the detector then has none until reset).
    pub fn take_heat(&mut self) -> Vec<u32> {
        std::mem::take(&mut self.rep.heat)
    }

    /// The hazards kept in detail, with buffer names from `name`.
    pub fn hazards(&self, name: impl Fn(u32) -> String) -> Vec<Hazard> {
        self.rep
            .hazards
            .iter()
            .map(|h| Hazard {
                kind: h.kind,
                buffer: name(h.addr.buffer()),
                index: h.addr.index(),
                victim: h.victim,
                other: h.other,
                step: h.step,
            })
            .collect()
    }

    /// The hottest addresses: (address, accesses, peak concurrent accessors); none when they
    /// are not kept ([`Detector::keep_hotspots`]).
    pub fn hotspots(&self, n: usize) -> Vec<(Addr, u64, u32)> {
        // Most accesses first, then the lowest address: a total order (addresses are
        // distinct), so keeping the first `n` in one pass gives what sorting every address
        // did (that sort was a twentieth of a fuzz campaign's time; collecting every
        // address to select from them, a twentieth again).
        let before = |a: &(Addr, u64, u32), b: &(Addr, u64, u32)| (b.1, a.0) < (a.1, b.0);
        if n == 0 || !self.hotspots {
            return Vec::new();
        }
        let mut top: Vec<(Addr, u64, u32)> = Vec::with_capacity(n + 1);
        for s in &self.slab[..self.slab_len] {
            let e = (s.addr, s.accesses, s.peak);
            if top.len() == n && !before(&e, &top[n - 1]) {
                continue;
            }
            let at = top.partition_point(|t| before(t, &e));
            top.insert(at, e);
            top.truncate(n);
        }
        top
    }
}

#[cfg(test)]
mod tests;
