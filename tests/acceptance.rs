//! Acceptance checks of the software GPU as a whole (issue: the software GPU): the minimal
//! racy kernel loses updates where and only where it should, and scheduled runs are
//! reproducible.

use fragrace::run::{self, RunSpec, SceneSpec};
use fragrace_emu::{ExecConfig, ExecMode, Policy, ScheduleConfig};

fn spec(scene: &str, algo: &str, size: u32, exec: ExecConfig) -> RunSpec {
    let mut s = RunSpec::new(SceneSpec::Builtin(scene.into()), algo);
    s.width = size;
    s.height = size;
    s.exec = exec;
    s
}

fn scheduled(policy: Policy, seed: u64) -> ExecConfig {
    ExecConfig {
        mode: ExecMode::Scheduled(ScheduleConfig {
            policy,
            seed,
            window: 64,
            record: true,
            ..Default::default()
        }),
        ..ExecConfig::default()
    }
}

fn counts(s: &RunSpec) -> (Vec<u32>, fragrace_emu::PassReport) {
    let loaded = run::load(s).unwrap();
    let r = run::render(s, &loaded).unwrap().result;
    (r.counts.unwrap().into_vec(), r.report)
}

#[test]
fn count_plain_loses_updates_and_count_never_does() {
    let (exact, _) = counts(&spec("hairball", "count", 128, ExecConfig::ordered()));
    let total: u64 = exact.iter().map(|&c| c as u64).sum();
    let mut execs = vec![ExecConfig::parallel(2), ExecConfig::parallel(4)];
    for p in Policy::all() {
        execs.push(scheduled(p, 3));
    }
    for e in &execs {
        let (c, r) = counts(&spec("hairball", "count", 128, e.clone()));
        assert_eq!(c, exact, "count lost an update under {e:?}");
        assert_eq!(r.hazards.total(), 0);
    }
    // Parallel: real threads plus lockstep warps lose updates on the hairball.
    let (c, _) = counts(&spec(
        "hairball",
        "count-plain",
        128,
        ExecConfig::parallel(2),
    ));
    let got: u64 = c.iter().map(|&v| v as u64).sum();
    assert!(
        got < total,
        "parallel count-plain lost nothing ({got} of {total})"
    );
    assert!(
        c.iter().zip(&exact).all(|(a, b)| a <= b),
        "a plain count can only lose, never gain"
    );
    // Scheduled: every interleaving policy loses updates and the detector names them.
    for p in [
        Policy::Random,
        Policy::Pct { depth: 3 },
        Policy::Warp { lanes: 32 },
        Policy::Reverse,
        Policy::FarFirst,
    ] {
        let (c, r) = counts(&spec(
            "hairball",
            "count-plain",
            128,
            scheduled(p.clone(), 1),
        ));
        let got: u64 = c.iter().map(|&v| v as u64).sum();
        assert!(got < total, "{p}: lost nothing");
        assert!(
            r.hazards.lost_updates > 0,
            "{p}: the detector saw no lost update"
        );
        let h = &r.hazard_list[0];
        assert_eq!(h.buffer, "counts");
        assert_eq!(
            h.index,
            h.victim.y * 128 + h.victim.x,
            "the hazard names its pixel"
        );
    }
}

#[test]
fn scheduled_runs_are_bit_identical_per_seed_and_differ_across_seeds() {
    let a = spec("hairball", "count-plain", 64, scheduled(Policy::Random, 11));
    let (c1, r1) = counts(&a);
    let (c2, r2) = counts(&a);
    assert_eq!(c1, c2);
    assert_eq!(r1.schedule, r2.schedule);
    assert_eq!(r1.hazards, r2.hazards);
    let (c3, r3) = counts(&spec(
        "hairball",
        "count-plain",
        64,
        scheduled(Policy::Random, 12),
    ));
    assert!(c3 != c1 || r3.schedule != r1.schedule);
}

#[test]
fn a_recorded_schedule_replays_exactly_through_the_bytes_policy() {
    // A recorded schedule (one byte per step) fed back as an explicit schedule.
    let mut s = spec(
        "hairball",
        "count-plain",
        96,
        scheduled(Policy::Pct { depth: 3 }, 4),
    );
    s.params.k = 8;
    let (c1, r1) = counts(&s);
    let bytes = r1.schedule.clone().unwrap();
    let (c2, r2) = counts(&spec(
        "hairball",
        "count-plain",
        96,
        scheduled(Policy::Bytes(bytes.clone()), 0),
    ));
    assert_eq!(c1, c2);
    assert_eq!(r2.schedule.unwrap(), bytes);
}

#[test]
fn the_bunny_matches_the_llvmpipe_peers_figures() {
    // From ../shared/peers/llvmpipe/README.md (Mesa 22.3.6 llvmpipe, 512x512, azimuth 0):
    // 111,892 fragments over 55,090 covered pixels, depth complexity max 6.
    let (c, r) = counts(&spec("bunny", "count", 512, ExecConfig::parallel(2)));
    assert_eq!(r.stats.fragments_generated, 111_892);
    assert_eq!(c.iter().filter(|&&v| v > 0).count(), 55_090);
    assert_eq!(c.iter().copied().max(), Some(6));
}

/// Lockstep warps interleave their lanes at every access even on one thread: in one turn
/// every lane loads, in the next every lane stores, so lanes of one warp on one pixel lose
/// each other's plain increments, the same on every run. Independent lanes on one thread run
/// each invocation to its end and lose nothing.
#[test]
fn lockstep_lanes_race_on_one_thread_and_independent_lanes_do_not() {
    let mut exact_spec = spec("hairball", "count", 64, ExecConfig::ordered());
    exact_spec.exec.threads = 1;
    let (exact, _) = counts(&exact_spec);
    let total: u64 = exact.iter().map(|&v| v as u64).sum();
    let run = |lockstep: bool| {
        let mut e = ExecConfig::parallel(1);
        e.lockstep = lockstep;
        counts(&spec("hairball", "count-plain", 64, e)).0
    };
    let (a, b) = (run(true), run(true));
    let got: u64 = a.iter().map(|&v| v as u64).sum();
    assert!(got < total, "lockstep lost nothing ({got} of {total})");
    assert_eq!(
        a, b,
        "one thread: the lockstep interleaving is deterministic"
    );
    assert_eq!(
        run(false),
        exact,
        "independent lanes on one thread lost an update"
    );
}

/// `bench` times a frame without its self-check (as the llvmpipe peer times its frames):
/// `run` must still be exactly the frame followed by the check, and `render` must run both.
#[test]
fn count_frame_then_self_check_is_run() {
    use fragrace_kernels::Params;
    let s = spec("hairball", "count", 96, ExecConfig::parallel(2));
    let loaded = run::load(&s).unwrap();
    let frame = loaded.frame(&s);
    let count = fragrace_kernels::algorithm("count").unwrap();
    let whole = count.run(&frame, &Params::default(), &s.exec).unwrap();
    let mut split = count
        .run_frame(&frame, &Params::default(), &s.exec)
        .unwrap();
    assert!(
        split.checks.is_empty(),
        "the frame alone reads nothing back"
    );
    count.self_check(&mut split, &s.exec);
    assert_eq!(split.counts, whole.counts);
    let names = |r: &fragrace_kernels::AlgoResult| {
        r.checks
            .iter()
            .map(|c| (c.name.clone(), c.passed, c.detail.clone()))
            .collect::<Vec<_>>()
    };
    assert_eq!(names(&split), names(&whole));
    assert!(!whole.checks.is_empty() && whole.checks.iter().all(|c| c.passed));
    let rendered = run::render(&s, &loaded).unwrap();
    assert_eq!(
        names(&rendered.result),
        names(&whole),
        "render checks the frame"
    );

    // count-plain: what the check finds missing is what races lost.
    let s = spec("hairball", "count-plain", 96, ExecConfig::parallel(2));
    let r = run::render(&s, &loaded).unwrap().result;
    let sum: u64 = r
        .counts
        .as_ref()
        .unwrap()
        .iter()
        .map(|&c| u64::from(c))
        .sum();
    assert_eq!(r.dropped, r.report.stats.fragments_generated - sum);
    assert_eq!(r.checks.len(), 1);
}
