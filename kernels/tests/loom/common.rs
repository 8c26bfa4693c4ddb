//! What every model shares: fragments, the loom model with its bounds, running a kernel on
//! loom threads or on the ordered executor, reading buffers back.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use fragrace_emu::exec::{run_on_threads, ThreadOutcome};
use fragrace_emu::kernel::FragInput;
use fragrace_emu::sync::Arc;
use fragrace_emu::{Buf, Device, ExecConfig, Fragment, FragmentKernel};

/// Watchdog of the invocations (steps): far above what any of these kernels needs.
pub const MAX_STEPS: u64 = 10_000;

pub fn frag(x: u32, depth: f32, prim: u32, ticket: u32) -> FragInput {
    FragInput {
        seq: prim as u64,
        x,
        y: 0,
        tri: u32::MAX,
        primitive_id: prim,
        coverage: 1,
        front_facing: true,
        depth,
        ticket,
        ..Default::default()
    }
}

/// `depths` as fragments of pixel 0, primitive = position, tickets in API order.
pub fn stack(depths: &[f32]) -> Vec<FragInput> {
    depths
        .iter()
        .enumerate()
        .map(|(i, &d)| frag(0, d, i as u32, i as u32))
        .collect()
}

/// Explores `f` with the preemption bound pinned (the environment's LOOM_MAX_PREEMPTIONS is
/// overridden: each model states the bound its claim is made under), and prints how many
/// executions loom explored and how long it took.
pub fn model(preemption_bound: usize, f: impl Fn() + Sync + Send + 'static) {
    let mut b = loom::model::Builder::new();
    b.preemption_bound = Some(preemption_bound);
    b.max_branches = 1_000_000;
    let executions = std::sync::Arc::new(AtomicU64::new(0));
    let counter = executions.clone();
    let start = Instant::now();
    b.check(move || {
        counter.fetch_add(1, Relaxed);
        f()
    });
    println!(
        "{}: {} executions, preemption bound {preemption_bound}, {:.2} s",
        std::thread::current().name().unwrap_or("model"),
        executions.load(Relaxed),
        start.elapsed().as_secs_f64()
    );
}

/// Runs one pass of `kernel` with a loom thread per fragment on `dev`'s memory (pixels
/// `width x 1`) and gives the device back.
pub fn on_threads<K: FragmentKernel + Send + 'static>(
    dev: Device,
    kernel: K,
    frags: &[FragInput],
    width: u32,
) -> (Device, Vec<ThreadOutcome>) {
    let memory = Arc::new(dev.memory);
    let out = run_on_threads(
        Arc::new(kernel),
        memory.clone(),
        frags.to_vec(),
        width,
        1,
        MAX_STEPS,
    );
    let memory = Arc::try_unwrap(memory)
        .ok()
        .expect("every invocation thread has been joined");
    assert!(out.iter().all(|o| o.fault.is_none()), "{out:?}");
    (Device { memory }, out)
}

/// Runs one pass on the `ordered` executor (a pass this model does not explore).
pub fn ordered<K: FragmentKernel>(dev: &Device, kernel: &K, frags: &[FragInput], width: u32) {
    let r = dev.invocations(width, 1, frags, kernel, &ExecConfig::ordered());
    assert_eq!(r.stats.faulted, 0, "{:?}", r.faults);
}

pub fn read<T: fragrace_emu::Word>(dev: &Device, b: Buf<T>) -> Vec<T> {
    dev.memory.read(b).unwrap()
}

/// Counts the executions of a `loom_finds_*` model and when the bug first showed.
pub struct Hunt {
    name: &'static str,
    start: Instant,
    executions: AtomicU64,
    found: AtomicBool,
    first: Mutex<Option<(u64, Duration)>>,
}

impl Hunt {
    pub fn new(name: &'static str) -> std::sync::Arc<Hunt> {
        std::sync::Arc::new(Hunt {
            name,
            start: Instant::now(),
            executions: AtomicU64::new(0),
            found: AtomicBool::new(false),
            first: Mutex::new(None),
        })
    }
    pub fn execution(&self) {
        self.executions.fetch_add(1, Relaxed);
    }
    pub fn saw(&self, bug: bool) {
        if bug && !self.found.swap(true, Relaxed) {
            *self.first.lock().unwrap() =
                Some((self.executions.load(Relaxed), self.start.elapsed()));
        }
    }
    /// Asserts the bug was found and prints the figures.
    pub fn report(&self) {
        let total = self.executions.load(Relaxed);
        let first = *self.first.lock().unwrap();
        let Some((n, t)) = first else {
            panic!(
                "{}: loom explored {total} executions and never found the bug",
                self.name
            );
        };
        println!(
            "{}: loom found it at execution {n} after {:.3} s ({total} executions explored in {:.3} s)",
            self.name,
            t.as_secs_f64(),
            self.start.elapsed().as_secs_f64()
        );
    }
}

/// The k nearest of `frags` by (depth, primitive), as k-buffer slots.
pub fn nearest(frags: &[FragInput], k: usize) -> Vec<(f32, u32)> {
    let mut v: Vec<(f32, u32)> = frags.iter().map(|f| (f.depth, f.primitive_id)).collect();
    v.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    v.truncate(k);
    v
}
