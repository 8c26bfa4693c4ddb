//! The `scheduled` executor: one thread, a window of in-flight invocations, a seeded policy
//! choosing who steps next, and the hazard detector watching every step.

use std::cell::RefCell;
use std::future::Future;
use std::task::{Context, Waker};

use super::policy::{Candidate, Chooser};
use super::simt::Simt;

use super::slots::{
    abandon, id_of, invocation, pass_deferred, poll_slot, Acc, FragOut, Polled, ShadeOutcome,
};
use super::{ExecConfig, ScheduleConfig};
use crate::hazard::{Detector, HazardCounts};
use crate::interlock::Claim;
use crate::invocation::{Frag, Invocation, PassEnv, StepKind};
use crate::kernel::{FaultKind, FragInput, FragmentKernel};
use crate::memory::OpKind;

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
    /// Per slot, the interlock words its invocation claims (with interlock only): a claim
    /// is a function of the fragment, computed at admission rather than at every step for
    /// every invocation waiting to enter (a fifth of a fuzz campaign's time on
    /// `kb-interlock`, docs/performance.md).
    claims: Vec<Option<Claim>>,
    pub record: Vec<u8>,
    conflicting: Vec<usize>,
    sub_cands: Vec<Candidate>,
    /// Interleave only conflicting invocations (ScheduleConfig::reduce).
    pub reduce: bool,
    /// Lockstep forward progress (ScheduleConfig::simt).
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
            claims: Vec::new(),
            record: Vec::new(),
            conflicting: Vec::new(),
            sub_cands: Vec::new(),
            reduce: false,
            simt: None,
        }
    }
}

/// Most invocations or addresses a kept [`SchedScratch`] may have grown to: a scratch that
/// watched a larger pass is dropped rather than kept (its reset walks what it holds).
const KEEP_SCRATCH_MAX: usize = 1 << 16;

thread_local! {
    /// The last scheduled pass's scratch on this thread, for the next one: a fuzz campaign
    /// runs thousands of small passes (several waves each), and a fresh detector grew its
    /// address table and per-address states again in every one (allocation and page
    /// faults: a sixth of a `kb-interlock` campaign's time, docs/performance.md). Every
    /// pass starts from [`schedule_once`]'s reset, as each execution of an exploration does,
    /// so what a pass reports does not depend on the scratch it got.
    static SCRATCH: RefCell<Option<SchedScratch>> = const { RefCell::new(None) };
}

/// Whether an in-flight invocation can be granted its pending step: any step but entering
/// the interlock or passing its turn, and those when the lock allows (`claim`: the words
/// it claims; `None` without interlock).
#[inline]
fn runnable(inv: &Invocation, claim: Option<&Claim>, env: &PassEnv<'_>) -> bool {
    let claim = match (claim, env.interlock, env.interlock_mode) {
        (Some(c), Some(l), Some(m)) => Some((l, m, c)),
        _ => None,
    };
    match inv.pending.get() {
        Some(StepKind::InterlockBegin) => claim.is_none_or(|(l, m, c)| l.can_enter_claim(m, c)),
        Some(StepKind::PassTurn) => claim.is_none_or(|(l, _, c)| l.is_turn_claim(c)),
        Some(_) => true,
        None => false,
    }
}

/// The candidate of the invocation in `slot`, input `i` of the pass.
#[inline]
fn candidate(inputs: &[FragInput], chooser: &Chooser, i: usize, slot: usize) -> Candidate {
    Candidate {
        seq: inputs[i].seq,
        rank: chooser.rank(i),
        slot: slot as u32,
    }
}

/// `v.remove(i)` for the executor's short lists (at most a window of slots), keeping the
/// order: the elements after `i` move down one by one, where `Vec::remove` called
/// `memmove` for a few words (two calls per retired invocation, 2 % of the explore bench's
/// time under `perf`).
#[inline(always)]
fn remove_at<T>(v: &mut Vec<T>, i: usize) {
    // (Swaps, not copies: a loop of copies would be turned back into the call.)
    for j in i + 1..v.len() {
        v.swap(j - 1, j);
    }
    v.pop();
}

#[allow(clippy::too_many_arguments)] // see run_direct
pub(super) fn run_scheduled<K: FragmentKernel>(
    kernel: &K,
    env: &PassEnv<'_>,
    sc: &ScheduleConfig,
    max_steps: u64,
    inputs: &[FragInput],
    outs: &mut [FragOut],
    colors: &mut [[u32; 4]],
    targets: usize,
    outcome: &mut ShadeOutcome,
) {
    let width = sc.window.max(1);
    let slots: Vec<Invocation> = (0..width).map(|_| Invocation::new()).collect();
    let mut futs: Vec<Option<_>> = Vec::with_capacity(width);
    futs.resize_with(width, || None);
    let mut scratch = SCRATCH
        .with(|s| s.borrow_mut().take())
        .unwrap_or_else(|| SchedScratch::new(env.width, env.height));
    scratch.reduce = sc.reduce;
    scratch.simt = (sc.simt > 0).then(|| Simt::new(sc.simt));
    let mut acc = Acc::default();
    schedule_once(
        &slots,
        &mut futs,
        |inv| invocation(kernel, Frag { inv, env }),
        env,
        sc,
        max_steps,
        inputs,
        Harvest::Full {
            outs,
            colors,
            targets,
        },
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
    if scratch.detector.retained() <= KEEP_SCRATCH_MAX {
        SCRATCH.with(|s| *s.borrow_mut() = Some(scratch));
    }
}

/// What an execution keeps of its invocations as they finish.
pub(crate) enum Harvest<'o> {
    /// Everything, for a pass: `outs[i]` and `colors[i * targets .. (i + 1) * targets]` of
    /// input `i`, and the statistics and faults in the accumulator.
    Full {
        outs: &'o mut [FragOut],
        colors: &'o mut [[u32; 4]],
        targets: usize,
    },
    /// Only the count of faults, in the accumulator's statistics (an exploration).
    Faults,
}

/// One scheduled execution of `inputs` on the given slots and future array (reset here).
/// Returns the number of steps.
///
/// Always inlined into its two callers: each passes a constant [`Harvest`], and an
/// exploration's loop keeps its state in registers across executions. Left to the
/// compiler, small changes anywhere in it decided between inlining it and one shared
/// copy, which ran the explore bench 6 % slower.
#[allow(clippy::too_many_arguments)] // the executor's whole state, borrowed apart
#[inline(always)]
pub(crate) fn schedule_once<'a, F: Future<Output = ()>>(
    slots: &'a [Invocation],
    futs: &mut [Option<F>],
    make: impl Fn(&'a Invocation) -> F,
    env: &PassEnv<'_>,
    sc: &ScheduleConfig,
    max_steps: u64,
    inputs: &[FragInput],
    mut harvest: Harvest<'_>,
    scratch: &mut SchedScratch,
    acc: &mut Acc,
) -> u64 {
    let width = slots.len();
    let reduce = scratch.reduce;
    // Without interlock every in-flight invocation with a pending step is runnable, and
    // stays so until its own next poll: the candidates are kept up to date as invocations
    // are admitted, stepped and retired instead of being rebuilt before every step.
    let simple = env.interlock.is_none() && scratch.simt.is_none();
    // With interlock (and without the SIMT rule, whose filter drops candidates), the
    // candidates are rebuilt only when they may have changed: an invocation is runnable
    // unless it waits for the lock, and the lock changes only in steps that enter or leave
    // it or pass a turn, or when an invocation retires. After any other step only the
    // stepped invocation's own entry can change (it keeps its place, or leaves). Rebuilding
    // them over every invocation in flight at every step was a tenth of a `kb-interlock`
    // campaign (docs/performance.md).
    let mut stale = true;
    // The version of `cands` (see `Chooser::choose`): bumped whenever they change.
    let mut version: u64 = 0;
    let SchedScratch {
        detector,
        chooser,
        which,
        free,
        inflight,
        cands,
        claims,
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
    chooser.rank_inputs(inputs);
    record.clear();
    // (`which` and `claims` are written at admission before they are read, and `claims`
    // is read only with interlock: they need only their length, not a clear, which was a
    // call to `memset` and a loop per execution of an exploration.)
    if which.len() != width {
        which.clear();
        which.resize(width, 0);
    }
    free.clear();
    free.extend((0..width).rev());
    inflight.clear();
    cands.clear();
    if claims.len() != width {
        claims.clear();
        claims.resize(width, None);
    }
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
            // (Only a faulted invocation has anything to abandon.)
            if slots[s].faulted() {
                deferred.extend(abandon(&slots[s], env));
            }
            let i = which[s];
            let seq = inputs[i].seq;
            match &mut harvest {
                Harvest::Full {
                    outs,
                    colors,
                    targets,
                } => {
                    let t = *targets;
                    acc.harvest(&slots[s], &mut outs[i], &mut colors[i * t..(i + 1) * t]);
                }
                Harvest::Faults => acc.count_fault(&slots[s]),
            }
            detector.finish(seq, step);
            stale = true;
            version += 1;
            if let Some(p) = inflight.iter().position(|&x| x == s) {
                remove_at(inflight, p);
            }
            if simple {
                if let Some(p) = cands.iter().position(|c| c.slot as usize == s) {
                    remove_at(cands, p);
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
            if env.interlock.is_some() {
                claims[s] = Frag {
                    inv: &slots[s],
                    env,
                }
                .claim()
                .map(|(_, _, c)| c);
            }
            which[s] = next;
            futs[s] = Some(make(&slots[s]));
            detector.start(id_of(&inputs[next]), step, s);
            chooser.admit(s as u32);
            if let Some(m) = simt.as_mut() {
                m.admit(s, next);
            }
            inflight.push(s);
            stale = true;
            next += 1;
            // Run up to the first step.
            if let Polled::Done = poll_slot(&mut futs[s], &slots[s], &mut cx) {
                retire!(s);
            } else if simple && slots[s].pending.get().is_some() {
                cands.push(candidate(inputs, chooser, which[s], s));
                version += 1;
            }
        }
        if !deferred.is_empty() {
            pass_deferred(&mut deferred, env);
            stale = true;
        }
        if inflight.is_empty() {
            break;
        }
        if !simple && (stale || simt.is_some()) {
            cands.clear();
            for &s in inflight.iter() {
                // (`Frag::claim` is `None` without interlock, and so is the slot's.)
                if runnable(&slots[s], claims[s].as_ref(), env) {
                    cands.push(candidate(inputs, chooser, which[s], s));
                }
            }
            stale = false;
            version += 1;
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
            // Only interleave where it can matter (see ScheduleConfig::reduce).
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
                conflicting[chooser.choose(sub_cands, None, step)]
            }
        } else {
            chooser.choose(cands, Some(version), step)
        };
        if sc.record {
            record.push(k as u8);
        }
        let s = cands[k].slot as usize;
        let inv = &slots[s];
        // The detector sees a memory step after it ran (a compare-exchange's outcome
        // decides whether it wrote), with what held before it.
        let mem_step = if let Some(StepKind::Mem {
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
            inv.cas_failed.set(false);
            Some((input.seq, addr, op, lock, rec))
        } else {
            None
        };
        // Whether the step leaves the lock as it is (see `stale`).
        // (Not read without interlock: the candidates are kept up to date there.)
        let lock_kept = !simple
            && matches!(
                inv.pending.get(),
                Some(StepKind::Mem { .. } | StepKind::Yield)
            );
        if let Some(m) = simt.as_mut() {
            m.before_step(k, s, inv, env.memory);
        }
        inv.granted.set(true);
        step += 1;
        let done = matches!(poll_slot(&mut futs[s], inv, &mut cx), Polled::Done);
        if let Some((seq, addr, op, lock, rec)) = mem_step {
            // What an atomic load or a compare-exchange read (the detector's ABA rule): the
            // word before the step, as the access saw it.
            let read = if matches!(op, OpKind::AtomicLoad | OpKind::CompareExchange) {
                inv.read.get()
            } else {
                0
            };
            // A compare-exchange that failed only read the word: an atomic load.
            let op = if op == OpKind::CompareExchange && inv.cas_failed.get() {
                OpKind::AtomicLoad
            } else {
                op
            };
            detector.access(
                s,
                seq,
                addr,
                op,
                read,
                step - 1,
                lock,
                rec.map(|r| (r.base, r.len, r.word)),
            );
        }
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
            remove_at(cands, k);
            version += 1;
        } else if !simple && !stale {
            if !lock_kept {
                stale = true;
            } else if !runnable(inv, claims[s].as_ref(), env) {
                remove_at(cands, k);
                version += 1;
            }
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
    // (An execution shows its callback no hotspots: the detector need not count them.)
    scratch.detector.keep_hotspots(false);
    let mut sc = sc.clone();
    let mut n = 0;
    // One accumulator for every execution: each counts only its faults (`Harvest::Faults`),
    // from zero.
    let mut acc = Acc::default();
    for seed in seeds {
        sc.seed = seed;
        if let Some(l) = env.interlock {
            l.reset();
        }
        acc.stats.faulted = 0;
        let steps = schedule_once(
            &slots,
            &mut futs,
            |inv| invocation(kernel, Frag { inv, env }),
            env,
            &sc,
            max_steps,
            inputs,
            // An execution shows its callback the memory and its count of faults, never
            // outputs or statistics: harvesting them (eight colour outputs, then the
            // operation counters, of every invocation) was work thrown away.
            Harvest::Faults,
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

/// The scheduled executor across the waves of one rasterized pass: fragments are admitted
/// block by block (`ScheduleConfig::block` pixels a side, API order within a block), as a GPU's
/// fine rasterizer hands out small screen tiles; each wave gets its own seed (the
/// schedule's, advanced by the wave's number); an explicit `bytes:` schedule runs on across
/// waves, each continuing where the previous one stopped reading it.
#[derive(Default)]
pub(crate) struct Waves {
    /// Waves shaded so far.
    index: u64,
    /// Bytes of an explicit schedule read by the earlier waves.
    bytes_used: usize,
}

impl Waves {
    /// Shades one wave's `inputs` (API order) of a pass `width` pixels wide under `sc`,
    /// writing `outs[i]` and `colors[i * targets .. (i + 1) * targets]`.
    #[allow(clippy::too_many_arguments)] // the pieces of one wave, as `shade` takes them
    pub(crate) fn shade<K: FragmentKernel>(
        &mut self,
        kernel: &K,
        env: &PassEnv<'_>,
        exec: &ExecConfig,
        sc: &ScheduleConfig,
        inputs: &[FragInput],
        outs: &mut [FragOut],
        colors: &mut [[u32; 4]],
        targets: usize,
    ) -> ShadeOutcome {
        let mut sc = sc.clone();
        sc.seed = sc
            .seed
            .wrapping_add(self.index.wrapping_mul(0x9E37_79B9_7F4A_7C15));
        if let super::Policy::Bytes(b) = &mut sc.policy {
            b.drain(..self.bytes_used.min(b.len()));
        }
        // Admission order: pixel block by block, API order within a block.
        let block = sc.block.max(1);
        let blocks_per_row = env.width.div_ceil(block) as u64;
        let order = admission_order(inputs, block, blocks_per_row);
        let sched: Vec<FragInput> = order.iter().map(|&i| inputs[i]).collect();
        let mut s_outs = vec![FragOut::default(); sched.len()];
        let mut s_colors = vec![[0u32; 4]; sched.len() * targets];
        let mut outcome = ShadeOutcome::default();
        run_scheduled(
            kernel,
            env,
            &sc,
            exec.max_steps,
            &sched,
            &mut s_outs,
            &mut s_colors,
            targets,
            &mut outcome,
        );
        for (k, &i) in order.iter().enumerate() {
            outs[i] = s_outs[k];
            colors[i * targets..(i + 1) * targets]
                .copy_from_slice(&s_colors[k * targets..(k + 1) * targets]);
        }
        self.bytes_used += outcome.bytes_used;
        self.index += 1;
        outcome
    }
}

/// Buckets beyond the inputs' count that [`admission_order`] may allocate for its counting
/// sort; with more blocks than that (large viewports with few fragments) it sorts.
const COUNTING_SLACK: u64 = 4096;

/// The scheduled executor's admission order of a wave's `inputs` (see [`Waves`]): their
/// indices by pixel block (`block` pixels a side, `blocks_per_row` to a row of blocks,
/// row-major), in API order (index order) within a block. A counting sort by block when
/// the blocks are few for the inputs (a fuzz scene's waves: the comparison sort of every
/// wave was a thirtieth of a `kb-interlock` campaign, docs/performance.md), else a sort by
/// (block, index); both give the one order those distinct keys define.
pub(crate) fn admission_order(inputs: &[FragInput], block: u32, blocks_per_row: u64) -> Vec<usize> {
    let key = |f: &FragInput| (f.y / block) as u64 * blocks_per_row + (f.x / block) as u64;
    let blocks = inputs.iter().map(key).max().map_or(0, |k| k + 1);
    if blocks > inputs.len() as u64 * 4 + COUNTING_SLACK {
        let mut order: Vec<usize> = (0..inputs.len()).collect();
        order.sort_unstable_by_key(|&i| (key(&inputs[i]), i));
        return order;
    }
    // Start of each block's run, then a stable scatter in index order.
    let mut start = vec![0usize; blocks as usize + 1];
    for f in inputs {
        start[key(f) as usize + 1] += 1;
    }
    for b in 1..start.len() {
        start[b] += start[b - 1];
    }
    let mut order = vec![0usize; inputs.len()];
    for (i, f) in inputs.iter().enumerate() {
        let b = key(f) as usize;
        order[start[b]] = i;
        start[b] += 1;
    }
    order
}

#[cfg(test)]
mod admission_tests {
    use super::*;

    /// The order as it was computed before the counting sort: a sort by (block, index).
    fn sorted(inputs: &[FragInput], block: u32, blocks_per_row: u64) -> Vec<usize> {
        let mut order: Vec<usize> = (0..inputs.len()).collect();
        order.sort_by_key(|&i| {
            let f = &inputs[i];
            (
                (f.y / block) as u64 * blocks_per_row + (f.x / block) as u64,
                i,
            )
        });
        order
    }

    #[test]
    fn counting_sort_gives_the_sorted_order() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = |m: u32| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state % u64::from(m)) as u32
        };
        // (width, height, fragments, block): few blocks (counting sort), and a wide
        // viewport with few fragments (the comparison sort's branch).
        for (w, h, n, block) in [
            (64, 48, 3000, 8),
            (37, 91, 500, 4),
            (16, 16, 1, 1),
            (50_000, 50_000, 40, 1),
        ] {
            let inputs: Vec<FragInput> = (0..n)
                .map(|i| FragInput {
                    x: next(w),
                    y: next(h),
                    seq: i as u64,
                    ..FragInput::default()
                })
                .collect();
            let bpr = u64::from(w.div_ceil(block));
            let got = admission_order(&inputs, block, bpr);
            assert_eq!(
                got,
                sorted(&inputs, block, bpr),
                "{w}x{h}, {n} fragments, block {block}"
            );
            let blocks = inputs
                .iter()
                .map(|f| (f.y / block) as u64 * bpr + (f.x / block) as u64)
                .max()
                .unwrap()
                + 1;
            assert_eq!(
                blocks > n as u64 * 4 + COUNTING_SLACK,
                w == 50_000,
                "branch taken"
            );
        }
        assert!(admission_order(&[], 8, 4).is_empty());
    }
}
