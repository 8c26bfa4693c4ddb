//! The three executors' shared machinery: invocation slots, polling, harvesting results.

use std::future::Future;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::pin::Pin;
use std::task::{Context, Poll, Waker};

use super::policy::{Candidate, Chooser};
use super::simt::Simt;
use super::{ExecConfig, ExecMode, ScheduleConfig};
use crate::hazard::{Detector, Hazard, HazardCounts, InvocationId};
use crate::invocation::{DirectState, Frag, Invocation, PassEnv, StepKind, OP_KINDS};
use crate::kernel::{FaultKind, FragInput, FragmentKernel};
use crate::stats::Stats;
use crate::sync::pool;

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

fn id_of(i: &FragInput) -> InvocationId {
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
    stats: Stats,
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

/// Shades `inputs` (API order) with `kernel` under `cfg`, writing `outs[i]` and
/// `colors[i * targets .. (i + 1) * targets]`.
pub(crate) fn shade<K: FragmentKernel>(
    kernel: &K,
    env: &PassEnv<'_>,
    cfg: &ExecConfig,
    inputs: &[FragInput],
    outs: &mut [FragOut],
    colors: &mut [[u32; 4]],
    targets: usize,
) -> ShadeOutcome {
    let mut outcome = ShadeOutcome::default();
    match &cfg.mode {
        ExecMode::Ordered => {
            let mut acc = Acc::default();
            run_direct(
                kernel, env, inputs, outs, colors, targets, 1, false, &mut acc,
            );
            acc.finish(&mut outcome);
        }
        ExecMode::Parallel => run_parallel(
            kernel,
            env,
            cfg,
            inputs,
            outs,
            colors,
            targets,
            &mut outcome,
        ),
        ExecMode::Scheduled(sc) => run_scheduled(
            kernel,
            env,
            sc,
            cfg.max_steps,
            inputs,
            outs,
            colors,
            targets,
            &mut outcome,
            cfg.reduce,
            cfg.simt,
        ),
    }
    outcome
}

/// Runs a batch in direct mode: `width` lanes in flight; with `lockstep`, lanes take turns
/// at every suspension point, otherwise each lane is polled until it finishes or waits.
#[allow(clippy::too_many_arguments)] // one call site per executor; a struct would only rename them
fn run_direct<K: FragmentKernel>(
    kernel: &K,
    env: &PassEnv<'_>,
    inputs: &[FragInput],
    outs: &mut [FragOut],
    colors: &mut [[u32; 4]],
    targets: usize,
    width: usize,
    lockstep: bool,
    acc: &mut Acc,
) {
    let width = width.max(1);
    let slots: Vec<Invocation> = (0..width).map(|_| Invocation::new()).collect();
    let mut futs: Vec<Option<_>> = Vec::with_capacity(width);
    futs.resize_with(width, || None);
    let mut deferred = Vec::new();
    let mut cx = Context::from_waker(Waker::noop());
    let mut base = 0;
    while base < inputs.len() {
        let n = width.min(inputs.len() - base);
        for lane in 0..n {
            slots[lane].reset(inputs[base + lane]);
            futs[lane] = Some(invocation(
                kernel,
                Frag {
                    inv: &slots[lane],
                    env,
                },
            ));
        }
        let mut left = n;
        while left > 0 {
            for lane in 0..n {
                if futs[lane].is_none() {
                    continue;
                }
                loop {
                    match poll_slot(&mut futs[lane], &slots[lane], &mut cx) {
                        Polled::Done => {
                            futs[lane] = None;
                            deferred.extend(abandon(&slots[lane], env));
                            let i = base + lane;
                            acc.harvest(
                                &slots[lane],
                                &mut outs[i],
                                &mut colors[i * targets..(i + 1) * targets],
                            );
                            left -= 1;
                            break;
                        }
                        // A lane that waits (interlock) lets the others run; in lockstep
                        // every lane takes one step per turn.
                        Polled::Pending if lockstep || slots[lane].waits.get() > 0 => break,
                        Polled::Pending => {}
                    }
                }
            }
            pass_deferred(&mut deferred, env);
            if left > 0 && n < width {
                // Everyone left is waiting on another worker: don't burn the core.
                std::hint::spin_loop();
            }
        }
        base += n;
    }
    // Abandoned turns wait for their predecessors (earlier batches, always progressing).
    // (Bounded like any wait: a turn that never comes was a deadlock, already reported.)
    let mut waits = 0;
    while !pass_deferred(&mut deferred, env) && waits < env.max_waits {
        waits += 1;
        std::hint::spin_loop();
    }
}

#[allow(clippy::too_many_arguments)] // see run_direct
fn run_parallel<K: FragmentKernel>(
    kernel: &K,
    env: &PassEnv<'_>,
    cfg: &ExecConfig,
    inputs: &[FragInput],
    outs: &mut [FragOut],
    colors: &mut [[u32; 4]],
    targets: usize,
    outcome: &mut ShadeOutcome,
) {
    let batch = cfg.batch.max(1);
    let mut chunks = Vec::with_capacity(inputs.len().div_ceil(batch));
    let mut outs_rest = outs;
    let mut colors_rest = colors;
    for ins in inputs.chunks(batch) {
        let (o, orest) = outs_rest.split_at_mut(ins.len());
        let (c, crest) = colors_rest.split_at_mut(ins.len() * targets);
        outs_rest = orest;
        colors_rest = crest;
        chunks.push((ins, o, c));
    }
    run_chunks(kernel, env, cfg, chunks, targets, outcome);
}

/// One batch of fragments with the slices its results go to.
pub(crate) type Chunk<'s> = (&'s [FragInput], &'s mut [FragOut], &'s mut [[u32; 4]]);

/// Shades pre-cut batches (each at most `cfg.batch` long, in API order) under the ordered
/// or parallel executor.
pub(crate) fn shade_chunks<K: FragmentKernel>(
    kernel: &K,
    env: &PassEnv<'_>,
    cfg: &ExecConfig,
    chunks: Vec<Chunk<'_>>,
    targets: usize,
) -> ShadeOutcome {
    let mut outcome = ShadeOutcome::default();
    match cfg.mode {
        ExecMode::Parallel => run_chunks(kernel, env, cfg, chunks, targets, &mut outcome),
        _ => {
            let mut acc = Acc::default();
            for (ins, o, c) in chunks {
                run_direct(kernel, env, ins, o, c, targets, 1, false, &mut acc);
            }
            acc.finish(&mut outcome);
        }
    }
    outcome
}

fn run_chunks<K: FragmentKernel>(
    kernel: &K,
    env: &PassEnv<'_>,
    cfg: &ExecConfig,
    chunks: Vec<Chunk<'_>>,
    targets: usize,
    outcome: &mut ShadeOutcome,
) {
    let batch = cfg.batch.max(1);
    let threads = cfg.threads.max(1).min(chunks.len()).max(1);
    // Batches are handed out in API order, so the predecessors of any fragment on its pixel
    // are in batches already taken: ordered interlock cannot deadlock.
    let queue = pool::Mutex::new(chunks.into_iter());
    // All threads at once (`broadcast`): with ordered interlock a batch may wait for one
    // another thread holds.
    let accs: Vec<Acc> = pool::broadcast(threads, |_| {
        let mut acc = Acc::default();
        loop {
            let next = queue.lock().unwrap_or_else(|e| e.into_inner()).next();
            let Some((ins, o, c)) = next else { break };
            run_direct(
                kernel,
                env,
                ins,
                o,
                c,
                targets,
                batch,
                cfg.lockstep,
                &mut acc,
            );
        }
        acc
    });
    for acc in accs {
        acc.finish(outcome);
    }
}

/// Reusable state of the scheduled executor (everything but the futures), so that
/// exploring many schedules of one model allocates nothing per execution.
pub(crate) struct SchedScratch {
    pub detector: Detector,
    chooser: Option<Chooser>,
    which: Vec<usize>,
    free: Vec<usize>,
    /// Slots in flight, in admission order.
    inflight: Vec<usize>,
    /// The runnable ones, in the same order (see `schedule_once`).
    cands: Vec<Candidate>,
    pub record: Vec<u8>,
    conflicting: Vec<usize>,
    sub_cands: Vec<Candidate>,
    /// Interleave only conflicting invocations (ExecConfig::reduce).
    pub reduce: bool,
    /// Lockstep forward progress (ExecConfig::simt).
    pub simt: Option<Simt>,
}

impl SchedScratch {
    pub fn new(width: u32, height: u32) -> SchedScratch {
        SchedScratch {
            detector: Detector::new(width, height),
            chooser: None,
            which: Vec::new(),
            free: Vec::new(),
            inflight: Vec::new(),
            cands: Vec::new(),
            record: Vec::new(),
            conflicting: Vec::new(),
            sub_cands: Vec::new(),
            reduce: false,
            simt: None,
        }
    }
}

fn candidate(inv: &Invocation, slot: usize) -> Candidate {
    let i = inv.input.get();
    Candidate {
        seq: i.seq,
        depth: i.depth,
        slot: slot as u32,
    }
}

#[allow(clippy::too_many_arguments)] // see run_direct
fn run_scheduled<K: FragmentKernel>(
    kernel: &K,
    env: &PassEnv<'_>,
    sc: &ScheduleConfig,
    max_steps: u64,
    inputs: &[FragInput],
    outs: &mut [FragOut],
    colors: &mut [[u32; 4]],
    targets: usize,
    outcome: &mut ShadeOutcome,
    reduce: bool,
    simt: u32,
) {
    let width = sc.window.max(1);
    let slots: Vec<Invocation> = (0..width).map(|_| Invocation::new()).collect();
    let mut futs: Vec<Option<_>> = Vec::with_capacity(width);
    futs.resize_with(width, || None);
    let mut scratch = SchedScratch::new(env.width, env.height);
    scratch.reduce = reduce;
    scratch.simt = (simt > 0).then(|| Simt::new(simt));
    let mut acc = Acc::default();
    schedule_once(
        &slots,
        &mut futs,
        |inv| invocation(kernel, Frag { inv, env }),
        env,
        sc,
        max_steps,
        inputs,
        outs,
        colors,
        targets,
        &mut scratch,
        &mut acc,
    );
    acc.finish(outcome);
    let memory = env.memory;
    outcome.hazard_counts = scratch.detector.counts();
    outcome.hazards = scratch
        .detector
        .hazards(|b| memory.buffer_name(b).to_string());
    outcome.scheduled_hotspots = scratch.detector.hotspots(crate::stats::HOTSPOTS);
    outcome.heat = scratch.detector.take_heat();
    outcome.schedule = sc.record.then(|| std::mem::take(&mut scratch.record));
    outcome.bytes_used = scratch.chooser.as_ref().map_or(0, |c| c.bytes_used());
}

/// One scheduled execution of `inputs` on the given slots and future array (reset here).
/// Returns the number of steps.
#[allow(clippy::too_many_arguments)] // the executor's whole state, borrowed apart
pub(crate) fn schedule_once<'a, F: Future<Output = ()>>(
    slots: &'a [Invocation],
    futs: &mut [Option<F>],
    make: impl Fn(&'a Invocation) -> F,
    env: &PassEnv<'_>,
    sc: &ScheduleConfig,
    max_steps: u64,
    inputs: &[FragInput],
    outs: &mut [FragOut],
    colors: &mut [[u32; 4]],
    targets: usize,
    scratch: &mut SchedScratch,
    acc: &mut Acc,
) -> u64 {
    let width = slots.len();
    let reduce = scratch.reduce;
    // Without interlock every in-flight invocation with a pending step is runnable, and
    // stays so until its own next poll: the candidates are kept up to date as invocations
    // are admitted, stepped and retired instead of being rebuilt before every step.
    let simple = env.interlock.is_none() && scratch.simt.is_none();
    let SchedScratch {
        detector,
        chooser,
        which,
        free,
        inflight,
        cands,
        record,
        conflicting,
        sub_cands,
        simt,
        ..
    } = scratch;
    if let Some(m) = simt.as_mut() {
        m.reset(width);
    }
    detector.reset(env.width, env.height);
    if let Some(base) = inputs.iter().map(|f| f.seq).min() {
        detector.set_base(base);
    }
    match chooser {
        Some(c) => c.reset(&sc.policy, sc.seed, inputs.len() as u64 * 4),
        None => *chooser = Some(Chooser::new(&sc.policy, sc.seed, inputs.len() as u64 * 4)),
    }
    let chooser = chooser.as_mut().expect("set above");
    record.clear();
    which.clear();
    which.resize(width, 0);
    free.clear();
    free.extend((0..width).rev());
    inflight.clear();
    cands.clear();
    for f in futs.iter_mut() {
        *f = None;
    }
    let mut deferred: Vec<crate::interlock::Claim> = Vec::new();
    let mut cx = Context::from_waker(Waker::noop());
    let mut next = 0usize;
    let mut step: u64 = 0;

    macro_rules! retire {
        ($slot:expr) => {{
            let s = $slot;
            futs[s] = None;
            deferred.extend(abandon(&slots[s], env));
            let i = which[s];
            let seq = inputs[i].seq;
            acc.harvest(
                &slots[s],
                &mut outs[i],
                &mut colors[i * targets..(i + 1) * targets],
            );
            detector.finish(seq, step);
            if let Some(p) = inflight.iter().position(|&x| x == s) {
                inflight.remove(p);
            }
            if simple {
                if let Some(p) = cands.iter().position(|c| c.slot as usize == s) {
                    cands.remove(p);
                }
            }
            if let Some(m) = simt.as_mut() {
                m.retired();
            }
            free.push(s);
        }};
    }

    loop {
        // Admit in API order while there is room.
        while next < inputs.len() {
            let Some(s) = free.pop() else { break };
            slots[s].reset(inputs[next]);
            which[s] = next;
            futs[s] = Some(make(&slots[s]));
            detector.start(id_of(&inputs[next]), step, s);
            chooser.admit(s as u32);
            if let Some(m) = simt.as_mut() {
                m.admit(s);
            }
            inflight.push(s);
            next += 1;
            // Run up to the first step.
            if let Polled::Done = poll_slot(&mut futs[s], &slots[s], &mut cx) {
                retire!(s);
            } else if simple && slots[s].pending.get().is_some() {
                cands.push(candidate(&slots[s], s));
            }
        }
        if !deferred.is_empty() {
            pass_deferred(&mut deferred, env);
        }
        if inflight.is_empty() {
            break;
        }
        if !simple {
            cands.clear();
            for &s in inflight.iter() {
                let inv = &slots[s];
                let runnable = match inv.pending.get() {
                    Some(StepKind::InterlockBegin) => Frag { inv, env }
                        .claim()
                        .is_none_or(|(l, m, c)| l.can_enter_claim(m, &c)),
                    Some(StepKind::PassTurn) => Frag { inv, env }
                        .claim()
                        .is_none_or(|(l, _, c)| l.is_turn_claim(&c)),
                    Some(_) => true,
                    None => false,
                };
                if runnable {
                    cands.push(candidate(inv, s));
                }
            }
            if let Some(m) = simt.as_mut() {
                m.filter(cands, slots, which);
                if m.deadlocked(cands) {
                    for (s, fault) in m.deadlock_faults(cands, slots, which) {
                        slots[s].replace_fault(fault);
                        retire!(s);
                    }
                    continue;
                }
            }
        }
        if cands.is_empty() {
            // Everyone in flight waits on someone: a deadlock. Report and drop them all.
            while let Some(&s) = inflight.first() {
                let inv = &slots[s];
                let w = inv.waits.get() + 1;
                inv.replace_fault(FaultKind::Deadlock { waits: w });
                retire!(s);
            }
            continue;
        }
        let k = if reduce {
            // Only interleave where it can matter (see ExecConfig::reduce).
            let key = |s: usize| match slots[s].pending.get() {
                Some(StepKind::Mem { addr, .. }) => Some(addr.0),
                _ => None,
            };
            let pixel = |s: usize| {
                let i = slots[s].input.get();
                (i.x, i.y)
            };
            conflicting.clear();
            for (ci, c) in cands.iter().enumerate() {
                let s = c.slot as usize;
                let hot = inflight.iter().any(|&o| {
                    o != s && ((key(s).is_some() && key(o) == key(s)) || pixel(o) == pixel(s))
                });
                if hot {
                    conflicting.push(ci);
                }
            }
            if conflicting.is_empty() {
                0
            } else {
                sub_cands.clear();
                sub_cands.extend(conflicting.iter().map(|&ci| cands[ci]));
                conflicting[chooser.choose(sub_cands, step)]
            }
        } else {
            chooser.choose(cands, step)
        };
        if sc.record {
            record.push(k as u8);
        }
        let s = cands[k].slot as usize;
        let inv = &slots[s];
        if let Some(StepKind::Mem {
            addr,
            op,
            record: rec,
        }) = inv.pending.get()
        {
            let input = inv.input.get();
            let lock = match (env.interlock, env.interlock_mode) {
                (Some(l), Some(mode)) if inv.in_interlock.get() => {
                    // Per-sample sections exclude only fragments sharing a covered sample.
                    let samples = if mode.per_sample {
                        input.coverage
                    } else {
                        0xff
                    };
                    Some(crate::hazard::LockKey::new(
                        l.key(input.x, input.y),
                        samples,
                    ))
                }
                _ => None,
            };
            detector.access(
                s,
                input.seq,
                addr,
                op,
                step,
                lock,
                rec.map(|r| (r.base, r.len, r.word)),
            );
        }
        if let Some(m) = simt.as_mut() {
            m.before_step(k, s, inv, env.memory);
        }
        inv.granted.set(true);
        step += 1;
        let done = matches!(poll_slot(&mut futs[s], inv, &mut cx), Polled::Done);
        if let Some(m) = simt.as_mut() {
            m.after_step(env.memory);
        }
        if !done && inv.steps.get() > max_steps {
            inv.replace_fault(FaultKind::Watchdog {
                steps: inv.steps.get(),
            });
            retire!(s);
        } else if done {
            retire!(s);
        } else if simple && inv.pending.get().is_none() {
            // Suspended on something other than a step: it will never be granted one.
            cands.remove(k);
        }
    }
    step
}

/// One execution of an exploration, as shown to its callback.
pub struct Execution<'r> {
    /// Position in the exploration (0, 1, ...).
    pub index: u64,
    pub seed: u64,
    pub steps: u64,
    pub hazards: HazardCounts,
    pub faults: u64,
    /// The schedule (one byte per step), when recording.
    pub schedule: &'r [u8],
}

/// Runs `inputs` once per seed under the scheduled executor, reusing every allocation
/// across executions; `each` sees every execution and the memory after it (and must reset
/// the memory for the next one); it returns false to stop. Returns the executions run.
#[allow(clippy::too_many_arguments)] // mirrors Device::explore
pub(crate) fn explore<K: FragmentKernel>(
    kernel: &K,
    env: &PassEnv<'_>,
    sc: &ScheduleConfig,
    max_steps: u64,
    inputs: &[FragInput],
    seeds: std::ops::Range<u64>,
    mut each: impl FnMut(&Execution<'_>, &crate::memory::Memory) -> bool,
) -> u64 {
    let width = sc.window.max(1);
    let slots: Vec<Invocation> = (0..width).map(|_| Invocation::new()).collect();
    let mut futs: Vec<Option<_>> = Vec::with_capacity(width);
    futs.resize_with(width, || None);
    let mut scratch = SchedScratch::new(env.width, env.height);
    let mut outs = vec![FragOut::default(); inputs.len()];
    let mut colors = vec![[0u32; 4]; inputs.len() * 8];
    let mut sc = sc.clone();
    let mut n = 0;
    for seed in seeds {
        sc.seed = seed;
        if let Some(l) = env.interlock {
            l.reset();
        }
        let mut acc = Acc::default();
        let steps = schedule_once(
            &slots,
            &mut futs,
            |inv| invocation(kernel, Frag { inv, env }),
            env,
            &sc,
            max_steps,
            inputs,
            &mut outs,
            &mut colors,
            8,
            &mut scratch,
            &mut acc,
        );
        let e = Execution {
            index: n,
            seed,
            steps,
            hazards: scratch.detector.counts(),
            faults: acc.stats.faulted,
            schedule: &scratch.record,
        };
        n += 1;
        if !each(&e, env.memory) {
            break;
        }
    }
    n
}
