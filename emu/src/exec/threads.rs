//! One OS thread (or, under `--cfg loom`, one loom thread) per invocation: the executor loom
//! model-checks. The kernel, memory and interlock code are exactly those of the other
//! executors; only the scheduling is loom's, which explores every interleaving of the
//! threads' atomic accesses (up to its bounds).

use std::future::Future;
use std::pin::pin;
use std::task::{Context, Poll, Waker};

use crate::interlock::{Interlock, InterlockMode};
use crate::invocation::{Frag, Invocation, Mode, PassEnv};
use crate::kernel::{FaultKind, FragInput, FragmentKernel};
use crate::memory::Memory;
use crate::sync::{thread, Arc};

/// What one invocation left behind.
#[derive(Clone, Debug, PartialEq)]
pub struct ThreadOutcome {
    pub input: FragInput,
    pub outputs: [[u32; 4]; 8],
    pub discarded: bool,
    pub fault: Option<FaultKind>,
}

/// Runs each fragment's invocation of `kernel` on its own thread and waits for all.
/// Fragments of one pixel must carry their ordered-interlock tickets (0, 1, ... in API
/// order) if the kernel uses ordered interlock.
pub fn run_on_threads<K: FragmentKernel + Send + 'static>(
    kernel: Arc<K>,
    memory: Arc<Memory>,
    frags: Vec<FragInput>,
    width: u32,
    height: u32,
    max_steps: u64,
) -> Vec<ThreadOutcome> {
    let mode: Option<InterlockMode> = kernel.info().interlock;
    let interlock = Arc::new(Interlock::new(width, height));
    let handles: Vec<_> = frags
        .into_iter()
        .map(|input| {
            let kernel = kernel.clone();
            let memory = memory.clone();
            let interlock = interlock.clone();
            thread::spawn(move || {
                let env = PassEnv {
                    memory: &memory,
                    tris: &[],
                    width,
                    height,
                    samples: 1,
                    interlock: mode.map(|_| &*interlock),
                    interlock_mode: mode,
                    sample_tickets: &[],
                    mode: Mode::Direct { yield_every: 0 },
                    max_steps,
                    max_waits: max_steps,
                    spurious_cas: 0,
                    contention: None,
                    no_interpolants: false,
                };
                let inv = Invocation::new();
                inv.reset(input);
                let frag = Frag {
                    inv: &inv,
                    env: &env,
                };
                let mut fut = pin!(async move {
                    kernel.shade(frag).await;
                    frag.retire().await;
                });
                let mut cx = Context::from_waker(Waker::noop());
                loop {
                    match fut.as_mut().poll(&mut cx) {
                        Poll::Ready(()) => break,
                        Poll::Pending if inv.faulted() => break,
                        // Waiting (interlock): let the others run.
                        Poll::Pending => thread::yield_now(),
                    }
                }
                if let Some(claim) = super::slots::abandon(&inv, &env) {
                    let mut pending = vec![claim];
                    let mut waits = 0;
                    while !super::slots::pass_deferred(&mut pending, &env) && waits < max_steps {
                        waits += 1;
                        thread::yield_now();
                    }
                }
                let fault = inv.take_fault();
                ThreadOutcome {
                    input,
                    outputs: std::array::from_fn(|i| inv.outputs[i].get()),
                    discarded: inv.discarded.get(),
                    fault,
                }
            })
        })
        .collect();
    handles
        .into_iter()
        .map(|h| {
            h.join()
                .expect("invocation threads catch nothing; a panic is a kernel bug")
        })
        .collect()
}
