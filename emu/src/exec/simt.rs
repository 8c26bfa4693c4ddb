//! Lockstep forward progress for the scheduled executor ([`super::ScheduleConfig::simt`]): the
//! lanes of a warp share one program counter, as on GPUs without independent thread
//! scheduling (NVIDIA before Volta, and most others).
//!
//! The executor does not see program counters, only each invocation's next step, so the
//! model works from steps:
//! - **warps**: invocations in admission order, `lanes` at a time (admission index / lanes);
//! - **spinning**: a lane whose next step is a `Yield` (what `yield_now` in a spin loop
//!   announces), or a memory access of the same kind to the same address as one it has
//!   already made (a loop's back edge: a failed compare-exchange retried, a flag re-read);
//! - **the rule**: in a warp where some runnable lane is spinning, only spinning lanes may
//!   run; the others are *held*. This is what the SIMT reconvergence stack does at a loop
//!   that some lanes leave and others do not: the looping lanes run until all of them exit,
//!   the others wait at the loop's exit. A lock holder held that way never releases.
//! - **deadlock**: when lanes are held, every lane allowed to run is spinning, and each has
//!   taken [`SPIN_LIMIT`] spinning steps in a row while no step anywhere changed memory or
//!   interlock and no invocation was admitted or retired, the warps with held lanes are
//!   deadlocked: their spinning lanes end with
//!   [`FaultKind::SimtDeadlock`], which lets the held lanes run (the run goes on and reports,
//!   where the hardware would hang).
//!
//! A spin loop that gives up after fewer than [`SPIN_LIMIT`] attempts is not a deadlock:
//! its lanes leave the loop (dropping their work, as the kernel decides) and the held lanes
//! then run, as they would on the hardware.

use super::policy::Candidate;
use crate::invocation::{Invocation, StepKind};
use crate::kernel::FaultKind;
use crate::memory::{Addr, Memory, OpKind};

/// Spinning steps in a row, with no memory changing anywhere, after which a spinning lane
/// is taken to spin forever. Far above the spin caps kernels use (`kb-spinlock`: 1024
/// attempts by default), so a bounded spin is never reported as a deadlock.
pub(crate) const SPIN_LIMIT: u32 = 4096;

/// The state of the mode during one scheduled run (reusable across runs).
pub(crate) struct Simt {
    lanes: u64,
    /// Per slot: the (address, kind) of every memory step the invocation has made.
    executed: Vec<Vec<(Addr, OpKind)>>,
    /// Per slot: (epoch, spinning steps in a row in that epoch); an epoch ends whenever
    /// memory (or interlock, or the set of invocations) changes.
    futile: Vec<(u64, u32)>,
    epoch: u64,
    /// Per candidate (after [`Simt::filter`]): whether it is spinning.
    spinning: Vec<bool>,
    /// Per slot: whether its invocation is spinning, `None` until computed. A slot's answer
    /// depends on its pending step and the steps it made, which change only when the slot
    /// is polled (at its admission and at its own steps), so it is computed once per step
    /// of the slot rather than for every candidate at every step of the run (the scan over
    /// each candidate's steps was a twelfth of a `kb-interlock` campaign's time).
    spin: Vec<Option<bool>>,
    /// Per slot: its invocation's warp (admission index / lanes, set at admission: a
    /// division per candidate per step otherwise).
    warp_of: Vec<u64>,
    /// Slots held by the rule at the last [`Simt::filter`].
    held: Vec<usize>,
    /// The step being taken.
    taking: Option<Taking>,
}

/// A step between [`Simt::before_step`] and [`Simt::after_step`].
struct Taking {
    slot: usize,
    kind: Option<StepKind>,
    spinning: bool,
    /// The word it touches, with its bits before.
    word: Option<(Addr, u64)>,
}

impl Simt {
    pub fn new(lanes: u32) -> Simt {
        Simt {
            lanes: lanes.max(1) as u64,
            executed: Vec::new(),
            futile: Vec::new(),
            epoch: 0,
            spinning: Vec::new(),
            spin: Vec::new(),
            warp_of: Vec::new(),
            held: Vec::new(),
            taking: None,
        }
    }

    /// Starts a run with `width` slots.
    pub fn reset(&mut self, width: usize) {
        self.executed.resize_with(width, Vec::new);
        for e in &mut self.executed {
            e.clear();
        }
        self.futile.clear();
        self.futile.resize(width, (0, 0));
        self.spin.clear();
        self.spin.resize(width, None);
        self.warp_of.clear();
        self.warp_of.resize(width, 0);
        self.epoch = 0;
        self.spinning.clear();
        self.held.clear();
        self.taking = None;
    }

    fn warp(&self, admission: usize) -> u64 {
        admission as u64 / self.lanes
    }

    /// A new invocation in `slot`, the pass's `admission`-th (from 0).
    pub fn admit(&mut self, slot: usize, admission: usize) {
        self.executed[slot].clear();
        self.spin[slot] = None;
        self.warp_of[slot] = self.warp(admission);
        self.futile[slot] = (self.epoch, 0);
        self.epoch += 1;
    }

    /// An invocation left (it may have released what others wait for).
    pub fn retired(&mut self) {
        self.epoch += 1;
    }

    fn is_spinning(&self, inv: &Invocation, slot: usize) -> bool {
        match inv.pending.get() {
            Some(StepKind::Yield) => true,
            Some(StepKind::Mem { addr, op, .. }) => self.executed[slot].contains(&(addr, op)),
            _ => false,
        }
    }

    fn futile(&self, slot: usize) -> u32 {
        let (epoch, n) = self.futile[slot];
        if epoch == self.epoch {
            n
        } else {
            0
        }
    }

    /// Applies the rule to `cands` (runnable invocations in admission order; `which[slot]`
    /// is a slot's admission index): drops the held ones.
    pub fn filter(&mut self, cands: &mut Vec<Candidate>, slots: &[Invocation], which: &[usize]) {
        self.spinning.clear();
        self.held.clear();
        for c in cands.iter() {
            let s = c.slot as usize;
            let spins = match self.spin[s] {
                Some(spins) => spins,
                None => {
                    let spins = self.is_spinning(&slots[s], s);
                    self.spin[s] = Some(spins);
                    spins
                }
            };
            self.spinning.push(spins);
        }
        debug_assert!(cands
            .iter()
            .all(|c| self.warp_of[c.slot as usize] == self.warp(which[c.slot as usize])));
        let mut keep = 0;
        let mut start = 0;
        while start < cands.len() {
            let warp = self.warp_of[cands[start].slot as usize];
            let mut end = start;
            while end < cands.len() && self.warp_of[cands[end].slot as usize] == warp {
                end += 1;
            }
            let any_spins = self.spinning[start..end].iter().any(|&s| s);
            for i in start..end {
                if any_spins && !self.spinning[i] {
                    self.held.push(cands[i].slot as usize);
                } else {
                    cands[keep] = cands[i];
                    self.spinning[keep] = self.spinning[i];
                    keep += 1;
                }
            }
            start = end;
        }
        cands.truncate(keep);
        self.spinning.truncate(keep);
    }

    /// After [`Simt::filter`]: lanes are held, and everyone allowed to run has been
    /// spinning for [`SPIN_LIMIT`] steps with nothing changing.
    pub fn deadlocked(&self, cands: &[Candidate]) -> bool {
        !self.held.is_empty()
            && cands
                .iter()
                .zip(&self.spinning)
                .all(|(c, &spins)| spins && self.futile(c.slot as usize) >= SPIN_LIMIT)
    }

    /// After [`Simt::deadlocked`]: per warp with held lanes, the faults of its spinning
    /// lanes, as (slot, fault).
    pub fn deadlock_faults(
        &self,
        cands: &[Candidate],
        slots: &[Invocation],
        which: &[usize],
    ) -> Vec<(usize, FaultKind)> {
        let seq = |s: usize| slots[s].input.get().seq;
        let mut warps: Vec<u64> = self.held.iter().map(|&s| self.warp(which[s])).collect();
        warps.dedup();
        let mut out = Vec::new();
        for w in warps {
            let spinners: Vec<usize> = cands
                .iter()
                .map(|c| c.slot as usize)
                .filter(|&s| self.warp(which[s]) == w)
                .collect();
            let mut spinning: Vec<u64> = spinners.iter().map(|&s| seq(s)).collect();
            let mut held: Vec<u64> = self
                .held
                .iter()
                .filter(|&&s| self.warp(which[s]) == w)
                .map(|&s| seq(s))
                .collect();
            spinning.sort_unstable();
            held.sort_unstable();
            for s in spinners {
                out.push((
                    s,
                    FaultKind::SimtDeadlock {
                        warp: w,
                        spinning: spinning.clone(),
                        held: held.clone(),
                    },
                ));
            }
        }
        out
    }

    /// Before candidate `k` (in `slot`) takes its step.
    pub fn before_step(&mut self, k: usize, slot: usize, inv: &Invocation, memory: &Memory) {
        let kind = inv.pending.get();
        let word = match kind {
            Some(StepKind::Mem { addr, .. }) => Some((addr, memory.bits(addr))),
            _ => None,
        };
        self.taking = Some(Taking {
            slot,
            kind,
            spinning: self.spinning[k],
            word,
        });
    }

    /// After the step announced by [`Simt::before_step`].
    pub fn after_step(&mut self, memory: &Memory) {
        let Some(Taking {
            slot,
            kind,
            spinning,
            word,
        }) = self.taking.take()
        else {
            return;
        };
        let changed = match (kind, word) {
            (Some(StepKind::Mem { .. }), Some((addr, old))) => memory.bits(addr) != old,
            (Some(StepKind::Yield), _) => false,
            // Interlock entries and exits change what others may do.
            _ => true,
        };
        // (The slot was polled: its pending step changed, and maybe its steps.)
        self.spin[slot] = None;
        if let Some(StepKind::Mem { addr, op, .. }) = kind {
            let done = &mut self.executed[slot];
            if !done.contains(&(addr, op)) {
                done.push((addr, op));
            }
        }
        if changed {
            self.epoch += 1;
        }
        self.futile[slot] = if spinning && !changed {
            (self.epoch, self.futile(slot) + 1)
        } else {
            (self.epoch, 0)
        };
    }
}
