//! The executors' worker threads: [`broadcast`] runs one closure on `n` threads at once, the
//! caller and `n - 1` threads kept from call to call.
//!
//! Why kept: a frame opens several parallel sections (vertex transform and projection, the
//! pass, buffer clears and read-back sums), and starting two OS threads costs 80-115 µs on
//! the 2-core VMs this is measured on (`ci/c/spawn_scope.c`): a few percent of a 10 ms frame,
//! and most of a small one. Threads kept alive also keep their thread-local buffers.
//!
//! What it guarantees, which a work-stealing pool (rayon) does not: the `n` calls run on `n`
//! distinct threads *at the same time*. Invocations spin on each other (interlock, spin
//! locks in kernels), so a call may wait for another to make progress; with fewer threads
//! than calls that would be a deadlock. So threads are never shared: a call takes idle
//! threads for itself (starting new ones when none are idle) and hands them back when all
//! calls have returned, and nested or concurrent calls simply take other threads.
//!
//! Between jobs a kept thread spins for up to 100 µs before it blocks, and so does the
//! caller waiting for the last call to end (`spin_for`): a frame's sections follow each
//! other within tens of microseconds, and waking a blocked thread took 20-70 µs.
//!
//! Always `std`, also under `--cfg loom`: loom model-checks the memory and interlock
//! protocols, not the pool (as before it, `std::thread::scope`).

use std::panic::{catch_unwind, resume_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::{channel, Sender};
use std::sync::Arc;
use std::thread::{self, Thread};

pub use std::sync::Mutex;

/// The closure a broadcast runs, with its borrows' lifetime erased (see [`broadcast`]).
type Task = dyn Fn(usize) + Sync;

/// One call of a broadcast's task, sent to a kept thread.
struct Job {
    task: *const Task,
    index: usize,
    latch: Arc<Latch>,
}

// SAFETY: `task` points to a `Sync` closure (so calling it from another thread is sound),
// and `broadcast` does not return, nor unwind, before every job it sent has counted down
// its latch, after which the job no longer touches `task`.
unsafe impl Send for Job {}

/// Counts a broadcast's outstanding jobs; the last one wakes the caller.
struct Latch {
    left: AtomicUsize,
    waiter: Thread,
}

impl Latch {
    fn count_down(&self) {
        // Release: the job's result (written before) is visible to the waiter's Acquire.
        if self.left.fetch_sub(1, Ordering::AcqRel) == 1 {
            self.waiter.unpark();
        }
    }

    fn wait(&self) {
        // Spin a little first: the threads of a broadcast usually end close together
        // (their work is split to balance), and waking a parked thread takes tens of
        // microseconds on these VMs.
        if spin_for(|| (self.left.load(Ordering::Acquire) == 0).then_some(())).is_some() {
            return;
        }
        // `park` may return spuriously (or for an unpark meant for an earlier wait).
        while self.left.load(Ordering::Acquire) != 0 {
            thread::park();
        }
    }
}

/// Threads waiting for a job.
static IDLE: Mutex<Vec<Sender<Job>>> = Mutex::new(Vec::new());

/// Runs `work(i)` for every `i` in `0..n`, each call on its own thread and all at the same
/// time (`work(0)` on the calling thread), and returns the results in index order. A panic
/// in any call is resumed on the caller once every call has returned.
pub fn broadcast<R: Send>(n: usize, work: impl Fn(usize) -> R + Sync) -> Vec<R> {
    if n <= 1 {
        return (0..n).map(work).collect();
    }
    // Everything that can fail is done before the first job is sent: from then on this
    // function must not return or unwind until the jobs are done (they borrow its frame).
    let workers = take_idle(n - 1);
    let results: Vec<Mutex<Option<thread::Result<R>>>> = (0..n).map(|_| Mutex::new(None)).collect();
    let task = |i: usize| {
        let r = catch_unwind(AssertUnwindSafe(|| work(i)));
        *results[i].lock().unwrap_or_else(|e| e.into_inner()) = Some(r);
    };
    let task: &(dyn Fn(usize) + Sync + '_) = &task;
    // SAFETY: only the lifetime changes (same fat pointer). The pointer is used by the jobs
    // below, which all count down `latch` before `latch.wait()` returns, and nothing
    // between here and that wait can unwind (`task` catches the panics of `work`).
    let erased: *const Task =
        unsafe { std::mem::transmute::<&(dyn Fn(usize) + Sync + '_), &'static Task>(task) };
    let latch = Arc::new(Latch {
        left: AtomicUsize::new(n - 1),
        waiter: thread::current(),
    });
    let mut alive = Vec::with_capacity(workers.len());
    for (k, worker) in workers.into_iter().enumerate() {
        let job = Job {
            task: erased,
            index: k + 1,
            latch: latch.clone(),
        };
        // A kept thread never ends (its loop catches every panic), so the send succeeds;
        // were it to fail, the call runs here, late but not lost, and the thread is
        // forgotten.
        match worker.send(job) {
            Ok(()) => alive.push(worker),
            Err(e) => {
                let job = e.0;
                task(job.index);
                job.latch.count_down();
            }
        }
    }
    task(0);
    latch.wait();
    IDLE.lock().unwrap_or_else(|e| e.into_inner()).extend(alive);
    let mut out = Vec::with_capacity(n);
    for r in results {
        match r.into_inner().unwrap_or_else(|e| e.into_inner()) {
            Some(Ok(v)) => out.push(v),
            Some(Err(payload)) => resume_unwind(payload),
            None => unreachable!("every call of a broadcast stores its result"),
        }
    }
    out
}

/// Runs `f` on every item, each on its own thread and all at the same time (as
/// [`broadcast`]), and returns the results in item order: for work split into parts that
/// own mutable borrows.
pub fn broadcast_each<T: Send, R: Send>(items: Vec<T>, f: impl Fn(T) -> R + Sync) -> Vec<R> {
    let items: Vec<Mutex<Option<T>>> = items.into_iter().map(|t| Mutex::new(Some(t))).collect();
    broadcast(items.len(), |i| {
        let item = items[i].lock().unwrap_or_else(|e| e.into_inner()).take();
        f(item.expect("call i takes item i, once"))
    })
}

/// Splits `items` into at most `threads` parts of at least `min_part` items (one part when
/// they are fewer) and runs `f` on each part, all at once (as [`broadcast`]); returns the
/// results in part order: for reductions over large arrays, which one core reads at less
/// than the memory's bandwidth.
pub fn map_parts<T: Sync, R: Send>(
    items: &[T],
    threads: usize,
    min_part: usize,
    f: impl Fn(&[T]) -> R + Sync,
) -> Vec<R> {
    let parts = threads.min(items.len() / min_part.max(1)).max(1);
    if parts == 1 {
        return vec![f(items)];
    }
    let parts: Vec<&[T]> = items.chunks(items.len().div_ceil(parts)).collect();
    broadcast(parts.len(), |k| f(parts[k]))
}

/// `n` idle threads, starting new ones when fewer are idle.
fn take_idle(n: usize) -> Vec<Sender<Job>> {
    let mut workers = {
        let mut idle = IDLE.lock().unwrap_or_else(|e| e.into_inner());
        let keep = idle.len().saturating_sub(n);
        idle.split_off(keep)
    };
    while workers.len() < n {
        workers.push(start_thread());
    }
    workers
}

/// How long a thread spins for an event before blocking ([`spin_for`]).
const SPIN: std::time::Duration = std::time::Duration::from_micros(100);

/// Polls `event` for up to [`SPIN`]; its value as soon as it has one (`None`: none came).
/// Blocking and waking a thread costs tens of microseconds on the VMs this is measured on
/// (a frame's parallel sections start and end a few times per frame); spinning costs only
/// the idle core's time, and for a bounded while.
/// Not crossbeam's `Backoff`: that one bounds the spin by a count of doubling steps and then
/// yields; this bound is a time, the measured cost of waking a blocked thread.
fn spin_for<T>(mut event: impl FnMut() -> Option<T>) -> Option<T> {
    let start = std::time::Instant::now();
    loop {
        for _ in 0..64 {
            if let Some(v) = event() {
                return Some(v);
            }
            std::hint::spin_loop();
        }
        if start.elapsed() >= SPIN {
            return None;
        }
    }
}

/// Starts a thread that runs the jobs sent to it, one at a time, forever.
fn start_thread() -> Sender<Job> {
    let (tx, rx) = channel::<Job>();
    thread::Builder::new()
        .name("fragrace-worker".into())
        .spawn(move || {
            // A frame's parallel sections follow each other closely (a buffer's clear,
            // then the pass): wait for the next job spinning a little before blocking,
            // which would take tens of microseconds to wake from. Ends when the channel
            // closes.
            while let Some(job) = spin_for(|| rx.try_recv().ok()).or_else(|| rx.recv().ok()) {
                // SAFETY: see `Job`: the task outlives the job, until `count_down`.
                let task = unsafe { &*job.task };
                // `task` catches the panics of the work it wraps; this guard is for a
                // panic of its own bookkeeping, so the caller is never left waiting.
                let _ = catch_unwind(AssertUnwindSafe(|| task(job.index)));
                job.latch.count_down();
            }
        })
        .expect("the OS could not start a worker thread");
    tx
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicU32;

    #[test]
    fn every_index_runs_once_in_order() {
        for n in [0, 1, 2, 5] {
            let out = broadcast(n, |i| i * 10);
            assert_eq!(out, (0..n).map(|i| i * 10).collect::<Vec<_>>());
        }
    }

    #[test]
    fn calls_run_at_the_same_time() {
        // Each call waits until all have arrived: with fewer threads than calls this would
        // never finish.
        let arrived = AtomicU32::new(0);
        let n = 4;
        broadcast(n, |_| {
            arrived.fetch_add(1, Ordering::SeqCst);
            while arrived.load(Ordering::SeqCst) < n as u32 {
                std::hint::spin_loop();
            }
        });
        assert_eq!(arrived.load(Ordering::SeqCst), 4);
    }

    #[test]
    fn each_item_goes_to_one_call() {
        let mut v = vec![0u32; 10];
        broadcast_each(v.chunks_mut(3).enumerate().collect(), |(k, part)| {
            for x in part {
                *x = k as u32;
            }
        });
        assert_eq!(v, [0, 0, 0, 1, 1, 1, 2, 2, 2, 3]);
    }

    #[test]
    fn parts_cover_the_items_in_order() {
        let items: Vec<u32> = (0..1000).collect();
        for (threads, min_part, parts) in [(4, 1, 4), (4, 300, 3), (4, 2000, 1), (1, 1, 1)] {
            let got = map_parts(&items, threads, min_part, |p| p.to_vec());
            assert_eq!(got.len(), parts);
            assert_eq!(got.concat(), items);
        }
        assert_eq!(map_parts(&[] as &[u32], 4, 1, |p| p.len()), vec![0]);
    }

    #[test]
    fn nested_broadcasts_take_other_threads() {
        let out = broadcast(3, |i| broadcast(3, |j| i * 3 + j).iter().sum::<usize>());
        assert_eq!(out, vec![3, 12, 21]);
    }

    #[test]
    fn a_panic_reaches_the_caller_after_every_call_returned() {
        let finished = AtomicU32::new(0);
        let r = std::panic::catch_unwind(AssertUnwindSafe(|| {
            broadcast(3, |i| {
                if i == 1 {
                    panic!("call 1");
                }
                std::thread::sleep(std::time::Duration::from_millis(20));
                finished.fetch_add(1, Ordering::SeqCst);
            })
        }));
        assert!(r.is_err());
        assert_eq!(finished.load(Ordering::SeqCst), 2);
        // The threads are kept and still work.
        assert_eq!(broadcast(3, |i| i), vec![0, 1, 2]);
    }
}
