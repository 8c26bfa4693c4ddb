//! Inputs out of range are refused with their name and range, never clamped, replaced or
//! ignored; runs too large for the memory budget are refused before they allocate.

use std::path::PathBuf;
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use fragrace::case::{Case, Observation};
use fragrace::run::{self, RunSpec, SceneSpec};
use fragrace_emu::{ExecConfig, ExecMode, Policy};

fn fragrace(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fragrace"))
        .args(args)
        .output()
        .expect("runs")
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("fragrace-limits-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs the binary, which must fail with exit code 2 and every needle in its stderr, and
/// return within `secs` (refusals happen before any large allocation).
fn refused_within(args: &[&str], needles: &[&str], secs: u64) {
    let t = Instant::now();
    let o = fragrace(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(
        o.status.code(),
        Some(2),
        "{args:?} should be refused: {err}"
    );
    for n in needles {
        assert!(err.contains(n), "{args:?}: expected `{n}` in: {err}");
    }
    assert!(!err.contains("panicked"), "{err}");
    assert!(
        t.elapsed() < Duration::from_secs(secs),
        "{args:?} took {:?} to be refused",
        t.elapsed()
    );
}

fn refused(args: &[&str], needles: &[&str]) {
    refused_within(args, needles, 60);
}

const SMALL: [&str; 6] = ["--scene", "cubes", "--width", "16", "--height", "16"];

fn with_small<'a>(args: &[&'a str]) -> Vec<&'a str> {
    let mut v = args.to_vec();
    v.extend_from_slice(&SMALL);
    v
}

#[test]
fn values_out_of_range_are_refused_not_clamped() {
    refused(
        &with_small(&["render", "--k", "0"]),
        &["k (--k) = 0", "from 1 to 65536"],
    );
    refused(
        &with_small(&["check", "--exec", "scheduled", "--schedules", "0"]),
        &["--schedules 0", "at least 1"],
    );
    refused(
        &with_small(&["render", "--threads", "0"]),
        &["threads (--threads) = 0", "from 1 to", "cores"],
    );
    refused(
        &with_small(&["bench", "--threads", "100000", "--frames", "1"]),
        &["threads (--threads) = 100000", "from 1 to"],
    );
    refused(
        &with_small(&["bench", "--frames", "0"]),
        &["--frames 0 is out of range: it must be at least 1"],
    );
    refused(
        &with_small(&["render", "--lanes", "0"]),
        &["--lanes", "= 0", "from 1 to 65536"],
    );
    refused(
        &with_small(&["render", "--exec", "scheduled", "--window", "0"]),
        &["window (--window) = 0", "from 1 to"],
    );
    refused(
        &with_small(&["render", "--exec", "scheduled", "--block", "0"]),
        &["block (--block) = 0"],
    );
    refused(
        &with_small(&["render", "--spurious-cas", "1001"]),
        &["(--spurious-cas) = 1001", "from 0 to 1000"],
    );
    refused(
        &with_small(&["render", "--spin-cap", "0"]),
        &["spin_cap (--spin-cap) = 0"],
    );
    refused(
        &with_small(&["render", "--alpha", "2"]),
        &["alpha (--alpha) = 2", "from 0 to 1"],
    );
    // A known policy with a bad value is not an unknown policy.
    for (policy, needle) in [
        (
            "pct:0",
            "policy `pct:0`: depth `0` must be an integer from 1",
        ),
        (
            "warp:x",
            "policy `warp:x`: lanes `x` must be an integer from 1",
        ),
        (
            "bytes:zz",
            "policy `bytes:zz`: bytes:HEX takes an even number of hexadecimal",
        ),
        ("bytes:é1", "hexadecimal"),
    ] {
        let o = fragrace(&with_small(&[
            "render",
            "--exec",
            "scheduled",
            "--policy",
            policy,
        ]));
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{policy}: {err}");
        assert!(err.contains(needle), "{policy}: {err}");
        assert!(!err.contains("unknown policy"), "{policy}: {err}");
    }
    refused(
        &with_small(&["render", "--exec", "scheduled", "--policy", "nope"]),
        &["unknown policy `nope`"],
    );
    let out = tmp("fuzz-limits");
    let out = out.to_str().unwrap();
    refused(
        &["fuzz", "--iterations", "1", "--jobs", "0", "--out", out],
        &["jobs (--jobs) = 0", "from 1 to"],
    );
    refused(
        &[
            "fuzz",
            "--iterations",
            "1",
            "--jobs",
            "100000",
            "--out",
            out,
        ],
        &["jobs (--jobs) = 100000"],
    );
    refused(
        &["fuzz", "--iterations", "0", "--out", out],
        &["--iterations 0 is out of range: it must be at least 1"],
    );
    refused(
        &["fuzz", "--time", "0s", "--out", out],
        &["--time 0s: a campaign needs a positive time"],
    );
    refused(
        &["fuzz", "--iterations", "1", "--max-size", "4", "--out", out],
        &["max_size (--max-size) = 4", "from 8 to 16384"],
    );
    refused(
        &[
            "fuzz",
            "--iterations",
            "1",
            "--schedules",
            "0",
            "--out",
            out,
        ],
        &["schedules (--schedules) = 0", "from 1 to 1048576"],
    );
}

#[test]
fn options_the_executor_ignores_are_refused() {
    for (args, needle) in [
        (
            vec!["check", "--schedules", "4"],
            "--schedules has no effect under --exec parallel",
        ),
        (
            vec!["render", "--policy", "pct:0"],
            "--policy has no effect under --exec parallel",
        ),
        (
            vec!["render", "--policy", "bytes:zz"],
            "--policy has no effect under --exec parallel",
        ),
        (
            vec!["check", "--exec", "ordered", "--seed", "3"],
            "--seed has no effect under --exec ordered",
        ),
        (
            vec!["render", "--window", "8"],
            "--window has no effect under --exec parallel",
        ),
        (
            vec!["render", "--exec", "scheduled", "--lanes", "8"],
            "--lanes has no effect under --exec scheduled: it applies to --exec parallel only",
        ),
        (
            vec!["render", "--exec", "ordered", "--no-lockstep"],
            "--no-lockstep has no effect under --exec ordered",
        ),
        (
            vec!["report", "--policy", "fifo"],
            "--policy has no effect under --exec parallel",
        ),
    ] {
        let args = if args[0] == "report" {
            args
        } else {
            with_small(&args)
        };
        refused(&args, &[needle]);
    }
    // The same options where they apply run.
    let o = fragrace(&with_small(&[
        "check",
        "--exec",
        "scheduled",
        "--schedules",
        "2",
        "--policy",
        "pct:2",
        "--json",
    ]));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// A small case file, written by the library as `fuzz` writes them, then edited.
fn case_with(d: &std::path::Path, name: &str, edit: impl FnOnce(&mut serde_json::Value)) -> String {
    let mut spec = RunSpec::new(
        SceneSpec::Inline {
            positions: vec![
                [-0.5, -0.5, 0.0],
                [0.5, -0.5, 0.0],
                [0.0, 0.5, 0.0],
                [-0.5, 0.5, 0.1],
                [0.5, 0.5, 0.1],
                [0.0, -0.5, 0.1],
            ],
            indices: vec![[0, 1, 2], [3, 4, 5]],
            radius: Some(1.0),
        },
        "kb-rmw",
    );
    spec.width = 8;
    spec.height = 8;
    spec.exec = ExecConfig::scheduled(Policy::Random, 1);
    if let ExecMode::Scheduled(s) = &mut spec.exec.mode {
        s.window = 4;
    }
    spec.exec.threads = 1;
    let loaded = run::load(&spec).unwrap();
    let truth = run::truth(&spec, &loaded).unwrap();
    let checked = run::check_with(&spec, &loaded, &truth).unwrap();
    let case = Case {
        version: fragrace::case::VERSION,
        verdict: "test".into(),
        spec,
        observed: Observation::of(&checked),
        original_size: None,
        shrunk_size: None,
    };
    let mut v = serde_json::to_value(&case).unwrap();
    edit(&mut v);
    let p = d.join(name);
    std::fs::write(&p, serde_json::to_vec_pretty(&v).unwrap()).unwrap();
    p.to_str().unwrap().to_string()
}

#[test]
fn case_files_with_bad_fields_are_refused_by_name() {
    let d = tmp("cases");
    let good = case_with(&d, "good.json", |_| {});
    let o = fragrace(&["replay", &good]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for (name, needles, edit) in [
        (
            "window0",
            vec!["window (--window) = 0"],
            Box::new(|v: &mut serde_json::Value| {
                v["spec"]["exec"]["mode"]["Scheduled"]["window"] = 0.into()
            }) as Box<dyn FnOnce(&mut serde_json::Value)>,
        ),
        (
            "window-huge",
            vec!["window (--window) = 1000000000", "from 1 to 1048576"],
            Box::new(|v: &mut serde_json::Value| {
                v["spec"]["exec"]["mode"]["Scheduled"]["window"] = 1_000_000_000u64.into()
            }),
        ),
        (
            "pct0",
            vec!["pct depth (--policy pct:D) = 0"],
            Box::new(|v: &mut serde_json::Value| {
                v["spec"]["exec"]["mode"]["Scheduled"]["policy"] =
                    serde_json::json!({"Pct": {"depth": 0}})
            }),
        ),
        (
            "max-steps0",
            vec!["max_steps = 0"],
            Box::new(|v: &mut serde_json::Value| v["spec"]["exec"]["max_steps"] = 0.into()),
        ),
        (
            "radius0",
            vec!["scene radius = 0", "positive and finite"],
            Box::new(|v: &mut serde_json::Value| {
                v["spec"]["scene"]["inline"]["radius"] = 0.0.into()
            }),
        ),
        (
            "radius-neg",
            vec!["scene radius = -1"],
            Box::new(|v: &mut serde_json::Value| {
                v["spec"]["scene"]["inline"]["radius"] = (-1.0).into()
            }),
        ),
        (
            "fovy0",
            vec!["fovy 0 is not in (0, 180) degrees"],
            Box::new(|v: &mut serde_json::Value| v["spec"]["camera"]["fovy"] = 0.0.into()),
        ),
        (
            "fovy180",
            vec!["fovy 180 is not in (0, 180) degrees"],
            Box::new(|v: &mut serde_json::Value| v["spec"]["camera"]["fovy"] = 180.0.into()),
        ),
        (
            "k0",
            vec!["k (--k) = 0"],
            Box::new(|v: &mut serde_json::Value| v["spec"]["params"]["k"] = 0.into()),
        ),
        (
            "huge",
            vec!["this run needs an estimated", "more than the memory limit"],
            Box::new(|v: &mut serde_json::Value| {
                v["spec"]["width"] = 16384.into();
                v["spec"]["height"] = 16384.into();
            }),
        ),
    ] {
        let p = case_with(&d, &format!("{name}.json"), edit);
        let o = fragrace(&["replay", &p]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{name}: {err}");
        for n in needles {
            assert!(err.contains(n), "{name}: expected `{n}` in: {err}");
        }
        assert!(!err.contains("no longer holds"), "{name}: {err}");
    }
}

#[test]
fn runs_beyond_the_memory_budget_are_refused_before_they_allocate() {
    // Each of these used to abort on a failed allocation or be killed for want of memory.
    refused_within(
        &[
            "check",
            "--scene",
            "cubes",
            "--algo",
            "kb-rmw",
            "--exec",
            "scheduled",
            "--window",
            "1000000000",
            "--width",
            "32",
            "--height",
            "32",
        ],
        &["window (--window) = 1000000000", "from 1 to 1048576"],
        10,
    );
    refused_within(
        &[
            "check",
            "--scene",
            "cubes",
            "--algo",
            "kb-rmw",
            "--lanes",
            "1000000000",
            "--width",
            "32",
            "--height",
            "32",
        ],
        &["--lanes", "= 1000000000", "from 1 to 65536"],
        10,
    );
    refused_within(
        &[
            "render",
            "--scene",
            "cubes",
            "--algo",
            "kb-rmw",
            "--width",
            "16384",
            "--height",
            "16384",
            "--k",
            "8",
            "--memory-limit",
            "16G",
        ],
        &[
            "this run needs an estimated",
            "per-pixel storage (16384x16384 pixels, k 8)",
            "more than the memory limit of 16.0 GB (--memory-limit 16G)",
        ],
        10,
    );
    refused_within(
        &[
            "check", "--scene", "cubes", "--algo", "kb-rmw", "--width", "16384", "--height",
            "16384", "--k", "64",
        ],
        &[
            "this run needs an estimated",
            "the default, half of this machine's",
        ],
        10,
    );
    // Slots of the window and of the warps are in the estimate.
    refused_within(
        &[
            "render",
            "--scene",
            "cubes",
            "--algo",
            "kb-rmw",
            "--exec",
            "scheduled",
            "--window",
            "1000000",
            "--width",
            "32",
            "--height",
            "32",
            "--memory-limit",
            "1G",
        ],
        &["executor slots (window 1000000)", "--memory-limit 1G"],
        10,
    );
    refused_within(
        &[
            "render",
            "--scene",
            "cubes",
            "--algo",
            "kb-rmw",
            "--lanes",
            "65536",
            "--threads",
            "16",
            "--width",
            "32",
            "--height",
            "32",
            "--memory-limit",
            "1G",
        ],
        &["executor slots (--lanes 65536 x 16 threads)"],
        10,
    );
    // A fuzz campaign: its jobs run at once.
    let out = tmp("fuzz-budget");
    refused_within(
        &[
            "fuzz",
            "--iterations",
            "1",
            "--jobs",
            "32",
            "--max-size",
            "256",
            "--memory-limit",
            "8G",
            "--out",
            out.to_str().unwrap(),
        ],
        &[
            "this campaign needs an estimated",
            "32 jobs x",
            "--max-size 256",
            "use fewer --jobs or a smaller --max-size",
        ],
        10,
    );
    refused(
        &with_small(&["render", "--memory-limit", "lots"]),
        &["--memory-limit `lots`: expected a size"],
    );
    refused(
        &with_small(&["render", "--memory-limit", "0"]),
        &["--memory-limit `0`"],
    );
}

#[test]
fn replay_prints_a_command_that_exists() {
    let d = tmp("replay-cmd");
    let p = case_with(&d, "case.json", |_| {});
    let o = fragrace(&["replay", &p]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{text}");
    assert!(!text.contains("--case"), "{text}");
    assert!(
        text.contains(&format!("rerun with: cargo run --release -- replay {p}")),
        "{text}"
    );
}
