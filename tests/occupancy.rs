//! Occupancy-map culling ("Improving k-buffer methods via occupancy maps"): the culled
//! variants on built-in scenes, the racy plain fill, the range choices, the acceptance
//! figure on hairball, and bad parameters. Exactness of every culled variant under every
//! executor and policy is the differential sweep's (`tests/differential.rs`).

use std::process::{Command, Output};

use fragrace::run::{self, Checked, RunSpec, SceneSpec};
use fragrace_emu::{ExecConfig, ExecMode, Policy, ScheduleConfig};
use fragrace_kernels::occupancy::{FillMode, Occupancy, RangeSource};

fn spec(scene: &str, algo: &str, size: u32, occupancy: Option<Occupancy>) -> RunSpec {
    let mut s = RunSpec::new(SceneSpec::Builtin(scene.into()), algo);
    s.width = size;
    s.height = size;
    s.params.occupancy = occupancy;
    s
}

fn occ(d: u32, range: RangeSource, fill: FillMode) -> Option<Occupancy> {
    Some(Occupancy { d, range, fill })
}

fn check(s: &RunSpec) -> Checked {
    let loaded = run::load(s).unwrap();
    let truth = run::truth(s, &loaded).unwrap();
    run::check_with(s, &loaded, &truth).unwrap()
}

fn scheduled(policy: Policy, seed: u64) -> ExecConfig {
    ExecConfig {
        mode: ExecMode::Scheduled(ScheduleConfig {
            policy,
            seed,
            window: 32,
            record: false,
            ..Default::default()
        }),
        ..ExecConfig::default()
    }
}

fn assert_exact_and_lemma(c: &Checked, what: &str) {
    assert_eq!(c.metrics.error_pixels, 0, "{what}: EPR {}", c.metrics.epr);
    assert_eq!(c.metrics.lemma_2_1_violations, Some(0), "{what}");
    assert!(
        c.failed_checks().is_empty(),
        "{what}: {:?}",
        c.failed_checks()
    );
}

/// The acceptance figure: on hairball at 512x512 (d = 32, k = 8, exact range), culled
/// kplus shades at most 30 % of the k-buffer invocations plain kplus shades (the ideal,
/// min(k, n) per pixel, is 20.7 %), and stays exact.
#[test]
fn culled_kplus_shades_at_most_30_percent_of_the_invocations_on_hairball() {
    let mut s = spec(
        "hairball",
        "kplus",
        512,
        occ(32, RangeSource::Exact, FillMode::Atomic),
    );
    s.exec = ExecConfig::parallel(2);
    let loaded = run::load(&s).unwrap();
    let truth = run::truth(&s, &loaded).unwrap();
    let c = run::check_with(&s, &loaded, &truth).unwrap();
    assert_exact_and_lemma(&c, "kplus culled on hairball");
    let base = fragrace::culling::baseline(&s, &loaded).unwrap().unwrap();
    let v = fragrace::culling::summary(&c.rendered, Some(&c.metrics), Some(&base));
    let ratio = v["saved"]["invocation_ratio"].as_f64().unwrap();
    assert!(
        ratio <= 0.30,
        "culled kplus shades {:.1} % of plain kplus's invocations",
        100.0 * ratio
    );
    // No culling scheme can keep fewer than min(k, n) per pixel.
    let ideal: u64 = truth
        .capture
        .as_ref()
        .map(|t| {
            (0..t.pixels())
                .map(|p| t.pixel(p).len().min(8) as u64)
                .sum()
        })
        .unwrap();
    let shaded = v["with"]["kbuffer_invocations"].as_u64().unwrap();
    assert!(
        shaded >= ideal,
        "{shaded} invocations, fewer than the {ideal} kept"
    );
    assert!(v["saved"]["memory_ops"].as_i64().unwrap() > 0);
    assert!(v["saved"]["atomics"].as_i64().unwrap() > 0);
}

#[test]
fn every_range_choice_culls_and_keeps_the_k_nearest() {
    let mut culled = Vec::new();
    for range in [RangeSource::Exact, RangeSource::Bbox, RangeSource::Hull] {
        for algo in ["kplus", "kb-atomic64"] {
            // The bunny has a few layers per pixel: k = 2 leaves some to cull.
            let mut s = spec("bunny", algo, 96, occ(2, range, FillMode::Atomic));
            s.params.k = 2;
            let c = check(&s);
            assert_exact_and_lemma(&c, &format!("{algo} with range {}", range.name()));
            let cull = c.rendered.result.culling.as_ref().unwrap();
            assert!(
                cull.culled_fragments > 0,
                "{algo}/{}: nothing culled",
                range.name()
            );
            culled.push((range, cull.culled_fragments));
        }
    }
    // The exact range is the tightest, so it culls most: the bounding volumes contain it.
    let of = |r| {
        culled
            .iter()
            .filter(|c| c.0 == r)
            .map(|c| c.1)
            .max()
            .unwrap()
    };
    assert!(of(RangeSource::Exact) >= of(RangeSource::Hull));
    assert!(of(RangeSource::Exact) >= of(RangeSource::Bbox));
}

#[test]
fn culled_variants_are_exact_under_scheduled_policies_on_hairball() {
    for algo in ["kplus", "kplus-heap", "kb-atomic32", "kb-interlock"] {
        for (i, policy) in [Policy::Random, Policy::Pct { depth: 3 }, Policy::FarFirst]
            .into_iter()
            .enumerate()
        {
            let mut s = spec(
                "hairball",
                algo,
                32,
                occ(1, RangeSource::Hull, FillMode::Atomic),
            );
            s.exec = scheduled(policy, i as u64);
            let c = check(&s);
            assert_exact_and_lemma(&c, &s.command("check"));
            assert_eq!(c.stage_hazards().total(), 0, "the atomic fill races");
        }
    }
}

/// The plain fill loses bits under a scheduled policy (the detector reports them on the
/// map's words), and a lost bit only moves the bound farther: Lemma 2.1 holds, the culled
/// k-buffer stays exact, and it culls no more than with the atomic fill.
#[test]
fn the_plain_fill_loses_bits_but_never_breaks_lemma_2_1() {
    let mut lost = 0;
    for seed in 0..3 {
        let run = |fill| {
            let mut s = spec("hairball", "kplus", 48, occ(32, RangeSource::Exact, fill));
            s.exec = scheduled(Policy::Random, seed);
            check(&s)
        };
        let (plain, atomic) = (run(FillMode::Plain), run(FillMode::Atomic));
        assert_exact_and_lemma(&plain, "plain fill");
        let hz = plain.stage_hazards();
        lost += hz.lost_updates;
        assert_eq!(
            plain.algorithm_hazards().total(),
            0,
            "kplus itself does not race"
        );
        assert!(plain
            .rendered
            .result
            .report
            .hazard_list
            .iter()
            .all(|h| h.buffer == "occupancy-map"));
        let culled = |c: &Checked| c.rendered.result.culling.as_ref().unwrap().culled_fragments;
        assert!(culled(&plain) <= culled(&atomic));
    }
    assert!(lost > 0, "no schedule lost a bit of the plain fill");
}

/// Culling removes far fragments before the racy read-modify-write: kb-rmw races less.
#[test]
fn culling_cuts_the_races_of_kb_rmw_without_removing_them() {
    let run = |o| {
        let mut s = spec("hairball", "kb-rmw", 48, o);
        s.exec = scheduled(Policy::Random, 1);
        check(&s)
    };
    let plain = run(None);
    let culled = run(occ(32, RangeSource::Exact, FillMode::Atomic));
    let (a, b) = (plain.algorithm_hazards(), culled.algorithm_hazards());
    assert!(b.total() > 0, "culled kb-rmw still races");
    assert!(b.lost_updates < a.lost_updates, "{b:?} vs {a:?}");
}

/// The no-gain worst case: on coplanar-stack the k nearest share one sub-interval with
/// everything else, so nothing is culled (and the extra passes are pure cost).
#[test]
fn coplanar_fragments_are_the_no_gain_worst_case() {
    let s = spec(
        "coplanar-stack",
        "kplus",
        48,
        occ(32, RangeSource::Exact, FillMode::Atomic),
    );
    let c = check(&s);
    assert_exact_and_lemma(&c, "coplanar-stack");
    assert_eq!(
        c.rendered.result.culling.as_ref().unwrap().culled_fragments,
        0
    );
}

fn fragrace(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fragrace"))
        .args(args)
        .output()
        .expect("runs")
}

fn assert_refused(args: &[&str], words: &[&str]) {
    let o = fragrace(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
    for w in words {
        assert!(err.contains(w), "{args:?}: `{w}` not in: {err}");
    }
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn bad_occupancy_parameters_get_a_clear_error() {
    let run = [
        "render", "--scene", "cubes", "--algo", "kplus", "--width", "16", "--height", "16",
    ];
    let with = |extra: &[&'static str]| -> Vec<&str> { run.iter().chain(extra).copied().collect() };
    assert_refused(
        &with(&["--occupancy", "0"]),
        &["--occupancy 0", "between 1 and 64"],
    );
    assert_refused(
        &with(&["--occupancy", "65"]),
        &["--occupancy 65", "between 1 and 64"],
    );
    assert_refused(
        &with(&["--occupancy", "1", "--k", "33"]),
        &["--occupancy 1", "k = 33", "at least k / 32 = 2"],
    );
    assert_refused(&with(&["--range", "hull"]), &["add --occupancy D"]);
    assert_refused(
        &with(&["--occupancy", "4", "--range", "sphere"]),
        &["sphere", "exact, bbox or hull"],
    );
    let ll = [
        "render",
        "--scene",
        "cubes",
        "--algo",
        "ll",
        "--occupancy",
        "4",
        "--width",
        "8",
        "--height",
        "8",
    ];
    assert_refused(
        &ll,
        &["`ll` does not run behind occupancy culling", "kplus"],
    );
    assert_refused(
        &[
            "fuzz",
            "--algo",
            "ll",
            "--occupancy",
            "4",
            "--iterations",
            "1",
        ],
        &["none of ll runs behind occupancy culling"],
    );
}

#[test]
fn list_says_which_algorithms_take_occupancy_culling() {
    let o = fragrace(&["list", "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let takers: Vec<&str> = v["algorithms"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|a| a["occupancy"] == true)
        .map(|a| a["name"].as_str().unwrap())
        .collect();
    for a in [
        "kplus",
        "kplus-heap",
        "kb-atomic32",
        "kb-atomic64",
        "kb-spinlock",
        "kb-interlock",
        "kb-rmw",
        "srab",
    ] {
        assert!(takers.contains(&a), "{a} missing from {takers:?}");
    }
    assert!(!takers.contains(&"ll"));
}
