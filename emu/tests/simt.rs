//! Lockstep forward progress (`ScheduleConfig::simt`): spinlocks whose holder shares a warp
//! with its spinners deadlock (reported, never hung), lock-free retry loops and bounded
//! spins complete.

use fragrace_emu::{
    Buf, Device, ExecConfig, ExecMode, FaultKind, FragInput, Fragment, FragmentKernel, KernelInfo,
    PassReport, Policy, ScheduleConfig,
};

/// A per-pixel spinlock around a plain increment, as kernels write it where interlock is
/// missing: compare-exchange 0 -> 1 until it succeeds (or `cap` attempts), then release.
struct SpinLock {
    lock: Buf<u32>,
    count: Buf<u32>,
    gave_up: Buf<u32>,
    /// Attempts before giving up (u32::MAX: never).
    cap: u32,
    /// Call `yield_now` between attempts.
    yields: bool,
}

impl FragmentKernel for SpinLock {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("spinlock")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let mut attempts = 0u32;
        while f.atomic_compare_exchange(self.lock, p, 0, 1).await.is_err() {
            attempts += 1;
            if attempts >= self.cap {
                f.atomic_add(self.gave_up, p, 1).await;
                return;
            }
            if self.yields {
                f.yield_now().await;
            }
        }
        let c = f.load(self.count, p).await;
        f.store(self.count, p, c + 1).await;
        f.atomic_store(self.lock, p, 0).await;
    }
}

/// Lock-free push onto a per-pixel list: a compare-exchange retry loop on the head.
struct Push {
    counter: Buf<u32>,
    head: Buf<u32>,
    next: Buf<u32>,
}

impl FragmentKernel for Push {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("push")
    }
    async fn shade(&self, f: impl Fragment) {
        let node = f.atomic_add(self.counter, 0, 1).await;
        let mut old = f.atomic_load(self.head, f.pixel_index()).await;
        loop {
            f.store(self.next, node, old).await;
            match f
                .atomic_compare_exchange(self.head, f.pixel_index(), old, node)
                .await
            {
                Ok(_) => break,
                Err(cur) => old = cur,
            }
        }
    }
}

fn exec(policy: Policy, seed: u64, simt: u32) -> ExecConfig {
    ExecConfig {
        mode: ExecMode::Scheduled(ScheduleConfig {
            policy,
            seed,
            window: 64,
            record: true,
            simt,
            ..Default::default()
        }),
        ..ExecConfig::default()
    }
}

/// `n` fragments on pixel 0 of a 1x1 target.
fn frags(n: u32) -> Vec<FragInput> {
    (0..n)
        .map(|i| FragInput {
            primitive_id: i,
            coverage: 1,
            ..Default::default()
        })
        .collect()
}

struct Spin {
    report: PassReport,
    count: u32,
    gave_up: u32,
    lock: u32,
}

fn spin(n: u32, cap: u32, yields: bool, e: &ExecConfig) -> Spin {
    let mut dev = Device::new();
    let lock = dev.buffer::<u32>("lock", 1).unwrap();
    let count = dev.buffer::<u32>("count", 1).unwrap();
    let gave_up = dev.buffer::<u32>("gave-up", 1).unwrap();
    let k = SpinLock {
        lock,
        count,
        gave_up,
        cap,
        yields,
    };
    let report = dev.invocations(1, 1, &frags(n), &k, e);
    let get = |b| dev.memory.get(b, 0).unwrap();
    Spin {
        count: get(count),
        gave_up: get(gave_up),
        lock: get(lock),
        report,
    }
}

fn simt_faults(r: &PassReport) -> Vec<(u64, Vec<u64>, Vec<u64>)> {
    r.faults
        .iter()
        .filter_map(|f| match &f.kind {
            FaultKind::SimtDeadlock {
                warp,
                spinning,
                held,
            } => Some((*warp, spinning.clone(), held.clone())),
            _ => None,
        })
        .collect()
}

#[test]
fn a_spinlock_deadlocks_when_its_holder_shares_the_warp() {
    // Lockstep: lane 0 takes the lock, lane 1 fails and loops; lane 0, past the loop,
    // cannot run until lane 1 leaves it.
    let s = spin(2, u32::MAX, false, &exec(Policy::Warp { lanes: 32 }, 0, 32));
    assert_eq!(simt_faults(&s.report), vec![(0, vec![1], vec![0])]);
    assert_eq!(s.report.stats.faulted, 1, "{:?}", s.report.faults);
    // Reported, not hung: the spinner was ended and the holder finished its section.
    assert_eq!((s.count, s.lock), (1, 0));
    let text = s.report.faults[0].kind.to_string();
    assert!(
        text.contains("warp 0") && text.contains("[1]") && text.contains("[0]"),
        "{text}"
    );
}

#[test]
fn independent_scheduling_lets_the_holder_release() {
    // (Not under PCT: a priority drop starves the holder of every step, which is the
    // watchdog's case, not this mode's.)
    for policy in [Policy::Warp { lanes: 32 }, Policy::Random] {
        let s = spin(4, u32::MAX, false, &exec(policy.clone(), 0, 0));
        assert_eq!(s.report.stats.faulted, 0, "{policy}: {:?}", s.report.faults);
        assert_eq!((s.count, s.lock), (4, 0), "{policy}");
    }
}

#[test]
fn under_random_schedules_every_run_completes_or_reports_the_deadlock() {
    let mut deadlocked = 0;
    for seed in 0..16 {
        let s = spin(3, u32::MAX, false, &exec(Policy::Random, seed, 32));
        let f = simt_faults(&s.report);
        assert_eq!(
            f.len() as u64,
            s.report.stats.faulted,
            "seed {seed}: only SIMT faults"
        );
        // Every fragment either entered the lock or was ended as a deadlocked spinner.
        assert_eq!(s.count as usize + f.len(), 3, "seed {seed}: {f:?}");
        assert_eq!(s.lock, 0, "seed {seed}: the lock is released in the end");
        deadlocked += (!f.is_empty()) as u32;
    }
    assert!(
        deadlocked > 0,
        "some schedule lets a lane spin on its warp-mate's lock"
    );
}

#[test]
fn lanes_of_different_warps_progress_independently() {
    // Warps of one lane: a spinner never holds back its lock's holder.
    let s = spin(4, u32::MAX, false, &exec(Policy::Warp { lanes: 32 }, 0, 1));
    assert_eq!(s.report.stats.faulted, 0, "{:?}", s.report.faults);
    assert_eq!((s.count, s.lock), (4, 0));
}

#[test]
fn a_yield_in_the_loop_is_a_spin_too() {
    let s = spin(2, u32::MAX, true, &exec(Policy::Warp { lanes: 32 }, 0, 32));
    assert_eq!(simt_faults(&s.report), vec![(0, vec![1], vec![0])]);
    assert_eq!((s.count, s.lock), (1, 0));
}

#[test]
fn a_bounded_spin_gives_up_and_is_not_a_deadlock() {
    // Fewer attempts than the deadlock bound: the spinner leaves the loop (dropping its
    // work), then the holder runs: on such hardware, every warp-mate of a holder gives up.
    let s = spin(4, 100, false, &exec(Policy::Warp { lanes: 32 }, 0, 32));
    assert_eq!(s.report.stats.faulted, 0, "{:?}", s.report.faults);
    assert_eq!((s.count, s.gave_up, s.lock), (1, 3, 0));
    // Independent scheduling gives the holder its turns: nobody gives up.
    let s = spin(4, 100, false, &exec(Policy::Warp { lanes: 32 }, 0, 0));
    assert_eq!((s.count, s.gave_up), (4, 0));
}

#[test]
fn lock_free_retry_loops_complete() {
    for seed in 0..8 {
        for policy in [
            Policy::Random,
            Policy::Warp { lanes: 32 },
            Policy::Pct { depth: 2 },
        ] {
            let mut dev = Device::new();
            let counter = dev.buffer::<u32>("counter", 1).unwrap();
            let head = dev.buffer::<u32>("head", 1).unwrap();
            let next = dev.buffer::<u32>("next", 9).unwrap();
            dev.memory.set(counter, 0, 1).unwrap();
            let r = dev.invocations(
                1,
                1,
                &frags(8),
                &Push {
                    counter,
                    head,
                    next,
                },
                &exec(policy.clone(), seed, 32),
            );
            assert_eq!(r.stats.faulted, 0, "{policy} {seed}: {:?}", r.faults);
            let mut p = dev.memory.get(head, 0).unwrap();
            let mut seen = vec![];
            while p != 0 && seen.len() < 9 {
                seen.push(p);
                p = dev.memory.get(next, p).unwrap();
            }
            seen.sort_unstable();
            assert_eq!(seen, (1..=8).collect::<Vec<u32>>(), "{policy} {seed}");
        }
    }
}

#[test]
fn simt_runs_replay_exactly() {
    let e = exec(Policy::Random, 5, 32);
    let (a, b) = (spin(3, u32::MAX, false, &e), spin(3, u32::MAX, false, &e));
    assert_eq!(a.report.faults, b.report.faults);
    assert_eq!(a.report.schedule, b.report.schedule);
    // And a recorded schedule replays under the same mode.
    let bytes = a.report.schedule.clone().unwrap();
    let c = spin(3, u32::MAX, false, &exec(Policy::Bytes(bytes), 0, 32));
    assert_eq!(a.report.faults, c.report.faults);
    assert_eq!(a.count, c.count);
}
