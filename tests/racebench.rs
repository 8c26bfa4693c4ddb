//! The race benchmark at a small schedule count: the detector's labels hold (every racy
//! kernel found by its best scheduled policy, on a labelled word; no report on any
//! race-free kernel, the plain section under a lock built from atomics included), except
//! exactly where a limitation is declared, and the declared limitations are real (the
//! detector misses the atomics-only races, which the oracle finds).

use std::process::Command;

use fragrace::racebench::{self, BenchConfig, BenchPolicy, BenchResult};
use fragrace_kernels::racebench::{Label, Limitation};

fn bench(schedules: u64) -> BenchResult {
    racebench::run(&BenchConfig {
        schedules,
        policies: BenchPolicy::defaults(),
        kernels: Vec::new(),
        threads: 2,
        stop_at_first: true,
    })
    .expect("a valid configuration")
}

#[test]
fn labels_hold_and_limitations_are_what_they_say() {
    let r = bench(40);
    let scheduled = |c: &&&racebench::Cell| c.policy != "parallel";
    for m in &r.kernels {
        let cells: Vec<&racebench::Cell> = r.cells.iter().filter(|c| c.kernel == m.name).collect();
        assert_eq!(cells.len(), 6, "{}", m.name);
        for c in &cells {
            assert!(
                c.faults.is_empty(),
                "{} under {}: {:?}",
                m.name,
                c.policy,
                c.faults
            );
        }
        let found = cells.iter().filter(scheduled).any(|c| c.found);
        let alarms: Vec<&String> = cells.iter().flat_map(|c| &c.false_alarms).collect();
        let oracle = cells
            .iter()
            .any(|c| c.oracle_violations > 0 || (c.found && c.policy == "parallel"));
        match (m.label, m.limitation) {
            (Label::Racy, None) => {
                assert!(found, "{}: no scheduled policy found it", m.name);
                assert!(alarms.is_empty(), "{}: false alarms {alarms:?}", m.name);
            }
            (Label::Racy, Some(Limitation::AtomicsOnly)) => {
                assert!(
                    !found,
                    "{}: declared atomics-only, yet the detector saw it",
                    m.name
                );
                assert!(
                    oracle,
                    "{}: the oracle never saw the atomics-only race",
                    m.name
                );
            }
            (Label::RaceFree, None) => {
                assert!(alarms.is_empty(), "{}: false alarms {alarms:?}", m.name);
                assert_eq!(
                    cells.iter().map(|c| c.oracle_violations).sum::<u64>(),
                    0,
                    "{}",
                    m.name
                );
            }
            (l, lim) => panic!("{}: limitation {lim:?} does not fit label {l:?}", m.name),
        }
    }
    assert_eq!(r.best_policy_recall_without_limitations, 1.0);
    assert_eq!(r.overall_precision_without_limitations, 1.0);
    // No kernel declares a false alarm any more: precision holds over all of them.
    assert_eq!(r.overall_precision, 1.0);
    assert!(
        r.best_policy_recall < 1.0,
        "the atomics-only races count in the totals"
    );
}

#[test]
fn bad_settings_are_refused_with_their_range() {
    let bin = env!("CARGO_BIN_EXE_fragrace");
    for (args, says) in [
        (&["racebench", "--schedules", "0"][..], "--schedules 0"),
        (
            &["racebench", "--kernels", "nope"][..],
            "unknown kernel `nope`",
        ),
        (&["racebench", "--policies", "pct:0"][..], "pct:0"),
        (&["racebench", "--threads", "0"][..], "--threads 0"),
    ] {
        let out = Command::new(bin)
            .args(args)
            .output()
            .expect("the binary runs");
        assert!(!out.status.success(), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(says), "{args:?}: {err}");
    }
}

#[test]
fn json_names_every_cell() {
    let bin = env!("CARGO_BIN_EXE_fragrace");
    let out = Command::new(bin)
        .args([
            "racebench",
            "--schedules",
            "2",
            "--kernels",
            "counter-plain,counter-atomic",
            "--policies",
            "random,parallel",
            "--json",
        ])
        .output()
        .expect("the binary runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    assert_eq!(v["cells"].as_array().map(|a| a.len()), Some(4));
    assert_eq!(v["totals"][0]["recall"], 1.0);
}
