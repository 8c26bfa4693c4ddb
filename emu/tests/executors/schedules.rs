//! The scheduled executor and its detector: exact atomics, lost updates seen, runs bit-identical
//! per seed, recorded and byte-string schedules, policies, settings refused by name, torn
//! records, contention, weak compare-exchange, reduction.

use fragrace_emu::{
    Buf, Device, ExecConfig, ExecMode, Fragment, FragmentKernel, FragmentState, KernelInfo, Policy,
    ScheduleConfig,
};

use super::common::*;

fn run_counter(exec: &ExecConfig, atomic: bool) -> (u32, fragrace_emu::PassReport) {
    let mut dev = Device::new();
    let counter = dev.buffer::<u32>("counter", 1).unwrap();
    let mut fb = fb(16, 16);
    let r = dev
        .fullscreen(
            &mut fb,
            &FragmentState::new(),
            &GlobalCounter { counter, atomic },
            exec,
        )
        .unwrap();
    (dev.memory.read(counter).unwrap()[0], r)
}

#[test]
fn atomic_counter_is_exact_under_every_executor() {
    let mut execs = vec![
        ExecConfig::ordered(),
        ExecConfig::parallel(2),
        ExecConfig::parallel(4),
    ];
    for p in Policy::all() {
        for seed in 0..3 {
            execs.push(scheduled(p.clone(), seed));
        }
    }
    for e in &execs {
        let (v, r) = run_counter(e, true);
        assert_eq!(v, 256, "{e:?}");
        assert_eq!(r.hazards.total(), 0, "{e:?}");
        assert_eq!(r.stats.shaded, 256);
        assert_eq!(r.stats.ops.get("add"), Some(&256));
    }
}

#[test]
fn plain_counter_loses_updates_and_the_detector_sees_them() {
    let (v, _) = run_counter(&ExecConfig::ordered(), false);
    assert_eq!(v, 256, "ordered is the reference: no loss");
    for p in [
        Policy::Random,
        Policy::Pct { depth: 3 },
        Policy::Warp { lanes: 4 },
    ] {
        let (v, r) = run_counter(&scheduled(p.clone(), 7), false);
        assert!(v < 256, "{p}: {v}");
        assert!(r.hazards.lost_updates > 0, "{p}: {:?}", r.hazards);
        assert!(r.hazards.races > 0, "{p}");
        let h = &r.hazard_list[0];
        assert_eq!(h.buffer, "counter");
        assert!(h.victim.seq != h.other.seq);
    }
}

#[test]
fn scheduled_runs_are_bit_identical_per_seed_and_differ_across_seeds() {
    let a = run_counter(&scheduled(Policy::Random, 42), false);
    let b = run_counter(&scheduled(Policy::Random, 42), false);
    assert_eq!(a.0, b.0);
    assert_eq!(a.1.schedule, b.1.schedule);
    assert_eq!(a.1.hazards, b.1.hazards);
    let schedules: std::collections::HashSet<_> = (0..8)
        .map(|s| {
            run_counter(&scheduled(Policy::Random, s), false)
                .1
                .schedule
                .unwrap()
        })
        .collect();
    assert!(
        schedules.len() > 1,
        "different seeds should give different schedules"
    );
}

#[test]
fn recorded_schedule_replays_exactly() {
    let (v, r) = run_counter(&scheduled(Policy::Pct { depth: 3 }, 5), false);
    let bytes = r.schedule.clone().unwrap();
    let (v2, r2) = run_counter(&scheduled(Policy::Bytes(bytes.clone()), 99), false);
    assert_eq!(v, v2);
    assert_eq!(r2.schedule.unwrap(), bytes);
    assert_eq!(r.hazards, r2.hazards);
}

#[test]
fn any_byte_string_is_a_valid_schedule() {
    for bytes in [vec![], vec![0xff; 3], (0..=255u8).collect::<Vec<_>>()] {
        let (v, r) = run_counter(&scheduled(Policy::Bytes(bytes), 0), false);
        assert!((1..=256).contains(&v));
        assert_eq!(r.stats.shaded, 256);
    }
}

#[test]
fn policies_parse_and_print() {
    for s in [
        "random",
        "pct:3",
        "warp:32",
        "reverse",
        "fifo",
        "far-first",
        "bytes:00ff10",
    ] {
        let p: Policy = s.parse().unwrap();
        assert_eq!(p.to_string(), s);
    }
    use fragrace_emu::exec::PolicyParseError;
    // A known policy with a bad value is a bad value, not an unknown policy.
    assert!(matches!(
        "pct:0".parse::<Policy>(),
        Err(PolicyParseError::BadValue {
            name: "depth",
            min: 1,
            ..
        })
    ));
    assert!(matches!(
        "bytes:0".parse::<Policy>(),
        Err(PolicyParseError::BadHex(_))
    ));
    // Not a char boundary at an even offset: an error, not a panic.
    assert!(matches!(
        "bytes:\u{e9}1".parse::<Policy>(),
        Err(PolicyParseError::BadHex(_))
    ));
    assert!(matches!(
        "nope".parse::<Policy>(),
        Err(PolicyParseError::Unknown(_))
    ));
}

#[test]
fn exec_settings_out_of_range_are_refused_by_name() {
    use fragrace_emu::exec::{ExecConfigError, MAX_WINDOW};
    use fragrace_emu::{ExecMode, ScheduleConfig};
    let name_of = |c: &ExecConfig| match c.validate() {
        Err(ExecConfigError::OutOfRange { name, .. }) => name,
        Ok(()) => "ok",
    };
    let sched = |window, policy| ExecConfig {
        mode: ExecMode::Scheduled(ScheduleConfig {
            policy,
            window,
            ..ScheduleConfig::default()
        }),
        ..ExecConfig::default()
    };
    assert_eq!(name_of(&ExecConfig::default()), "ok");
    assert_eq!(name_of(&sched(MAX_WINDOW, Policy::Random)), "ok");
    assert_eq!(name_of(&sched(0, Policy::Random)), "window (--window)");
    assert_eq!(
        name_of(&sched(MAX_WINDOW + 1, Policy::Random)),
        "window (--window)"
    );
    assert_eq!(
        name_of(&sched(8, Policy::Pct { depth: 0 })),
        "pct depth (--policy pct:D)"
    );
    let threads = ExecConfig {
        threads: fragrace_emu::exec::max_threads() + 1,
        ..ExecConfig::default()
    };
    assert_eq!(name_of(&threads), "threads (--threads)");
    let lanes = ExecConfig {
        batch: 0,
        ..ExecConfig::default()
    };
    assert_eq!(
        name_of(&lanes),
        "lanes per warp (--lanes, `batch` in case files)"
    );
    let steps = ExecConfig {
        max_steps: 0,
        ..ExecConfig::default()
    };
    assert_eq!(name_of(&steps), "max_steps");
}

struct Record {
    buf: Buf<u32>,
    write: bool,
}

impl FragmentKernel for Record {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("record")
    }
    async fn shade(&self, f: impl Fragment) {
        if self.write && f.x().is_multiple_of(2) {
            f.store_record(self.buf, 0, &[f.x(), f.x(), f.x()]).await;
        } else {
            let mut r = [0u32; 3];
            f.load_record(self.buf, 0, &mut r).await;
        }
    }
}

#[test]
fn torn_records_are_detected() {
    let mut torn = 0;
    for seed in 0..10 {
        let mut dev = Device::new();
        let buf = dev.buffer::<u32>("rec", 3).unwrap();
        let mut fb = fb(8, 1);
        let r = dev
            .fullscreen(
                &mut fb,
                &FragmentState::new(),
                &Record { buf, write: true },
                &scheduled(Policy::Random, seed),
            )
            .unwrap();
        torn += r.hazards.torn;
    }
    assert!(torn > 0);
    // Readers only: nothing to tear.
    let mut dev = Device::new();
    let buf = dev.buffer::<u32>("rec", 3).unwrap();
    let mut fb = fb(8, 1);
    let r = dev
        .fullscreen(
            &mut fb,
            &FragmentState::new(),
            &Record { buf, write: false },
            &scheduled(Policy::Random, 3),
        )
        .unwrap();
    assert_eq!(r.hazards.total(), 0);
}

#[test]
fn contention_names_the_hottest_address() {
    let mut dev = Device::new();
    let counter = dev.buffer::<u32>("counter", 1).unwrap();
    let mut fb = fb(32, 32);
    let e = ExecConfig {
        contention: true,
        ..ExecConfig::parallel(2)
    };
    let r = dev
        .fullscreen(
            &mut fb,
            &FragmentState::new(),
            &GlobalCounter {
                counter,
                atomic: true,
            },
            &e,
        )
        .unwrap();
    let h = &r.stats.hotspots[0];
    assert_eq!(
        (h.buffer.as_str(), h.index, h.accesses),
        ("counter", 0, 1024)
    );
    assert!(h.peak_concurrent >= 1);
    // Scheduled runs report contention from the detector.
    let (_, r) = run_counter(&scheduled(Policy::Random, 1), false);
    assert_eq!(r.stats.hotspots[0].accesses, 512);
    assert!(r.stats.hotspots[0].peak_concurrent > 1);
}

/// Increments a counter with a weak compare-exchange: retrying (correct) or not (drops an
/// increment on every spurious failure).
struct WeakCas {
    counter: Buf<u32>,
    retry: bool,
}

impl FragmentKernel for WeakCas {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("weak-cas")
    }
    async fn shade(&self, f: impl Fragment) {
        let mut old = f.atomic_load(self.counter, 0).await;
        loop {
            match f
                .atomic_compare_exchange_weak(self.counter, 0, old, old + 1)
                .await
            {
                Ok(_) => break,
                Err(cur) if self.retry => old = cur,
                Err(_) => break,
            }
        }
    }
}

#[test]
fn weak_compare_exchange_fails_spuriously_when_asked() {
    let run = |retry: bool, per_mille: u32, exec: ExecConfig| {
        let mut dev = Device::new();
        let counter = dev.buffer::<u32>("counter", 1).unwrap();
        let mut fb = fb(16, 16);
        let e = ExecConfig {
            spurious_cas_per_mille: per_mille,
            ..exec
        };
        let r = dev
            .fullscreen(
                &mut fb,
                &FragmentState::new(),
                &WeakCas { counter, retry },
                &e,
            )
            .unwrap();
        (dev.memory.read(counter).unwrap()[0], r)
    };
    for exec in [ExecConfig::ordered(), scheduled(Policy::Random, 2)] {
        // No spurious failures: both forms count exactly under ordered.
        assert_eq!(run(false, 0, ExecConfig::ordered()).0, 256);
        // Retrying loops survive spurious failures.
        let (v, r) = run(true, 300, exec.clone());
        assert_eq!(v, 256, "{exec:?}");
        assert!(
            r.stats.ops.of(fragrace_emu::memory::OpKind::AtomicLoad) > 256,
            "spurious failures read the word"
        );
        // A single attempt loses increments to spurious failures (deterministically).
        let (v1, _) = run(false, 300, exec.clone());
        let (v2, _) = run(false, 300, exec.clone());
        assert!(v1 < 256, "{exec:?}");
        assert_eq!(v1, v2);
    }
}

#[test]
fn reduction_keeps_every_step_and_still_finds_lost_updates() {
    let plain = |reduce: bool| {
        let e = ExecConfig {
            mode: ExecMode::Scheduled(ScheduleConfig {
                policy: Policy::Random,
                seed: 5,
                window: 16,
                record: true,
                reduce,
                ..Default::default()
            }),
            ..ExecConfig::default()
        };
        run_counter(&e, false)
    };
    let (v_full, r_full) = plain(false);
    let (v_red, r_red) = plain(true);
    assert_eq!(r_full.stats.steps, r_red.stats.steps);
    assert!(v_full < 256 && v_red < 256);
    assert!(r_red.hazards.lost_updates > 0);
}
