//! The peak memory of a run stays within 1.5x of the estimate it checks against the budget
//! before allocating (`memory_estimate_bytes`), and the estimate is not a blanket
//! overstatement either (at most 3x the peak). Each run is a child process, which reports
//! its own peak resident set (`peak_rss_bytes`, VmHWM).

use std::process::Command;

fn run(args: &[&str]) -> serde_json::Value {
    let o = Command::new(env!("CARGO_BIN_EXE_fragrace"))
        .args(args)
        .arg("--json")
        .output()
        .expect("runs");
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let text = String::from_utf8_lossy(&o.stdout);
    serde_json::from_str(text.lines().last().unwrap()).unwrap()
}

#[test]
fn peak_memory_stays_within_one_and_a_half_times_the_estimate() {
    if !std::path::Path::new("/proc/self/status").exists() {
        eprintln!("no /proc/self/status: the peak cannot be measured here");
        return;
    }
    let cases: &[&[&str]] = &[
        &[
            "render", "--scene", "cubes", "--algo", "kb-rmw", "--width", "384", "--height", "384",
            "--k", "16",
        ],
        &[
            "check", "--scene", "bunny", "--algo", "ll", "--width", "256", "--height", "256",
        ],
        &[
            "render", "--scene", "hairball", "--algo", "fab", "--width", "128", "--height", "128",
        ],
        &[
            "check", "--scene", "spheres", "--algo", "f2b", "--exec", "ordered", "--width", "192",
            "--height", "192",
        ],
        &[
            "render",
            "--scene",
            "teapot",
            "--algo",
            "kb-atomic32",
            "--exec",
            "scheduled",
            "--width",
            "96",
            "--height",
            "96",
        ],
        &[
            "check",
            "--scene",
            "cubes",
            "--algo",
            "kb-rmw",
            "--exec",
            "scheduled",
            "--schedules",
            "3",
            "--width",
            "128",
            "--height",
            "128",
        ],
        &[
            "check",
            "--scene",
            "hairball",
            "--algo",
            "sb",
            "--exec",
            "scheduled",
            "--width",
            "48",
            "--height",
            "48",
        ],
    ];
    let mut failures = Vec::new();
    for args in cases {
        let v = run(args);
        let est = v["memory_estimate_bytes"].as_f64().expect("an estimate");
        let peak = v["peak_rss_bytes"].as_f64().expect("a measured peak");
        let ratio = peak / est;
        eprintln!(
            "{args:?}: peak {:.1} MB, estimate {:.1} MB, peak/estimate {ratio:.2}",
            peak / 1e6,
            est / 1e6
        );
        if !(1.0 / 3.0..=1.5).contains(&ratio) {
            failures.push(format!("{args:?}: peak/estimate {ratio:.2}"));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
