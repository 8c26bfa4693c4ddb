//! What a newcomer reads: printed commands that run as printed, plain words about what
//! cannot be reproduced, the README's example models, outputs checked before the work.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

fn fragrace(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fragrace"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("runs")
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("fragrace-output-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn ok(o: &Output) -> String {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

#[test]
fn parallel_checks_say_they_are_not_reproducible_and_print_a_scheduled_command() {
    let args = [
        "check", "--scene", "cubes", "--algo", "kb-rmw", "--width", "32", "--height", "32",
    ];
    let text = ok(&fragrace(&args));
    assert!(
        text.contains("parallel runs are not reproducible"),
        "{text}"
    );
    let cmd = text
        .lines()
        .find(|l| l.trim_start().starts_with("cargo run --release -- check"))
        .unwrap_or_else(|| panic!("no command in {text}"))
        .trim();
    assert!(
        cmd.contains("--exec scheduled --policy random --seed 0"),
        "{cmd}"
    );
    // The printed command runs as printed (less the cargo prefix), twice to the same bits.
    let run = |cmd: &str| {
        let mut a: Vec<&str> = cmd
            .trim_start_matches("cargo run --release -- ")
            .split(' ')
            .collect();
        a.push("--json");
        let out = ok(&fragrace(&a));
        let v: serde_json::Value = serde_json::from_str(out.lines().last().unwrap()).unwrap();
        (
            v["epr_max"].clone(),
            v["hazards_total"].clone(),
            v["reproducible"].clone(),
        )
    };
    let first = run(cmd);
    assert_eq!(first.2, true);
    assert_eq!(first, run(cmd));
    let mut a = args.to_vec();
    a.push("--json");
    let out = ok(&fragrace(&a));
    let v: serde_json::Value = serde_json::from_str(out.lines().last().unwrap()).unwrap();
    assert_eq!(v["reproducible"], false, "{v}");
    assert!(
        v["reproduce_with"]
            .as_str()
            .unwrap()
            .contains("--exec scheduled"),
        "{v}"
    );
}

#[test]
fn the_readme_models_are_in_the_repository() {
    let d = tmp("models");
    let raw = d.join("counts.u32");
    let out = ok(&fragrace(&[
        "render",
        "--obj",
        "assets/bunny.obj.gz",
        "--algo",
        "count",
        "--raw-out",
        raw.to_str().unwrap(),
        "--json",
        "--width",
        "64",
        "--height",
        "64",
    ]));
    assert!(out.contains("\"triangles\":3674"), "{out}");
    ok(&fragrace(&[
        "bench",
        "--obj",
        "assets/dragon_res4.obj.gz",
        "--algo",
        "count",
        "--threads",
        "2",
        "--frames",
        "1",
        "--warmup",
        "0",
        "--width",
        "64",
        "--height",
        "64",
    ]));
    let readme =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md")).unwrap();
    for word in readme.split_whitespace().filter(|w| w.ends_with(".obj.gz")) {
        let p = word.trim_matches(|c: char| c == '`' || c == ',' || c == ')' || c == '(');
        if p.starts_with("assets/") {
            assert!(
                Path::new(env!("CARGO_MANIFEST_DIR")).join(p).exists(),
                "README names {p}, which is not in the repository"
            );
        }
    }
}

#[test]
fn output_paths_are_checked_before_the_work_and_named() {
    // A run of several seconds: refused at once.
    let t = Instant::now();
    let o = fragrace(&[
        "check",
        "--scene",
        "hairball",
        "--algo",
        "kb-rmw",
        "--exec",
        "scheduled",
        "--schedules",
        "8",
        "--width",
        "128",
        "--height",
        "128",
        "--out",
        "/nonexistent-dir/img.png",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("/nonexistent-dir/img.png: cannot write the image (--out)"),
        "{err}"
    );
    assert!(
        t.elapsed() < Duration::from_secs(5),
        "refused after {:?}",
        t.elapsed()
    );
    let d = tmp("outs");
    let file = d.join("a-file");
    std::fs::write(&file, b"x").unwrap();
    let o = fragrace(&[
        "render",
        "--scene",
        "cubes",
        "--algo",
        "count",
        "--width",
        "16",
        "--height",
        "16",
        "--heatmap",
        file.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("a-file: cannot write heatmaps (--heatmap)"),
        "{err}"
    );
    let o = fragrace(&[
        "render",
        "--scene",
        "cubes",
        "--algo",
        "ll",
        "--width",
        "16",
        "--height",
        "16",
        "--raw-out",
        d.join("x.u32").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("--raw-out needs a counting algorithm"),
        "{err}"
    );
}

#[test]
fn heatmaps_are_listed_and_an_empty_heatmap_directory_is_explained() {
    let d = tmp("heat");
    let o = fragrace(&[
        "render",
        "--scene",
        "cubes",
        "--algo",
        "kb-rmw",
        "--width",
        "16",
        "--height",
        "16",
        "--heatmap",
        d.to_str().unwrap(),
    ]);
    let text = ok(&o);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("no heatmap written"), "{text}{err}");
    assert_eq!(std::fs::read_dir(&d).unwrap().count(), 0);
    let text = ok(&fragrace(&[
        "check",
        "--scene",
        "cubes",
        "--algo",
        "count",
        "--width",
        "16",
        "--height",
        "16",
        "--heatmap",
        d.to_str().unwrap(),
    ]));
    for f in ["depth-complexity.png", "errors.png"] {
        assert!(
            text.contains(&format!("wrote {}", d.join(f).display())),
            "{text}"
        );
        assert!(d.join(f).exists());
    }
}

#[test]
fn checks_give_a_verdict_in_words_first_and_explain_their_metrics() {
    let small = ["--width", "48", "--height", "48"];
    for (args, kind, first) in [
        (
            vec!["--scene", "cubes", "--algo", "ll"],
            "exact",
            "exact: ll matches the truth",
        ),
        (
            vec![
                "--scene",
                "cubes",
                "--algo",
                "kb-rmw",
                "--exec",
                "scheduled",
            ],
            "hazard-found",
            "hazard found: kb-rmw is hazard-prone",
        ),
        (
            vec!["--scene", "coplanar-stack", "--algo", "f2b", "--k", "16"],
            "within-promise",
            "errors within what f2b promises: it drops, and counts, fragments it cannot keep",
        ),
    ] {
        let mut a = vec!["check"];
        a.extend(&args);
        a.extend(small);
        let text = ok(&fragrace(&a));
        assert!(text.lines().next().unwrap().starts_with(first), "{text}");
        for line in [
            "error pixel rate, covered pixels whose result differs from the truth",
            "robustness, fragments kept over fragments the algorithm should keep",
            "coplanarity, covered pixels with two fragments at exactly the same depth",
        ] {
            assert!(text.contains(line), "{text}");
        }
        a.push("--json");
        let out = ok(&fragrace(&a));
        let v: serde_json::Value = serde_json::from_str(out.lines().last().unwrap()).unwrap();
        assert_eq!(v["verdict"]["kind"], kind, "{v}");
    }
}

#[test]
fn piped_output_has_no_progress_bar() {
    // The bar is drawn on a terminal only: piped, stdout is the report and stderr is empty.
    for args in [
        vec![
            "check",
            "--scene",
            "cubes",
            "--algo",
            "kb-rmw",
            "--exec",
            "scheduled",
            "--schedules",
            "2",
            "--width",
            "32",
            "--height",
            "32",
        ],
        vec![
            "render", "--scene", "cubes", "--algo", "ll", "--width", "32", "--height", "32",
        ],
        vec![
            "report", "--scenes", "cubes", "--algo", "ll", "--size", "32",
        ],
        vec![
            "bench", "--scene", "cubes", "--algo", "ll", "--width", "32", "--height", "32",
            "--frames", "3",
        ],
    ] {
        let o = fragrace(&args);
        ok(&o);
        assert!(
            o.stderr.is_empty(),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
}

#[test]
fn fuzz_findings_are_deduplicated_by_signature_with_one_case_each() {
    let d = tmp("fuzz-dedup");
    let out = d.join("cases");
    let o = fragrace(&[
        "fuzz",
        "--iterations",
        "150",
        "--algo",
        "kb-rmw",
        "--shrink-secs",
        "1",
        "--seed",
        "7",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    let text = ok(&o);
    let v: serde_json::Value = serde_json::from_str(text.lines().last().unwrap()).unwrap();
    let sigs = v["signatures"].as_object().unwrap();
    let runs: u64 = sigs.values().map(|n| n.as_u64().unwrap()).sum();
    assert_eq!(
        runs,
        v["expected_findings"].as_u64().unwrap() + v["violations"].as_u64().unwrap()
    );
    // Many runs, whatever their policies, come down to a few signatures: the principal
    // hazard and its buffer (or, without hazards, the kind of anomaly). kb-rmw has two
    // buffers (kb-depth, kb-prim) and three hazard classes (lost update, race, torn), plus
    // error pixels without a hazard: at most 7, for hundreds of runs.
    assert!(runs >= 100, "{v}");
    assert!(sigs.len() <= 7, "{:#?}", sigs.keys().collect::<Vec<_>>());
    for sig in sigs.keys() {
        assert!(sig.starts_with("kb-rmw (hazard-prone): "), "{sig}");
        let case = v["case_of"][sig]
            .as_str()
            .unwrap_or_else(|| panic!("no case for {sig}"));
        assert!(out.join(case).exists(), "{case}");
    }
    assert_eq!(v["cases"].as_array().unwrap().len(), sigs.len());
}

#[test]
fn bench_shows_its_frames_on_a_terminal() {
    // `script` (util-linux) gives the command a terminal; the bar counts the frames there.
    let cmd = format!(
        "{} bench --scene cubes --algo ll --width 32 --height 32 --frames 4 --warmup 1",
        env!("CARGO_BIN_EXE_fragrace")
    );
    let o = std::process::Command::new("script")
        .args(["-qec", &cmd, "/dev/null"])
        .output()
        .expect("`script` (util-linux) runs: it gives the command a terminal");
    ok(&o);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("/5 "), "no bar of 5 frames: {text:?}");
    assert!(text.contains("median"), "{text:?}");
}
