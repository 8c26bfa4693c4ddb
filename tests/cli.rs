//! The command line as a user meets it: JSON output, bad input, case files, and a fuzz
//! campaign killed with SIGKILL and resumed.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn fragrace(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fragrace"))
        .args(args)
        .output()
        .expect("runs")
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("fragrace-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn json(o: &Output) -> serde_json::Value {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    serde_json::from_str(text.lines().last().unwrap()).unwrap()
}

#[test]
fn render_json_has_the_documented_fields() {
    let d = tmp("render");
    let raw = d.join("counts.u32");
    let o = fragrace(&[
        "render",
        "--scene",
        "bunny",
        "--algo",
        "count",
        "--width",
        "96",
        "--height",
        "80",
        "--json",
        "--raw-out",
        raw.to_str().unwrap(),
        "--threads",
        "2",
    ]);
    let v = json(&o);
    for key in [
        "algo",
        "scene",
        "triangles",
        "width",
        "height",
        "exec",
        "policy",
        "seed",
        "threads",
        "fragments",
        "covered_pixels",
        "max_depth_complexity",
        "hazards",
        "epr",
        "wall_ms",
    ] {
        assert!(v.get(key).is_some(), "missing {key}: {v}");
    }
    assert_eq!(v["triangles"], 3674);
    let bytes = std::fs::read(&raw).unwrap();
    assert_eq!(bytes.len(), 96 * 80 * 4);
    let sum: u64 = bytes
        .chunks(4)
        .map(|c| u32::from_le_bytes(c.try_into().unwrap()) as u64)
        .sum();
    assert_eq!(sum, v["fragments"].as_u64().unwrap());
}

#[test]
fn check_reports_epr_and_a_replay_command() {
    let o = fragrace(&[
        "check",
        "--scene",
        "coplanar-stack",
        "--algo",
        "kb-rmw",
        "--exec",
        "scheduled",
        "--schedules",
        "4",
        "--width",
        "24",
        "--height",
        "24",
        "--json",
    ]);
    let v = json(&o);
    assert!(
        v["hazards_total"]["lost_updates"].as_u64().unwrap() > 0,
        "{v}"
    );
    assert!(v["replay"]
        .as_str()
        .unwrap()
        .contains("--policy random --seed"));
    let o = fragrace(&[
        "check",
        "--scene",
        "cubes",
        "--algo",
        "kb-atomic64",
        "--width",
        "32",
        "--height",
        "32",
        "--json",
    ]);
    let v = json(&o);
    assert_eq!(v["epr"], 0.0);
}

#[test]
fn check_under_lockstep_forward_progress_reports_the_spinlock_deadlock() {
    let args = |simt: &str, algo: &str| {
        let mut v: Vec<String> = vec![
            "check".to_string(),
            "--scene".into(),
            "coplanar-stack".into(),
            "--algo".into(),
            algo.into(),
            "--exec".into(),
            "scheduled".into(),
            "--simt".into(),
            simt.into(),
            "--width".into(),
            "16".into(),
            "--height".into(),
            "16".into(),
        ];
        // The spin lock without a cap (only kb-spinlock has one: others refuse the option).
        if algo == "kb-spinlock" {
            v.extend(["--spin-cap".into(), "4294967295".into()]);
        }
        v
    };
    let run = |a: Vec<String>| fragrace(&a.iter().map(|s| s.as_str()).collect::<Vec<_>>());
    let mut a = args("32", "kb-spinlock");
    a.push("--json".into());
    let v = json(&run(a));
    assert!(v["faults"].as_u64().unwrap() > 0, "{v}");
    let f = &v["faults_list"][0]["kind"]["SimtDeadlock"];
    assert!(f["warp"].is_u64(), "{v}");
    assert!(!f["spinning"].as_array().unwrap().is_empty(), "{f}");
    assert!(!f["held"].as_array().unwrap().is_empty(), "{f}");
    let replay = v["replay"].as_str().unwrap();
    assert!(
        replay.contains("--simt 32") && replay.contains("--spin-cap 4294967295"),
        "{replay}"
    );
    // In text, the fault says what happened.
    let o = run(args("32", "kb-spinlock"));
    assert!(o.status.success());
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("SIMT deadlock in warp"), "{text}");
    // Independent scheduling: the holder releases, nothing faults.
    let mut a = args("0", "kb-spinlock");
    a.push("--json".into());
    assert_eq!(json(&run(a))["faults"], 0);
    // A lock-free algorithm is unaffected.
    let mut a = args("32", "kb-atomic64");
    a.push("--json".into());
    let v = json(&run(a));
    assert_eq!(
        (v["faults"].as_u64(), v["epr"].as_f64()),
        (Some(0), Some(0.0))
    );
}

/// `bench --floor` reports the floor of `count` beside the frame, and refuses other
/// algorithms up front.
#[test]
fn bench_floor_reports_the_frame_and_its_floor() {
    let v = json(&fragrace(&[
        "bench",
        "--scene",
        "cubes",
        "--algo",
        "count",
        "--width",
        "64",
        "--height",
        "48",
        "--frames",
        "2",
        "--warmup",
        "0",
        "--threads",
        "2",
        "--floor",
        "--json",
    ]));
    for key in ["median_ms", "floor_atomics_ms", "floor_frame_ms"] {
        let ms = v[key].as_f64().unwrap_or_else(|| panic!("{key} in {v}"));
        assert!(ms.is_finite() && ms >= 0.0, "{key}: {ms}");
    }
    assert!(v["fragments"].as_u64().unwrap() > 0, "{v}");
    fails_with(
        &["bench", "--scene", "cubes", "--algo", "opaque", "--floor"],
        "--floor measures the floor of `count`",
    );
}

fn fails_with(args: &[&str], needle: &str) {
    let o = fragrace(args);
    assert!(!o.status.success(), "{args:?} should fail");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains(needle),
        "{args:?}: expected `{needle}` in: {err}"
    );
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn bad_input_gets_a_clear_error() {
    let d = tmp("bad");
    let obj = |name: &str, text: &[u8]| {
        let p = d.join(name);
        std::fs::write(&p, text).unwrap();
        p.to_str().unwrap().to_string()
    };
    fails_with(
        &[
            "render",
            "--obj",
            &obj("trunc.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"),
        ],
        "out of range",
    );
    fails_with(
        &[
            "render",
            "--obj",
            &obj("nan.obj", b"v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
        ],
        "non-finite",
    );
    fails_with(
        &[
            "render",
            "--obj",
            &obj("inf.obj", b"v inf 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
        ],
        "non-finite",
    );
    fails_with(
        &[
            "render",
            "--obj",
            &obj("garbage.obj", b"\x00\xff\xfe garbage"),
        ],
        "",
    );
    fails_with(
        &["render", "--obj", &obj("bad.obj.gz", b"not gzip at all")],
        "gzip",
    );
    fails_with(
        &["render", "--obj", &obj("empty.obj", b"# nothing\n")],
        "no triangles",
    );
    fails_with(&["render", "--obj", "/nonexistent/model.obj"], "not found");
    fails_with(&["render", "--scene", "cubes", "--width", "0"], "viewport");
    fails_with(
        &[
            "render", "--scene", "cubes", "--width", "100000", "--height", "100000",
        ],
        "viewport",
    );
    fails_with(&["render", "--scene", "nope"], "unknown built-in scene");
    fails_with(&["render", "--algo", "nope"], "unknown algorithm");
    fails_with(
        &["render", "--exec", "scheduled", "--policy", "pct:0"],
        "policy `pct:0`: depth `0` must be an integer from 1",
    );
    fails_with(
        &["replay", &obj("case.json", b"{\"version\": 1}")],
        "not a fragrace case file",
    );
    // A missing file: its path and the cause, said once.
    let missing = d.join("no-such-case.json");
    let o = fragrace(&["replay", missing.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("no-such-case.json: "), "{err}");
    assert_eq!(err.matches("(os error 2)").count(), 1, "{err}");
}

#[test]
fn fuzz_finds_the_rmw_hazard_and_replay_reproduces_it() {
    let d = tmp("fuzz");
    let out = d.join("cases");
    let o = fragrace(&[
        "fuzz",
        "--algo",
        "kb-rmw",
        "--iterations",
        "12",
        "--out",
        out.to_str().unwrap(),
        "--shrink-secs",
        "3",
        "--json",
    ]);
    let state = json(&o);
    assert!(state["expected_findings"].as_u64().unwrap() > 0, "{state}");
    let cases = state["cases"].as_array().unwrap();
    assert!(!cases.is_empty());
    let case = out.join(cases[0].as_str().unwrap());
    let o = fragrace(&["replay", case.to_str().unwrap(), "--json"]);
    let v = json(&o);
    assert_eq!(v["exact"], true, "{v}");
}

fn wait_for(mut cond: impl FnMut() -> bool, secs: u64) -> bool {
    let t = std::time::Instant::now();
    while t.elapsed().as_secs() < secs {
        if cond() {
            return true;
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    false
}

fn case_files(dir: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(dir)
        .map(|r| {
            r.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    p.extension().is_some_and(|e| e == "json") && !p.ends_with("campaign.json")
                })
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn a_killed_campaign_loses_nothing_and_resumes() {
    let d = tmp("kill");
    let out = d.join("cases");
    let mut child = Command::new(env!("CARGO_BIN_EXE_fragrace"))
        .args([
            "fuzz",
            "--algo",
            "kb-rmw,count-plain",
            "--iterations",
            "100000",
            "--shrink-secs",
            "1",
            "--out",
        ])
        .arg(&out)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    assert!(
        wait_for(|| case_files(&out).len() >= 2, 120),
        "no case within 120 s"
    );
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    let before = case_files(&out);
    for c in &before {
        let bytes = std::fs::read(c).unwrap();
        fragrace::case::parse(&bytes, &c.display().to_string())
            .expect("every case is complete JSON");
    }
    let state: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("campaign.json")).unwrap())
            .expect("state is complete JSON");
    let done = state["next_iteration"].as_u64().unwrap();
    let o = fragrace(&[
        "fuzz",
        "--resume",
        "--iterations",
        "5",
        "--shrink-secs",
        "1",
        "--json",
        "--out",
        out.to_str().unwrap(),
    ]);
    let after = json(&o);
    assert!(
        after["next_iteration"].as_u64().unwrap() >= done + 5,
        "{after}"
    );
    for c in &before {
        assert!(c.exists(), "{} vanished", c.display());
    }
}

/// `--binning always` (every pass binned into tiles) and the default (counting passes
/// unbinned) give the same per-pixel counts; a bad value is refused with a clear message.
#[test]
fn binning_flag_changes_no_count() {
    let d = tmp("binning");
    let mut outs = Vec::new();
    for binning in ["auto", "always"] {
        let raw = d.join(format!("{binning}.u32"));
        let o = fragrace(&[
            "render",
            "--scene",
            "hairball",
            "--algo",
            "count",
            "--width",
            "64",
            "--height",
            "64",
            "--exec",
            "parallel",
            "--threads",
            "2",
            "--binning",
            binning,
            "--raw-out",
            raw.to_str().unwrap(),
            "--json",
        ]);
        let v = json(&o);
        outs.push((v["fragments"].clone(), std::fs::read(&raw).unwrap()));
    }
    assert!(outs[0].0.as_u64().unwrap() > 1000);
    assert_eq!(outs[0], outs[1]);
    let o = fragrace(&[
        "render",
        "--scene",
        "cubes",
        "--algo",
        "count",
        "--binning",
        "sometimes",
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("expected `auto` or `always`"));
}
