//! The claims of Kim & Kye, "Z-Thickness Blending: Effective Fragment Merging for
//! Multi-Fragment Rendering", tested under every interleaving on built-in scenes: OFM's
//! order independence, SFM's limit, z-fighting blended the same under every schedule, tail
//! handling against dropping the overflow, and the races of the unsynchronized k-buffers.
//! Unit tests of the operators themselves are in `kernels/src/merging/`.

use fragrace::run::{self, Loaded, RunSpec, SceneSpec};
use fragrace::scene::Camera;
use fragrace_emu::{ExecConfig, ExecMode, Policy, ScheduleConfig};
use fragrace_kernels::merging::skb::{SkbOfm, Sync};
use fragrace_kernels::merging::{MergeParams, Thickness};
use fragrace_kernels::{AlgoResult, Algorithm};

const SIZE: u32 = 40;
/// Fixed z-thickness (view depth) of the z-fighting test: wider than the gaps of its
/// fighting surfaces.
const THICK: f32 = 0.02;

fn spec(scene: &str, algo: &str) -> RunSpec {
    let mut s = RunSpec::new(SceneSpec::Builtin(scene.into()), algo);
    s.width = SIZE;
    s.height = SIZE;
    s.camera = Camera::new(0.0, 15.0);
    s
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
        ..ExecConfig::parallel(2)
    }
}

/// Ordered, parallel (lockstep and not), and every scheduled policy with `seeds` seeds.
fn executors(seeds: u64) -> Vec<ExecConfig> {
    let mut v = vec![
        ExecConfig::ordered(),
        ExecConfig::parallel(2),
        ExecConfig {
            lockstep: false,
            ..ExecConfig::parallel(3)
        },
    ];
    for p in Policy::all() {
        for seed in 0..seeds {
            v.push(scheduled(p.clone(), seed));
        }
    }
    v
}

fn image(r: &AlgoResult) -> &[[f32; 4]] {
    r.image
        .as_deref()
        .expect("merging algorithms resolve an image")
}

/// Largest RGB channel difference between two images.
fn max_diff(a: &[[f32; 4]], b: &[[f32; 4]]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| (0..3).map(move |c| (x[c] - y[c]).abs()))
        .fold(0.0, f32::max)
}

fn assert_checks(r: &AlgoResult, what: &str) {
    for c in &r.checks {
        assert!(c.passed, "{what}: {} ({})", c.name, c.detail);
    }
    assert_eq!(r.report.stats.faulted, 0, "{what}: {:?}", r.report.faults);
}

/// Runs `algo` under every executor; returns the largest image difference from the
/// ordered run. Checks the invariants and that no hazard was seen on every run.
fn variation(algo: &dyn Algorithm, loaded: &Loaded, s: &RunSpec, seeds: u64) -> f32 {
    let frame = loaded.frame(s);
    let mut reference: Option<Vec<[f32; 4]>> = None;
    let mut worst = 0.0f32;
    for exec in executors(seeds) {
        let r = algo.run(&frame, &s.params, &exec).unwrap();
        let what = format!("{} {:?}", algo.info().name, exec.mode);
        assert_checks(&r, &what);
        assert_eq!(
            r.report.hazards.total(),
            0,
            "{what}: {:?}",
            r.report.hazard_list.first()
        );
        match &reference {
            None => reference = Some(image(&r).to_vec()),
            Some(want) => worst = worst.max(max_diff(image(&r), want)),
        }
    }
    worst
}

#[test]
fn skb_ofm_and_dfb_sfm_give_the_same_image_under_every_executor() {
    // skb-ofm enters its pixels' critical sections in primitive order and dfb-sfm merges
    // after a sort, so both are deterministic: measured difference 0 (bit-identical images)
    // on hairball and cubes under ordered, parallel and 6 policies x 2 seeds.
    for scene in ["hairball", "cubes"] {
        let s = spec(scene, "skb-ofm");
        let loaded = run::load(&s).unwrap();
        for name in ["skb-ofm", "dfb-sfm"] {
            let algo = fragrace_kernels::algorithm(name).unwrap();
            let worst = variation(algo.as_ref(), &loaded, &s, 2);
            eprintln!("{name} on {scene}: worst image difference across executors {worst:e}");
            assert_eq!(worst, 0.0, "{name} on {scene}");
        }
    }
}

#[test]
fn ofm_merges_the_same_in_any_entry_order() {
    // The paper's claim for OFM: the store pass can merge in whatever order fragments
    // arrive. Under *unordered* interlock the entry order is the schedule's. With k larger
    // than any pixel's merged record count nothing reaches the tail and only rounding
    // differs; measured on coplanar-stack (16 coplanar fragments merged into one record per
    // pixel) and cubes: at most 2.4e-7 (two ulps of 1).
    for (scene, k) in [("coplanar-stack", 8), ("cubes", 16)] {
        let mut s = spec(scene, "skb-ofm");
        s.params.k = k;
        let loaded = run::load(&s).unwrap();
        let worst = variation(&SkbOfm(Sync::UnorderedInterlock), &loaded, &s, 2);
        eprintln!("skb-ofm, unordered interlock, on {scene}: worst difference {worst:e}");
        assert!(worst <= 2.5e-7, "{scene}: {worst}");
    }
}

#[test]
fn dfb_sfm_tends_to_the_exact_composite_as_the_thickness_goes_to_0() {
    // spheres: no two fragments of a pixel at the same depth, so once the thickness is
    // below the smallest depth gap nothing merges and SFM's resolve is the plain
    // front-to-back composite (tail handling uses the over operator).
    let mut s = spec("spheres", "dfb-sfm");
    let loaded = run::load(&s).unwrap();
    let truth = run::truth(&s, &loaded).unwrap();
    let cp = run::check_with(&s, &loaded, &truth)
        .unwrap()
        .metrics
        .coplanarity;
    assert_eq!(cp, 0.0, "spheres has coplanar fragments");
    let mut errors = Vec::new();
    for t in [0.5f32, 0.05, 5e-3, 5e-4, 0.0] {
        s.params.merge = MergeParams {
            thickness: Thickness::Fixed(t),
            ..MergeParams::default()
        };
        let c = run::check_with(&s, &loaded, &truth).unwrap();
        let im = c.metrics.image.clone().unwrap();
        eprintln!(
            "dfb-sfm on spheres, thickness {t}: max difference {:e}, image EPR {}, PSNR {:.1}",
            im.max_diff, im.image_epr, im.psnr
        );
        errors.push(im.max_diff);
    }
    assert!(
        errors[0] > 1.0 / 255.0,
        "a thick band must change the image: {errors:?}"
    );
    assert!(errors.windows(2).all(|w| w[1] <= w[0]), "{errors:?}");
    // Thickness 0: the exact composite up to rounding (measured 1.2e-7).
    assert!(*errors.last().unwrap() <= 5e-7, "{errors:?}");
}

#[test]
fn merged_algorithms_blend_coplanar_stack_the_same_under_every_schedule() {
    // The analogue of Figure 3: 16 coplanar quads. The merged algorithms blend them into one
    // record the same way under every schedule (variation 0); kb-rmw keeps whichever
    // fragments survive the races, so its image varies from schedule to schedule.
    let s = spec("coplanar-stack", "skb-ofm");
    let loaded = run::load(&s).unwrap();
    let vary = |name: &str| {
        let algo = fragrace_kernels::algorithm(name).unwrap();
        schedule_variation(algo.as_ref(), &loaded, &s)
    };
    for name in ["skb-ofm", "dfb-sfm"] {
        assert_eq!(vary(name), 0.0, "{name}");
    }
    let kb = vary("kb-rmw");
    eprintln!("kb-rmw on coplanar-stack: image variation across 4 schedules {kb}");
    assert!(kb > 1.0 / 255.0, "kb-rmw: {kb}");
}

#[test]
fn tail_handling_beats_dropping_the_overflow_on_hairball() {
    // The analogue of Figure 11 at M = k = 8: the merging k-buffer with a tail loses less of
    // the image than the k-buffers that drop what does not fit (kplus, kb-ofm without tail).
    let s = spec("hairball", "truth");
    let loaded = run::load(&s).unwrap();
    let truth = run::truth(&s, &loaded).unwrap();
    let metrics = |name: &str| {
        let mut t = s.clone();
        t.algo = name.into();
        t.exec = ExecConfig::ordered();
        let c = run::check_with(&t, &loaded, &truth).unwrap();
        assert!(
            c.failed_checks().is_empty(),
            "{name}: {:?}",
            c.failed_checks()
        );
        c.metrics.image.clone().unwrap()
    };
    let (skb, kplus, kb_ofm, dfb_sfm) = (
        metrics("skb-ofm"),
        metrics("kplus"),
        metrics("kb-ofm"),
        metrics("dfb-sfm"),
    );
    for (name, m) in [
        ("skb-ofm", &skb),
        ("kplus", &kplus),
        ("kb-ofm", &kb_ofm),
        ("dfb-sfm", &dfb_sfm),
    ] {
        eprintln!(
            "hairball k = 8, {name}: image EPR {:.4}, PSNR {:.2} dB",
            m.image_epr, m.psnr
        );
    }
    for dropping in [&kplus, &kb_ofm] {
        assert!(skb.image_epr < dropping.image_epr && skb.psnr > dropping.psnr);
    }
    // DFB keeps every fragment: its tail is exact up to the merges of 2 P(z).
    assert!(dfb_sfm.image_epr < skb.image_epr && dfb_sfm.psnr > skb.psnr);
}

#[test]
fn unsynchronized_merging_races_and_the_detector_names_the_words() {
    let s = spec("hairball", "kb-ofm");
    let loaded = run::load(&s).unwrap();
    let frame = loaded.frame(&s);
    // The detector keeps the first hazards it sees; they must name the records' words.
    for (name, record, buffers) in [
        (
            "skb-ofm-unordered",
            "skb-ofm-core",
            &[
                "skb-ofm-core",
                "skb-ofm-tail",
                "skb-ofm-count",
                "skb-ofm-max-pos",
            ][..],
        ),
        ("kb-ofm", "kb-ofm-records", &["kb-ofm-records"][..]),
    ] {
        let algo = fragrace_kernels::algorithm(name).unwrap();
        let mut images = Vec::new();
        let mut lost = 0;
        for policy in [Policy::Random, Policy::Pct { depth: 3 }] {
            let r = algo.run(&frame, &s.params, &scheduled(policy, 1)).unwrap();
            assert_checks(&r, name);
            let h = &r.report.hazards;
            assert!(h.races > 0, "{name}: {h:?}");
            lost += h.lost_updates;
            let list = &r.report.hazard_list;
            assert!(
                list.iter().any(|x| x.buffer == record),
                "{name}: {record} not named"
            );
            for x in list {
                assert!(buffers.contains(&x.buffer.as_str()), "{name}: {x:?}");
                assert!(x.victim.primitive != x.other.primitive, "{name}: {x:?}");
            }
            images.push(image(&r).to_vec());
        }
        assert!(lost > 0, "{name}: no lost update under either policy");
        assert!(
            max_diff(&images[0], &images[1]) > 1.0 / 255.0,
            "{name}: the races change nothing"
        );
    }
}

/// Largest image difference of `algo` across 4 random schedules.
fn schedule_variation(algo: &dyn Algorithm, loaded: &Loaded, s: &RunSpec) -> f32 {
    let frame = loaded.frame(s);
    let images: Vec<Vec<[f32; 4]>> = (0..4)
        .map(|seed| {
            let r = algo
                .run(&frame, &s.params, &scheduled(Policy::Random, seed))
                .unwrap();
            image(&r).to_vec()
        })
        .collect();
    images[1..]
        .iter()
        .map(|i| max_diff(i, &images[0]))
        .fold(0.0, f32::max)
}

#[test]
fn z_fighting_on_interpenetrating_surfaces_blends_the_same_under_every_schedule() {
    // The analogue of Figure 3 on surfaces that fight: two boxes on the same planes split
    // along opposite diagonals, and two spheres of one radius tessellated differently.
    // kb-rmw races on the fighting fragments, so its image changes from schedule to
    // schedule. A z-thickness wider than the gaps merges them into one record: one image
    // under every schedule. f2b does not vary either, but for another reason: its depth
    // test runs in API order under every schedule, so its speckle (which surface rounding
    // puts first at each pixel) is the same in every run: spatial, not temporal.
    let mut s = spec("interpenetrating", "skb-ofm");
    s.params.merge = MergeParams {
        thickness: Thickness::Fixed(THICK),
        ..MergeParams::default()
    };
    let loaded = run::load(&s).unwrap();
    let algo = |name: &str| fragrace_kernels::algorithm(name).unwrap();
    for name in ["skb-ofm", "dfb-sfm", "f2b"] {
        let v = schedule_variation(algo(name).as_ref(), &loaded, &s);
        eprintln!("{name}: image variation across schedules {v:e}");
        assert_eq!(v, 0.0, "{name} across schedules");
    }
    let kb = schedule_variation(algo("kb-rmw").as_ref(), &loaded, &s);
    eprintln!("kb-rmw: image variation across schedules {kb}");
    assert!(kb > 1.0 / 255.0, "kb-rmw: {kb}");
    // The thickness really merges the fighting surfaces: without it the image differs.
    let frame = loaded.frame(&s);
    let run_with = |t: f32| {
        let mut p = s.params.clone();
        p.merge.thickness = Thickness::Fixed(t);
        let r = algo("dfb-sfm")
            .run(&frame, &p, &ExecConfig::ordered())
            .unwrap();
        image(&r).to_vec()
    };
    let merged_vs_thin = max_diff(&run_with(THICK), &run_with(1e-7));
    eprintln!("dfb-sfm, thickness {THICK} against 1e-7: {merged_vs_thin}");
    assert!(merged_vs_thin > 1.0 / 255.0, "{merged_vs_thin}");
}
