//! The executors' shared machinery: invocation slots, polling, harvesting results.

use std::future::Future;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::pin::Pin;
use std::task::{Context, Poll};

use crate::hazard::{Hazard, HazardCounts, InvocationId};
use crate::invocation::{DirectState, Frag, Invocation, PassEnv, OP_KINDS};
use crate::kernel::{FaultKind, FragInput, FragmentKernel};
use crate::stats::Stats;

/// What one invocation left for the fixed-function stages.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct FragOut {
    pub discarded: bool,
    pub faulted: bool,
    pub depth: Option<f32>,
}

/// A fault, with the invocation it ended.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Fault {
    pub invocation: InvocationId,
    pub kind: FaultKind,
}

/// What shading a list of fragments produced besides outputs.
#[derive(Default)]
pub(crate) struct ShadeOutcome {
    pub stats: Stats,
    pub faults: Vec<Fault>,
    pub hazard_counts: HazardCounts,
    pub hazards: Vec<Hazard>,
    pub heat: Vec<u32>,
    pub schedule: Option<Vec<u8>>,
    pub scheduled_hotspots: Vec<(crate::memory::Addr, u64, u32)>,
    /// Bytes of a `Policy::Bytes` schedule consumed (the next wave continues after them).
    pub bytes_used: usize,
}

/// Faults kept in detail per pass (all are counted).
const KEEP_FAULTS: usize = 64;

pub(super) fn id_of(i: &FragInput) -> InvocationId {
    InvocationId {
        seq: i.seq,
        primitive: i.primitive_id,
        x: i.x,
        y: i.y,
    }
}

/// One invocation's whole life: the kernel, then the hand-over of an interlock turn.
// A named `impl Future` (not `async fn`) so the future type can live in fixed slot arrays.
#[allow(clippy::manual_async_fn)]
pub(crate) fn invocation<'a, K: FragmentKernel>(
    kernel: &'a K,
    frag: Frag<'a>,
) -> impl Future<Output = ()> + 'a {
    async move {
        kernel.shade(frag).await;
        frag.retire().await;
    }
}

pub(crate) enum Polled {
    Done,
    Pending,
}

/// Polls the future in `slot`, turning a panic into a fault.
pub(crate) fn poll_slot<F: Future<Output = ()>>(
    slot: &mut Option<F>,
    inv: &Invocation,
    cx: &mut Context<'_>,
) -> Polled {
    let Some(fut) = slot.as_mut() else {
        return Polled::Done;
    };
    // SAFETY: the future lives in a slot of a Vec that is never resized or moved while any
    // future is in it (allocated once per worker with its final length), and a future is
    // only ever dropped in place (`*slot = None`), so it is never moved after this pin.
    let pinned = unsafe { Pin::new_unchecked(fut) };
    match catch_unwind(AssertUnwindSafe(|| pinned.poll(cx))) {
        Ok(Poll::Ready(())) => Polled::Done,
        Ok(Poll::Pending) => {
            if inv.faulted() {
                Polled::Done
            } else {
                Polled::Pending
            }
        }
        Err(payload) => {
            record_panic(inv, payload.as_ref());
            Polled::Done
        }
    }
}

/// Turns a kernel's panic into the invocation's fault.
pub(crate) fn record_panic(inv: &Invocation, payload: &(dyn std::any::Any + Send)) {
    let message = payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "panic with a non-string payload".into());
    inv.set_fault(FaultKind::Panic { message });
}

/// A faulted invocation is dropped mid-kernel: release what it held of the interlock, and
/// pass its ordered turn on, or every later fragment of its pixel would wait forever. If its
/// turn has not come yet, the claim is returned: the executor passes it when it comes
/// ([`pass_deferred`]).
pub(crate) fn abandon(inv: &Invocation, env: &PassEnv<'_>) -> Option<crate::interlock::Claim> {
    if !inv.faulted() {
        return None;
    }
    let (lock, mode, claim) = (Frag { inv, env }).claim()?;
    if inv.in_interlock.get() {
        lock.leave_claim(mode, &claim);
        inv.in_interlock.set(false);
        None
    } else if mode.ordered && !inv.entered_interlock.get() {
        if lock.is_turn_claim(&claim) {
            lock.pass_turn_claim(&claim);
            None
        } else {
            Some(claim)
        }
    } else {
        None
    }
}

/// Passes the turns of abandoned invocations whose turn has come; returns true when none
/// is left waiting.
pub(crate) fn pass_deferred(
    deferred: &mut Vec<crate::interlock::Claim>,
    env: &PassEnv<'_>,
) -> bool {
    if let Some(lock) = env.interlock {
        deferred.retain(|c| {
            if lock.is_turn_claim(c) {
                lock.pass_turn_claim(c);
                false
            } else {
                true
            }
        });
    }
    deferred.is_empty()
}

/// Counts of invocations that finished without a fault (see [`Acc::tally_one`]).
#[derive(Clone, Copy, Default)]
pub(crate) struct Tally {
    pub shaded: u64,
    pub discarded: u64,
    pub steps: u64,
    pub max_steps: u64,
    /// Covered samples of those that did not discard.
    pub samples_passed: u64,
}

/// Per-worker accumulation.
#[derive(Default)]
pub(crate) struct Acc {
    pub(super) stats: Stats,
    faults: Vec<Fault>,
    ops: [u32; OP_KINDS],
}

impl Tally {
    /// Counts a fused-path invocation that did not fault, from its [`DirectState`]
    /// (`samples`: its covered samples, which pass unless it discarded). As
    /// [`Acc::tally_one`] does from a slot.
    #[inline(always)]
    pub(crate) fn add_direct(&mut self, state: &DirectState<'_>, samples: u8) {
        self.add(state.discarded.get(), state.steps.get(), samples);
    }

    /// Counts an invocation that did not fault: whether it discarded, its steps, and its
    /// covered samples (which pass unless it discarded).
    #[inline(always)]
    fn add(&mut self, discarded: bool, steps: u64, samples: u8) {
        self.shaded += 1;
        self.discarded += u64::from(discarded);
        self.steps += steps;
        self.max_steps = self.max_steps.max(steps);
        if !discarded {
            self.samples_passed += u64::from(samples);
        }
    }
}

impl Acc {
    /// Copies a finished invocation's results out and counts it.
    pub(crate) fn harvest(&mut self, inv: &Invocation, out: &mut FragOut, colors: &mut [[u32; 4]]) {
        out.discarded = inv.discarded.get();
        out.depth = inv.depth_out.get();
        for (c, o) in colors.iter_mut().zip(&inv.outputs) {
            *c = o.get();
        }
        out.faulted = self.count(inv);
        for (a, o) in self.ops.iter_mut().zip(&inv.ops) {
            *a = a.saturating_add(o.get());
        }
    }

    /// Counts a finished invocation's fault only (and takes it, so the slot can be reused).
    #[inline]
    pub(crate) fn count_fault(&mut self, inv: &Invocation) {
        if inv.take_fault().is_some() {
            self.stats.faulted += 1;
        }
    }

    /// Counts a finished invocation (steps, waits, discard, fault) and takes its
    /// fault; returns whether it faulted. Its outputs stay in the slot.
    pub(crate) fn count(&mut self, inv: &Invocation) -> bool {
        let fault = inv.take_fault();
        let faulted = fault.is_some();
        let s = &mut self.stats;
        s.shaded += 1;
        if inv.discarded.get() {
            s.discarded += 1;
        }
        let steps = inv.steps.get();
        s.steps += steps;
        s.max_steps_per_invocation = s.max_steps_per_invocation.max(steps);
        s.interlock_waits += inv.waits.get();
        if let Some(kind) = fault {
            s.faulted += 1;
            if self.faults.len() < KEEP_FAULTS {
                self.faults.push(Fault {
                    invocation: id_of(&inv.input.get()),
                    kind,
                });
            }
        }
        faulted
    }

    /// Counts a warp of finished invocations that nothing follows but counting (fused passes
    /// with no late tests and no targets): [`Self::count`] for each, in one loop. Returns
    /// the samples that passed (covered samples of the invocations that neither discarded
    /// nor faulted).
    pub(crate) fn count_passing(&mut self, slots: &[Invocation]) -> u64 {
        let mut passed = 0u64;
        // No interlock on the fused path, so no invocation waits (`reset_direct` checks).
        let (mut shaded, mut discarded, mut steps) = (0u64, 0u64, 0u64);
        let mut max_steps = self.stats.max_steps_per_invocation;
        for inv in slots {
            if inv.faulted() {
                self.count(inv);
                continue;
            }
            let d = inv.discarded.get();
            let s = inv.steps.get();
            shaded += 1;
            discarded += u64::from(d);
            steps += s;
            max_steps = max_steps.max(s);
            if !d {
                passed += u64::from(inv.input.get().coverage.count_ones());
            }
        }
        let st = &mut self.stats;
        st.shaded += shaded;
        st.discarded += discarded;
        st.steps += steps;
        st.max_steps_per_invocation = st.max_steps_per_invocation.max(max_steps);
        passed
    }

    /// [`Self::count_passing`] for one invocation (the fused path without lockstep retires
    /// each fragment as soon as it is shaded), into a `tally` kept in registers for a segment
    /// (added by [`Self::add_tally`]). `samples`: its covered samples, which pass unless it
    /// discarded or faulted.
    #[inline(always)]
    pub(crate) fn tally_one(&mut self, tally: &mut Tally, inv: &Invocation, samples: u8) {
        if inv.faulted() {
            self.count(inv);
            return;
        }
        tally.add(inv.discarded.get(), inv.steps.get(), samples);
    }

    /// Adds a tally of invocations that did not fault.
    #[inline]
    pub(crate) fn add_tally(&mut self, t: Tally) {
        let st = &mut self.stats;
        st.shaded += t.shaded;
        st.discarded += t.discarded;
        st.steps += t.steps;
        st.max_steps_per_invocation = st.max_steps_per_invocation.max(t.max_steps);
    }

    /// Adds a slot's operation counters, kept across invocations on the fused path (where
    /// [`DirectState::drain_ops`] adds its own to the slot's), and clears them.
    pub(crate) fn add_ops(&mut self, inv: &Invocation) {
        for (a, o) in self.ops.iter_mut().zip(&inv.ops) {
            *a = a.saturating_add(o.get());
            o.set(0);
        }
    }

    pub(crate) fn finish(mut self, out: &mut ShadeOutcome) {
        self.stats.add_ops(&self.ops);
        out.stats.merge(&self.stats);
        out.faults.extend(self.faults);
        out.faults.truncate(KEEP_FAULTS);
    }
}
