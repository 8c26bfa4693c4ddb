//! Campaigns split over machines: `fuzz --shard I/N` runs disjoint slices of the iterations,
//! `fuzz --merge` combines the slices' directories, and the merged campaign reports the
//! same findings as one run of the same iterations. `report --views` splits the same way
//! (`--shard`), and runs views in parallel (`--jobs`) with the same rows.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::atomic::{AtomicBool, AtomicU64};
use std::time::Duration;

use fragrace::fuzz::{self, CampaignState, FuzzConfig, Progress, Shard};
use fragrace_emu::ExecMode;

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("fragrace-shards-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn config(out: &Path, seed: u64, iterations: u64, shard: Shard) -> FuzzConfig {
    FuzzConfig {
        out: out.to_path_buf(),
        time: None,
        iterations: Some(iterations),
        algos: vec!["kb-rmw".into(), "ll".into()],
        jobs: 1,
        seed,
        resume: false,
        meshes: None,
        shrink_budget: Duration::from_millis(200),
        max_size: 16,
        scenes: vec!["coplanar-stack".into(), "cubes".into()],
        occupancy: None,
        shard,
        schedules: SCHEDULES,
    }
}

/// Schedules per scene: more than one, so that the merged campaign also checks that each
/// iteration's later schedules are a function of the campaign (`fuzz::execution_spec`).
const SCHEDULES: u64 = 2;

fn run(cfg: &FuzzConfig) -> CampaignState {
    let progress = Progress {
        executions: AtomicU64::new(0),
        cases: AtomicU64::new(0),
        violations: AtomicU64::new(0),
    };
    fuzz::campaign(cfg, &AtomicBool::new(false), &progress).unwrap()
}

/// A campaign seed whose first `n` iterations all run under the `scheduled` executor, whose
/// outcome is a function of the spec (the `parallel` one's is not: it would differ between
/// any two runs, merged or not).
fn deterministic_seed(n: u64) -> u64 {
    (0..1000)
        .find(|&seed| {
            let cfg = config(Path::new("unused"), seed, n, Shard::WHOLE);
            let algos = cfg.algos.clone();
            (0..n).all(|i| {
                matches!(
                    fuzz::iteration_spec(&cfg, &algos, &[], i).exec.mode,
                    ExecMode::Scheduled(_)
                )
            })
        })
        .expect("a seed of scheduled iterations among the first 1000")
}

#[test]
fn shards_are_disjoint_and_cover_every_iteration() {
    for count in [1, 2, 3, 7] {
        let shards: Vec<Shard> = (1..=count).map(|i| Shard::new(i, count).unwrap()).collect();
        for i in 0..100 {
            let owners = shards.iter().filter(|s| s.contains(i)).count();
            assert_eq!(owners, 1, "iteration {i} of {count} shards");
        }
        for s in &shards {
            for slot in 0..20 {
                assert!(s.contains(s.iteration(slot)), "{s} slot {slot}");
            }
        }
    }
    assert_eq!("2/4".parse::<Shard>().unwrap(), Shard::new(2, 4).unwrap());
    for bad in ["0/4", "5/4", "1/0", "x/4", "3", ""] {
        let e = bad.parse::<Shard>().unwrap_err().to_string();
        assert!(e.contains("--shard"), "{bad}: {e}");
    }
}

#[test]
fn merged_shards_report_the_findings_of_one_run() {
    let n = 12;
    let seed = deterministic_seed(n);
    let d = tmp("merge");
    let whole = run(&config(&d.join("whole"), seed, n, Shard::WHOLE));
    assert_eq!(whole.executions, n * SCHEDULES);
    assert!(
        whole.expected_findings > 0,
        "the campaign should find kb-rmw's race: {whole:?}"
    );
    let dirs: Vec<PathBuf> = (1..=3).map(|i| d.join(format!("shard{i}"))).collect();
    let mut per_shard = 0;
    for (i, dir) in dirs.iter().enumerate() {
        let st = run(&config(dir, seed, n, Shard::new(i as u64 + 1, 3).unwrap()));
        assert_eq!(st.executions, n / 3 * SCHEDULES, "shard {}", i + 1);
        per_shard += st.executions;
    }
    assert_eq!(per_shard, n * SCHEDULES);
    let merged = fuzz::merge(&dirs, &d.join("merged")).unwrap();
    assert_eq!(merged.executions, whole.executions);
    assert_eq!(merged.violations, whole.violations);
    assert_eq!(merged.expected_findings, whole.expected_findings);
    assert_eq!(merged.signatures, whole.signatures);
    assert_eq!(merged.coverage, whole.coverage);
    // One case per signature, the smallest of the shards', copied into the merged directory.
    assert_eq!(
        merged.case_of.keys().collect::<Vec<_>>(),
        whole.signatures.keys().collect::<Vec<_>>()
    );
    assert_eq!(merged.cases.len(), merged.signatures.len());
    for (sig, name) in &merged.case_of {
        let case = fragrace::case::read(&d.join("merged").join(name)).unwrap();
        let size = |c: &fragrace::case::Case| {
            c.shrunk_size
                .as_ref()
                .or(c.original_size.as_ref())
                .map(|s| s.triangles)
        };
        for dir in &dirs {
            let st: CampaignState =
                serde_json::from_slice(&std::fs::read(dir.join("campaign.json")).unwrap()).unwrap();
            if let Some(other) = st.case_of.get(sig) {
                let other = fragrace::case::read(&dir.join(other)).unwrap();
                assert!(
                    size(&case) <= size(&other),
                    "{sig}: a smaller case in {dir:?}"
                );
            }
        }
    }
    assert_eq!(merged.merged_shards.len(), 3);

    // Overlapping campaigns are refused: a shard twice, or into a directory with a campaign.
    let twice = [dirs[0].clone(), dirs[0].clone()];
    let e = fuzz::merge(&twice, &d.join("twice"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("both ran shard 1/3"), "{e}");
    let e = fuzz::merge(&dirs, &d.join("merged"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("already holds a campaign"), "{e}");
    let mixed = [d.join("whole"), dirs[1].clone()];
    let e = fuzz::merge(&mixed, &d.join("mixed"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("different counts"), "{e}");
}

fn fragrace(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fragrace"))
        .args(args)
        .output()
        .expect("runs")
}

#[test]
fn the_cli_runs_shards_and_merges_them() {
    let d = tmp("cli");
    let dir = |i: u64| d.join(format!("s{i}"));
    for i in 1..=2u64 {
        let o = fragrace(&[
            "fuzz",
            "--algo",
            "kb-rmw",
            "--iterations",
            "4",
            "--max-size",
            "16",
            "--shrink-secs",
            "0",
            "--schedules",
            "1",
            "--shard",
            &format!("{i}/2"),
            "--out",
            dir(i).to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(
            text.contains(&format!("shard {i}/2 of the campaign")),
            "{text}"
        );
        assert!(text.contains("2 executions"), "{text}");
    }
    let merged = d.join("merged");
    let o = fragrace(&[
        "fuzz",
        "--merge",
        dir(1).to_str().unwrap(),
        dir(2).to_str().unwrap(),
        "--out",
        merged.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("merged 2 of 2 shards"), "{text}");
    assert!(text.contains("4 executions"), "{text}");
    // A campaign's options mean nothing to a merge: refused, not ignored.
    let o = fragrace(&[
        "fuzz",
        "--merge",
        dir(1).to_str().unwrap(),
        "--jobs",
        "2",
        "--out",
        d.join("m2").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--jobs") && err.contains("--merge"), "{err}");
    // A bad shard names the value and its range.
    let o = fragrace(&["fuzz", "--iterations", "1", "--shard", "3/2"]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("--shard 3/2") && err.contains("INDEX from 1 to COUNT"),
        "{err}"
    );
}

/// The CSV rows of `report --views` (azimuth, then one EPR per algorithm).
fn report_rows(extra: &[&str]) -> Vec<String> {
    let mut args = vec![
        "report",
        "--views",
        "5",
        "--scenes",
        "cubes",
        "--size",
        "24",
        "--algo",
        "kb-rmw,ll",
        "--exec",
        "ordered",
    ];
    args.extend_from_slice(extra);
    let o = fragrace(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout).to_string();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("azimuth,kb-rmw,ll"), "{text}");
    lines.map(String::from).collect()
}

#[test]
fn report_views_in_parallel_and_in_shards_give_the_same_rows() {
    let whole = report_rows(&[]);
    assert_eq!(whole.len(), 5, "{whole:?}");
    assert_eq!(report_rows(&["--jobs", "2"]), whole);
    let mut sharded: Vec<String> = (1..=2)
        .flat_map(|i| report_rows(&["--shard", &format!("{i}/2")]))
        .collect();
    sharded.sort_by(|a, b| {
        let az = |s: &str| s.split(',').next().unwrap().parse::<f64>().unwrap();
        az(a).total_cmp(&az(b))
    });
    assert_eq!(sharded, whole);
    let o = fragrace(&["report", "--views", "3", "--jobs", "0"]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--jobs 0 is out of range"), "{err}");
}
