//! Geometry passes per frame against their formulas (the analogue of Table 2 of "Efficient
//! Depth Peeling via Bucket Sort"): on the built-in scenes, each measured count of `f2b`,
//! `f2b2`, `dual`, `bdp`, `bdp2`, `adp`, `kb-rmw` and `kb-multipass` is the one its formula
//! gives from the scene's depth complexity (read off the exact truth of the same view).
//!
//! `D` is the most fragments of a pixel; `L` the most *distinct depths* of a pixel (the
//! layers a peeler that collapses coplanar fragments sees; `L = D` without coplanarity).

use fragrace::run::{self, RunSpec, SceneSpec};
use fragrace::scene::Camera;
use fragrace_emu::ExecConfig;

const SCENES: [&str; 6] = [
    "cubes",
    "spheres",
    "coplanar-stack",
    "bunny",
    "teapot",
    "hairball",
];

fn spec(scene: &str, algo: &str, k: u32, exec: ExecConfig) -> RunSpec {
    let mut s = RunSpec::new(SceneSpec::Builtin(scene.into()), algo);
    s.width = 40;
    s.height = 40;
    s.camera = Camera::new(30.0, 15.0);
    s.params.k = k;
    s.exec = exec;
    s
}

/// `(D, L)` of the truth.
fn complexity(truth: &fragrace_kernels::AlgoResult) -> (u32, u32) {
    let c = truth.capture.as_ref().expect("the truth captures");
    let (mut d, mut l) = (0, 0);
    for p in 0..c.pixels() {
        let frags = c.pixel(p);
        let mut depths: Vec<u32> = frags.iter().map(|f| f.depth.to_bits()).collect();
        depths.sort_unstable();
        depths.dedup();
        d = d.max(frags.len() as u32);
        l = l.max(depths.len() as u32);
    }
    (d, l)
}

/// The geometry passes `algo` must run, or the range they must fall in, given `D`, `L` and
/// `k` (`fullscreen`: the full-screen passes it ran, which say how many batches `adp` took).
fn formula(algo: &str, d: u32, l: u32, k: u32, fullscreen: u32, ordered: bool) -> (u32, u32) {
    let exact = |n| (n, n);
    match algo {
        // One pass per layer, at most k, and the pass that finds nothing left.
        "f2b" => exact(k.min(l + 1)),
        // Two per layer (depth, EQUAL shade), at most k layers, and the last depth pass.
        "f2b2" => exact(if k > l { 2 * l + 1 } else { 2 * k }),
        // The initial range pass, then two layers per pass.
        "dual" => exact(l.div_ceil(2) + 1),
        // The range pass (`--range exact`: the scene once more) and one or two bucket passes.
        "bdp" => exact(2),
        "bdp2" => exact(3),
        // Range, histogram, and one routing pass per batch of 32 of the deepest pixel's
        // non-empty sub-intervals (at least one, at most its fragments).
        "adp" => {
            let batches = fullscreen;
            assert!(
                batches >= 1 && batches <= d.min(k).div_ceil(32),
                "adp ran {batches} batches for D = {d}, k = {k}"
            );
            exact(2 + batches)
        }
        "kb-rmw" => exact(1),
        // One certified fragment per active pixel and pass at least: one pass when nothing
        // races (ordered), at most min(k, D).
        "kb-multipass" if ordered => exact(1),
        "kb-multipass" => (1, k.min(d)),
        _ => unreachable!("no formula for {algo}"),
    }
}

#[test]
fn geometry_passes_follow_their_formulas_on_the_built_in_scenes() {
    let algos: [(&str, u32); 8] = [
        ("f2b", 1024),
        ("f2b2", 1024),
        ("dual", 8),
        ("bdp", 32),
        ("bdp2", 64),
        ("adp", 1024),
        ("kb-rmw", 8),
        ("kb-multipass", 8),
    ];
    let mut seen_deep = false;
    for scene in SCENES {
        let base = spec(scene, "truth", 8, ExecConfig::ordered());
        let loaded = run::load(&base).expect("scene loads");
        let truth = run::truth(&base, &loaded).expect("truth runs");
        let (d, l) = complexity(&truth);
        seen_deep |= d > 32;
        for (algo, k) in algos {
            for exec in [ExecConfig::ordered(), ExecConfig::parallel(2)] {
                let ordered = exec.mode == fragrace_emu::ExecMode::Ordered;
                let s = spec(scene, algo, k, exec);
                let c = run::check_with(&s, &loaded, &truth).expect("runs");
                let stats = &c.rendered.result.report.stats;
                let (lo, hi) = formula(algo, d, l, k, stats.fullscreen_passes, ordered);
                assert!(
                    (lo..=hi).contains(&stats.geometry_passes),
                    "{algo} on {scene} (D = {d}, L = {l}, k = {k}): {} geometry passes, formula {lo}..={hi}\n    {}",
                    stats.geometry_passes,
                    s.command("check")
                );
                // The --json figure is the same count.
                let json = run::summary_json(&s, &loaded, Some(&c), &c.rendered);
                assert_eq!(json["geometry_passes"], stats.geometry_passes);
            }
            // Small k caps the front-to-back peelers.
            if algo == "f2b" || algo == "f2b2" {
                let s = spec(scene, algo, 2, ExecConfig::ordered());
                let c = run::check_with(&s, &loaded, &truth).expect("runs");
                let g = c.rendered.result.report.stats.geometry_passes;
                assert_eq!(
                    g,
                    formula(algo, d, l, 2, 0, true).0,
                    "{algo} on {scene}, k = 2"
                );
            }
        }
    }
    assert!(
        seen_deep,
        "hairball has pixels deeper than 32 (adp batches)"
    );
}
