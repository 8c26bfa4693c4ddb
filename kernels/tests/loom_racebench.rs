//! loom label checks of the race benchmark (`fragrace_kernels::racebench`): every kernel
//! runs as a loom model on the first three fragments (two for the interlock and spinlock
//! kernels) of one pixel of the benchmark's scene,
//! one loom thread per invocation (`Case::run_threads`, i.e.
//! `fragrace_emu::exec::run_on_threads`), and its oracle judges each execution loom
//! explores (loom also models weak memory: a relaxed load may read a stale value). A
//! `racy` kernel must show a wrong result or a hang in some execution; a `race-free`
//! kernel in none. So the labels the detector is measured against are checked, not only
//! asserted. The models run emu's own atomics (acquire-release for kernel atomics, relaxed
//! for plain accesses), the semantics the detector's happens-before follows: loom finding
//! no bug in `spin-plain-section` (a plain section under a compare-exchange / atomic-store
//! lock) is what makes the detector's silence there right, and loom finding the bug in
//! `spin-plain-release` (released by a plain, relaxed store) what makes its report right.
//!
//! Run with `RUSTFLAGS="--cfg loom" cargo test --release --target-dir target/loom
//! -p fragrace-kernels --test loom_racebench` (or `bash ci/loom.sh`); `-- --nocapture`
//! prints each kernel's executions and time.
#![cfg(loom)]

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use fragrace_emu::FragInput;
use fragrace_kernels::racebench::{cases, scene, Case, Fragments, Label};

/// Invocations per model.
const INVOCATIONS: usize = 3;
/// Invocations of the models whose waits (interlock, spinlocks) multiply the interleavings
/// (as in `kernels/tests/loom/rmw.rs`, whose interlock models take two fragments).
const WAITING: usize = 2;
const WAITING_FAMILIES: [&str; 1] = ["locks"];
/// Preemption bound of every model.
const PREEMPTIONS: usize = 2;
/// Watchdog per invocation: above the capped spinlocks' 16 attempts and their sections,
/// so only a lock that is never released makes a hang.
const STEPS: u64 = 48;

/// The pixel the models take their fragments from: its second primitive is nearer than its
/// first (0.21 behind 0.73), so that "nearer wins" kernels change their record with two
/// invocations already (checked in [`one_pixel`]).
const LOOM_PIXEL: u32 = 3;

/// The first `n` fragments of pixel `p`, as a one-pixel pass (pixel (0, 0), tickets
/// renumbered).
fn one_pixel(fr: &Fragments, p: u32, n: usize) -> Fragments {
    let inputs: Vec<FragInput> = fr
        .of_pixel(p)
        .take(n)
        .enumerate()
        .map(|(i, f)| FragInput {
            seq: i as u64,
            ticket: i as u32,
            x: 0,
            y: 0,
            ..*f
        })
        .collect();
    assert_eq!(inputs.len(), n);
    assert!(inputs[1].depth < inputs[0].depth, "see LOOM_PIXEL");
    Fragments {
        width: 1,
        height: 1,
        inputs,
    }
}

/// The scene's fragments, rasterized once inside a loom model (emu's memory is made of loom
/// atomics under `--cfg loom`, which only exist inside one).
fn fragments() -> Fragments {
    let out = Arc::new(Mutex::new(None));
    let o = out.clone();
    loom::model(move || {
        *o.lock().unwrap() = Some(scene::fragments());
    });
    let f = out.lock().unwrap().take();
    f.expect("the model ran")
}

/// Explores `case`; returns (some execution was wrong or hung, example, executions).
fn explore(case: &'static dyn Case, frags: &Fragments) -> (bool, Option<String>, u64) {
    let mut b = loom::model::Builder::new();
    b.preemption_bound = Some(PREEMPTIONS);
    b.max_branches = 1_000_000;
    let bad = Arc::new(AtomicBool::new(false));
    let example = Arc::new(Mutex::new(None));
    let executions = Arc::new(AtomicU64::new(0));
    let (bad2, ex2, n2, frags) = (
        bad.clone(),
        example.clone(),
        executions.clone(),
        frags.clone(),
    );
    b.check(move || {
        n2.fetch_add(1, Relaxed);
        let out = case.run_threads(&frags, STEPS);
        assert!(
            out.faults.is_empty(),
            "{}: {:?}",
            case.meta().name,
            out.faults
        );
        let what = match (&out.violation, out.reports.is_empty()) {
            (Some(v), _) => Some(v.what.clone()),
            (None, false) => Some(format!("{:?}", out.reports)),
            (None, true) => None,
        };
        if let Some(w) = what {
            if !bad2.swap(true, Relaxed) {
                *ex2.lock().unwrap() = Some(w);
            }
        }
    });
    let example = example.lock().unwrap().take();
    (bad.load(Relaxed), example, executions.load(Relaxed))
}

#[test]
fn every_label_holds_under_loom() {
    let frags = fragments();
    let all: &'static [Box<dyn Case>] = Box::leak(cases().into_boxed_slice());
    let only = std::env::var("RACEBENCH_KERNELS").ok();
    let mut wrong = Vec::new();
    for case in all {
        let m = case.meta();
        if only
            .as_deref()
            .is_some_and(|o| !o.split(',').any(|k| k == m.name))
        {
            continue;
        }
        let waits = WAITING_FAMILIES.contains(&m.family) || m.name.contains("interlock");
        let n = if waits { WAITING } else { INVOCATIONS };
        let frags = one_pixel(&frags, LOOM_PIXEL, n);
        let start = Instant::now();
        let (bad, example, n) = explore(case.as_ref(), &frags);
        println!(
            "{:<30} {:<9} {:<5} {n:>8} executions {:>7.2} s  {}",
            m.name,
            m.label.name(),
            if bad { "bug" } else { "clean" },
            start.elapsed().as_secs_f64(),
            example.as_deref().unwrap_or("")
        );
        if bad != (m.label == Label::Racy) {
            wrong.push(format!(
                "{} ({}): loom {}",
                m.name,
                m.label.name(),
                example.unwrap_or_else(|| "found no bug".into())
            ));
        }
    }
    assert!(
        wrong.is_empty(),
        "labels loom contradicts:\n{}",
        wrong.join("\n")
    );
}
