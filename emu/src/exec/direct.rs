//! The `ordered` and `parallel` executors on fragment lists (the general path: explicit
//! invocations, interlock, contention counting), and the dispatch of a list of fragments to
//! the configured executor ([`shade`]).

use std::task::{Context, Waker};

use super::scheduled::run_scheduled;

use super::slots::{
    abandon, invocation, pass_deferred, poll_slot, Acc, FragOut, Polled, ShadeOutcome,
};
use super::{ExecConfig, ExecMode};
use crate::invocation::{Frag, Invocation, PassEnv};
use crate::kernel::{FragInput, FragmentKernel};
use crate::sync::pool;

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
        // Rounds in which no lane stepped or finished back off, then yield the core: every
        // lane left waits on another worker (interlock), which on a loaded machine may be
        // descheduled, and spinning the time slice away kept it from running.
        let backoff = crate::sync::Backoff::new();
        let lane_steps =
            |lanes: &[Invocation]| -> u64 { lanes.iter().map(|s| s.steps.get()).sum() };
        while left > 0 {
            let (left_before, steps_before) = (left, lane_steps(&slots[..n]));
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
            if left == left_before && lane_steps(&slots[..n]) == steps_before {
                backoff.snooze();
            } else {
                backoff.reset();
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
fn shade_chunks<K: FragmentKernel>(
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

/// Shades a wave of per-tile fragment lists (each in API order) under the ordered or
/// parallel executor: batches of at most `cfg.batch` straight from each list (no copy),
/// results into `outs_lists` and `colors_lists` (resized to match).
pub(crate) fn shade_lists<K: FragmentKernel>(
    kernel: &K,
    env: &PassEnv<'_>,
    cfg: &ExecConfig,
    lists: &[Vec<FragInput>],
    outs_lists: &mut Vec<Vec<FragOut>>,
    colors_lists: &mut Vec<Vec<[u32; 4]>>,
    targets: usize,
) -> ShadeOutcome {
    outs_lists.resize_with(lists.len(), Vec::new);
    colors_lists.resize_with(lists.len(), Vec::new);
    let batch = cfg.batch.max(1);
    let mut chunks = Vec::new();
    for ((l, o), c) in lists
        .iter()
        .zip(outs_lists.iter_mut())
        .zip(colors_lists.iter_mut())
    {
        o.clear();
        o.resize(l.len(), FragOut::default());
        c.clear();
        c.resize(l.len() * targets, [0; 4]);
        let mut o_rest = &mut o[..];
        let mut c_rest = &mut c[..];
        for ins in l.chunks(batch) {
            let (oo, orest) = o_rest.split_at_mut(ins.len());
            let (cc, crest) = c_rest.split_at_mut(ins.len() * targets);
            o_rest = orest;
            c_rest = crest;
            chunks.push((ins, oo, cc));
        }
    }
    shade_chunks(kernel, env, cfg, chunks, targets)
}
