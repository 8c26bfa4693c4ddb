//! The algorithms under lockstep forward progress (`ScheduleConfig::simt`, lanes of a warp
//! without independent scheduling): the spinlock k-buffer deadlocks when fragments of one
//! pixel share a warp (reported, not hung); counters, lists, atomic k-buffers and hardware
//! interlock complete and match the truth.

use fragrace_emu::{ExecConfig, ExecMode, FaultKind, Mesh, Policy, ScheduleConfig};
use fragrace_kernels::basic::Truth;
use fragrace_kernels::{algorithm, oracle, AlgoResult, Frame, Params};
use glam::{Mat4, Vec3};

/// `n` overlapping quads at distinct depths, in an order that is not depth order, each a
/// little offset so that depth complexity varies (identity view-projection).
fn quads(n: usize) -> Mesh {
    let mut m = Mesh::default();
    for i in 0..n {
        let z = -0.8 + 1.6 * ((i * 5 + 2) % n) as f32 / n as f32;
        let o = (i % 3) as f32 * 0.15;
        let (x0, y0, x1, y1) = (-0.9 + o, -0.9 + o * 0.5, 0.7 + o * 0.3, 0.8 - o);
        let b = m.positions.len() as u32;
        m.positions.extend([
            Vec3::new(x0, y0, z),
            Vec3::new(x1, y0, z),
            Vec3::new(x1, y1, z),
            Vec3::new(x0, y1, z),
        ]);
        m.indices.push([b, b + 1, b + 2]);
        m.indices.push([b, b + 2, b + 3]);
    }
    m
}

fn exec(policy: Policy, seed: u64, simt: u32) -> ExecConfig {
    ExecConfig {
        mode: ExecMode::Scheduled(ScheduleConfig {
            policy,
            seed,
            simt,
            ..ScheduleConfig::default()
        }),
        ..ExecConfig::default()
    }
}

fn run(name: &str, frame: &Frame<'_>, params: &Params, e: &ExecConfig) -> AlgoResult {
    algorithm(name)
        .expect("registered")
        .run(frame, params, e)
        .expect("runs")
}

fn simt_faults(r: &AlgoResult) -> usize {
    r.report
        .faults
        .iter()
        .filter(|f| matches!(f.kind, FaultKind::SimtDeadlock { .. }))
        .count()
}

#[test]
fn lock_free_and_interlocked_algorithms_complete_and_match_the_truth() {
    let mesh = quads(6);
    let frame = Frame {
        mesh: &mesh,
        objects: &[],
        view_proj: Mat4::IDENTITY,
        width: 10,
        height: 10,
    };
    let truth = Truth::capture(&frame, 1).unwrap();
    let params = Params::default();
    for name in ["count", "ll", "kb-atomic64", "kb-interlock"] {
        let info = algorithm(name).unwrap().info();
        for (policy, seed) in [
            (Policy::Random, 0),
            (Policy::Random, 1),
            (Policy::Warp { lanes: 32 }, 0),
            (Policy::Pct { depth: 3 }, 0),
        ] {
            let what = format!("{name}, {policy} seed {seed}, simt 32");
            let r = run(name, &frame, &params, &exec(policy, seed, 32));
            assert_eq!(r.report.stats.faulted, 0, "{what}: {:?}", r.report.faults);
            for c in &r.checks {
                assert!(c.passed, "{what}: {} ({})", c.name, c.detail);
            }
            let m = oracle::compare(&info, &r, &truth, &params);
            assert_eq!(m.error_pixels, 0, "{what}: first error {:?}", m.first_error);
        }
    }
}

#[test]
fn the_spinlock_k_buffer_deadlocks_when_fragments_of_one_pixel_share_a_warp() {
    let mesh = quads(6);
    let frame = Frame {
        mesh: &mesh,
        objects: &[],
        view_proj: Mat4::IDENTITY,
        width: 8,
        height: 8,
    };
    // A spinlock that never gives up, as it is usually written.
    let params = Params {
        spin_cap: u32::MAX,
        ..Params::default()
    };
    for seed in 0..2 {
        let r = run(
            "kb-spinlock",
            &frame,
            &params,
            &exec(Policy::Random, seed, 32),
        );
        let faults = simt_faults(&r);
        assert!(faults > 0, "seed {seed}: {:?}", r.report.faults);
        // (The report keeps the first faults in detail and counts them all.)
        assert_eq!(
            faults,
            r.report.faults.len(),
            "seed {seed}: only SIMT deadlocks: {:?}",
            r.report.faults
        );
        // The deadlocked spinners neither entered the lock nor gave up: the invariant
        // check says so; every lock was still released (the held holders ran in the end).
        let failed: Vec<&str> = r
            .checks
            .iter()
            .filter(|c| !c.passed)
            .map(|c| c.name.as_str())
            .collect();
        assert!(
            failed.iter().any(|n| n.contains("entered the lock")),
            "{failed:?}"
        );
        assert!(!failed.iter().any(|n| n.contains("released")), "{failed:?}");
    }
    // With independent scheduling (or warps of one lane) the holder always gets to
    // release: no fault.
    for e in [exec(Policy::Random, 0, 0), exec(Policy::Random, 0, 1)] {
        let r = run("kb-spinlock", &frame, &params, &e);
        assert_eq!(r.report.stats.faulted, 0, "{e:?}: {:?}", r.report.faults);
        assert!(r.checks.iter().all(|c| c.passed));
    }
}

#[test]
fn with_its_spin_cap_the_spinlock_k_buffer_drops_warp_mates_instead() {
    let mesh = quads(6);
    let frame = Frame {
        mesh: &mesh,
        objects: &[],
        view_proj: Mat4::IDENTITY,
        width: 8,
        height: 8,
    };
    let params = Params::default();
    let simt = run("kb-spinlock", &frame, &params, &exec(Policy::Random, 0, 32));
    let free = run("kb-spinlock", &frame, &params, &exec(Policy::Random, 0, 0));
    // Bounded spins are not deadlocks: spinners give up (counted), then the holder runs.
    assert_eq!(simt.report.stats.faulted, 0, "{:?}", simt.report.faults);
    assert!(simt.checks.iter().all(|c| c.passed));
    assert!(
        simt.dropped > free.dropped,
        "lockstep makes warp-mates of a holder give up: {} vs {}",
        simt.dropped,
        free.dropped
    );
}
