//! The hazard detector of the `scheduled` executor. It sees every step in the order the
//! schedule ran them and reports:
//! - **lost updates**: A plain-loads X, another invocation B writes X, then A plain-stores
//!   X (B's write is overwritten by a value computed from a stale read);
//! - **data races**: conflicting accesses to X (at least one a write, at least one plain)
//!   by two invocations whose lifetimes overlap, not both inside the interlock critical
//!   section of the same pixel (interlock orders them);
//! - **torn records**: another invocation writes a word of a multi-word record while A is
//!   part-way through loading it ([`crate::Frag::load_record`]).
//!
//! Atomic-vs-atomic is never a race here (it is what atomics are for); the lost updates and
//! atomicity violations built from atomics show up in the algorithms' invariant oracles.
//! This module knows nothing of kernels or policies: the executor feeds it steps.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use crate::memory::{Addr, OpKind};

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

/// Fast multiplicative hasher for addresses and sequence numbers (no DoS concern here).
#[derive(Default, Clone, Copy)]
pub(crate) struct AddrHasher(u64);
impl Hasher for AddrHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(5) ^ b as u64).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
        }
    }
    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0 ^ v)
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .rotate_left(29);
    }
    fn write_usize(&mut self, v: usize) {
        self.write_u64(v as u64);
    }
}
pub(crate) type FastMap<K, V> = HashMap<K, V, BuildHasherDefault<AddrHasher>>;

#[derive(Clone, Copy)]
struct Access {
    seq: u64,
    step: u64,
    plain: bool,
    /// The interlock key held at the time, if any.
    lock: Option<usize>,
}

#[derive(Default)]
struct AddrState {
    addr: Addr,
    last_write: Option<Access>,
    /// Reads since the last write (one entry per invocation, latest).
    reads: Vec<Access>,
    /// Invocations in flight that touched it (for peak concurrency).
    touchers: Vec<u64>,
    accesses: u64,
    peak: u32,
}

#[derive(Default)]
struct InvState {
    id: Option<InvocationId>,
    start: u64,
    end: Option<u64>,
    /// Step of this invocation's latest plain load, per address.
    loads: Vec<(Addr, u64)>,
    /// An open record load: (base, len, interrupted by (who, step)).
    record: Option<OpenRecord>,
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

/// Watches the steps of one scheduled pass. Reusable: [`Detector::reset`] keeps every
/// allocation, so exploring many schedules of a small model allocates nothing per run.
pub struct Detector {
    /// Per invocation, indexed by `seq - base_seq`.
    invs: Vec<InvState>,
    base_seq: Option<u64>,
    /// Address -> slot in `slab`; `slab[..slab_len]` are live.
    index: FastMap<Addr, u32>,
    slab: Vec<AddrState>,
    slab_len: usize,
    counts: HazardCounts,
    hazards: Vec<RawHazard>,
    /// Per-pixel hazard counts (row-major).
    pub heat: Vec<u32>,
    width: u32,
    /// How many hazards are kept in detail (all are counted).
    pub keep: usize,
    /// Pairs already reported, so a spin loop is one hazard, not thousands.
    seen: FastMap<(u8, u64, u64, u64), ()>,
    /// Invocations with an open record load (few at a time).
    open_records: Vec<u64>,
}

impl Detector {
    /// A detector for a `width` x `height` pass.
    pub fn new(width: u32, height: u32) -> Detector {
        Detector {
            invs: Vec::new(),
            base_seq: None,
            index: FastMap::default(),
            slab: Vec::new(),
            slab_len: 0,
            counts: HazardCounts::default(),
            hazards: Vec::new(),
            heat: vec![0; width as usize * height as usize],
            width,
            keep: 256,
            seen: FastMap::default(),
            open_records: Vec::new(),
        }
    }

    /// Forgets everything, keeping allocations.
    pub fn reset(&mut self, width: u32, height: u32) {
        for s in &mut self.invs {
            s.id = None;
            s.end = None;
            s.loads.clear();
            s.record = None;
        }
        self.base_seq = None;
        self.index.clear();
        for a in &mut self.slab[..self.slab_len] {
            a.last_write = None;
            a.reads.clear();
            a.touchers.clear();
            a.accesses = 0;
            a.peak = 0;
        }
        self.slab_len = 0;
        self.counts = HazardCounts::default();
        self.hazards.clear();
        let n = width as usize * height as usize;
        if self.heat.len() != n {
            self.heat = vec![0; n];
        } else {
            self.heat.fill(0);
        }
        self.width = width;
        self.seen.clear();
        self.open_records.clear();
    }

    fn inv(&self, seq: u64) -> Option<&InvState> {
        let i = seq.checked_sub(self.base_seq?)? as usize;
        self.invs.get(i).filter(|s| s.id.is_some())
    }

    fn inv_mut(&mut self, seq: u64) -> Option<&mut InvState> {
        let i = seq.checked_sub(self.base_seq?)? as usize;
        self.invs.get_mut(i).filter(|s| s.id.is_some())
    }

    /// Sets the smallest `seq` this run will admit (invocations are indexed from it).
    pub fn set_base(&mut self, base: u64) {
        self.base_seq = Some(base);
    }

    /// An invocation was admitted at `step` (its `seq` at least the base, see
    /// [`Detector::set_base`]; without a base, the first admitted sets it).
    pub fn start(&mut self, id: InvocationId, step: u64) {
        let base = *self.base_seq.get_or_insert(id.seq);
        let Some(i) = id.seq.checked_sub(base).map(|i| i as usize) else {
            return;
        };
        if self.invs.len() <= i {
            self.invs.resize_with(i + 1, InvState::default);
        }
        let s = &mut self.invs[i];
        s.id = Some(id);
        s.start = step;
        s.end = None;
        s.loads.clear();
        s.record = None;
    }

    /// An invocation finished (or was dropped after a fault) at `step`.
    pub fn finish(&mut self, seq: u64, step: u64) {
        if let Some(s) = self.inv_mut(seq) {
            s.end = Some(step);
            s.loads.clear();
            s.record = None;
        }
        self.open_records.retain(|&o| o != seq);
    }

    fn live(&self, seq: u64) -> bool {
        self.inv(seq).is_some_and(|s| s.end.is_none())
    }

    /// Whether invocations `a` and `b` overlapped in time (neither finished before the
    /// other started).
    fn overlapped(&self, a: u64, b: u64) -> bool {
        match (self.inv(a), self.inv(b)) {
            (Some(x), Some(y)) => {
                x.end.is_none_or(|e| e > y.start) && y.end.is_none_or(|e| e > x.start)
            }
            _ => false,
        }
    }

    fn report(&mut self, kind: HazardKind, addr: Addr, victim: u64, other: u64, step: u64) {
        let key = (kind as u8, addr.0, victim.min(other), victim.max(other));
        if self.seen.insert(key, ()).is_some() {
            return;
        }
        self.counts.bump(kind);
        let (Some(v), Some(o)) = (
            self.inv(victim).and_then(|s| s.id),
            self.inv(other).and_then(|s| s.id),
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

    fn slot(&mut self, addr: Addr) -> usize {
        if let Some(&i) = self.index.get(&addr) {
            return i as usize;
        }
        let i = self.slab_len;
        if self.slab.len() <= i {
            self.slab.push(AddrState::default());
        }
        self.slab[i].addr = addr;
        self.slab_len += 1;
        self.index.insert(addr, i as u32);
        i
    }

    /// A memory access by `seq` at `step`; `lock` is the interlock key it holds, if any;
    /// `record` is `(base, len, word)` for record accesses.
    pub fn access(
        &mut self,
        seq: u64,
        addr: Addr,
        op: OpKind,
        step: u64,
        lock: Option<usize>,
        record: Option<(Addr, u32, u32)>,
    ) {
        let plain = op.is_plain();
        let write = op.is_write();
        let me = Access {
            seq,
            step,
            plain,
            lock,
        };
        let slot = self.slot(addr);
        // Conflicts with the last write (and, for a write, with the reads since it).
        let mut conflicts: [Option<Access>; 8] = [None; 8];
        let mut more: Vec<Access> = Vec::new();
        let mut n = 0;
        let prev_write;
        {
            let st = &mut self.slab[slot];
            st.accesses += 1;
            if !st.touchers.contains(&seq) {
                st.touchers.push(seq);
            }
            prev_write = st.last_write;
            let mut push = |a: Access| {
                if n < conflicts.len() {
                    conflicts[n] = Some(a);
                    n += 1;
                } else {
                    more.push(a);
                }
            };
            if let Some(w) = prev_write {
                if w.seq != seq && (plain || w.plain) {
                    push(w);
                }
            }
            if write {
                for r in &st.reads {
                    if r.seq != seq && (plain || r.plain) {
                        push(*r);
                    }
                }
                st.reads.clear();
                st.last_write = Some(me);
            } else {
                st.reads.retain(|r| r.seq != seq);
                st.reads.push(me);
            }
        }
        for c in conflicts.iter().flatten().copied().chain(more) {
            let ordered = matches!((c.lock, lock), (Some(a), Some(b)) if a == b);
            if !ordered && self.overlapped(c.seq, seq) {
                self.report(HazardKind::Race, addr, seq, c.seq, step);
            }
        }
        // Lost update: my plain store after my plain load, with another's write between.
        if op == OpKind::Store {
            let my_load = self
                .inv(seq)
                .and_then(|s| s.loads.iter().rev().find(|l| l.0 == addr).map(|l| l.1));
            if let (Some(load_step), Some(w)) = (my_load, prev_write) {
                if w.seq != seq && w.step > load_step {
                    self.report(HazardKind::LostUpdate, addr, seq, w.seq, step);
                }
            }
        }
        if op == OpKind::Load {
            if let Some(s) = self.inv_mut(seq) {
                match s.loads.iter_mut().find(|l| l.0 == addr) {
                    Some(l) => l.1 = step,
                    None => s.loads.push((addr, step)),
                }
            }
        }
        // Torn records: my record load interrupted by another's write.
        if let Some((base, len, word)) = record {
            if op == OpKind::Load {
                let mut torn_by = None;
                let mut opened = false;
                let mut closed = false;
                if let Some(s) = self.inv_mut(seq) {
                    if word == 0 && len > 1 {
                        s.record = Some((base, len, None));
                        opened = true;
                    } else if let Some((b, _, hit)) = s.record {
                        if b == base && word + 1 == len {
                            torn_by = hit;
                            s.record = None;
                            closed = true;
                        }
                    }
                }
                if opened && !self.open_records.contains(&seq) {
                    self.open_records.push(seq);
                }
                if closed {
                    self.open_records.retain(|&o| o != seq);
                }
                if let Some((other, _)) = torn_by {
                    self.report(HazardKind::Torn, base, seq, other, step);
                }
            }
        }
        if write && !self.open_records.is_empty() {
            let open = std::mem::take(&mut self.open_records);
            for &other in &open {
                if other == seq {
                    continue;
                }
                if let Some(s) = self.inv_mut(other) {
                    if let Some((base, len, hit @ None)) = &mut s.record {
                        if base.buffer() == addr.buffer()
                            && addr.index() >= base.index()
                            && addr.index() < base.index().saturating_add(*len)
                        {
                            *hit = Some((seq, step));
                        }
                    }
                }
            }
            self.open_records = open;
        }
        // Peak concurrency: touchers still in flight.
        let mut live = std::mem::take(&mut self.slab[slot].touchers);
        live.retain(|&t| self.live(t));
        let st = &mut self.slab[slot];
        st.peak = st.peak.max(live.len() as u32);
        st.touchers = live;
    }

    pub fn counts(&self) -> HazardCounts {
        self.counts
    }

    /// The hazards kept in detail, with buffer names from `name`.
    pub fn hazards(&self, name: impl Fn(u32) -> String) -> Vec<Hazard> {
        self.hazards
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

    /// The hottest addresses: (address, accesses, peak concurrent accessors).
    pub fn hotspots(&self, n: usize) -> Vec<(Addr, u64, u32)> {
        let mut v: Vec<(Addr, u64, u32)> = self.slab[..self.slab_len]
            .iter()
            .map(|s| (s.addr, s.accesses, s.peak))
            .collect();
        v.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
        v.truncate(n);
        v
    }
}
