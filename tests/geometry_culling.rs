//! Geometry culling of the multi-pass peelers (depth-fighting paper, section 3.3): per
//! iteration an occlusion query of each object's bounding box against the last peeled layer,
//! conditional rendering of the objects, culled objects never queried again. It must change
//! no pixel, and draw fewer objects as objects are peeled completely.

use fragrace::run::{self, ObjFile, RunSpec, SceneSpec};
use fragrace::scene::Camera;
use fragrace_emu::{ExecConfig, Policy};
use fragrace_kernels::peeling::GeometryCulling;
use fragrace_kernels::HazardClass;

fn spec(scene: SceneSpec, algo: &str, culling: GeometryCulling, exec: ExecConfig) -> RunSpec {
    let mut s = RunSpec::new(scene, algo);
    s.width = 48;
    s.height = 48;
    s.camera = Camera::new(20.0, 15.0);
    s.params.k = 64;
    s.params.geometry_culling = culling;
    s.exec = exec;
    s
}

/// Every algorithm that takes geometry culling: with and without it, the same digest (every
/// captured fragment, image bit, count and hazard) and the same geometry passes; with it,
/// fewer objects drawn once objects are peeled, and no culled object queried again.
fn same_with_and_without(scene: SceneSpec, objects: u32) {
    let takers: Vec<_> = fragrace_kernels::algorithms()
        .into_iter()
        .filter(|a| a.takes_geometry_culling())
        .collect();
    assert!(takers.len() >= 6, "the front-to-back peelers take culling");
    let base = spec(
        scene.clone(),
        "truth",
        GeometryCulling::Off,
        ExecConfig::ordered(),
    );
    let loaded = run::load(&base).expect("scene loads");
    assert_eq!(loaded.scene.objects.len() as u32, objects);
    let truth = run::truth(&base, &loaded).expect("truth runs");
    for algo in takers {
        let info = algo.info();
        let mut execs = vec![ExecConfig::ordered()];
        if info.hazard != HazardClass::HazardProne {
            execs.push(ExecConfig::parallel(2));
            execs.push(ExecConfig::scheduled(Policy::Random, 1));
        }
        for exec in execs {
            let plain = spec(scene.clone(), info.name, GeometryCulling::Off, exec.clone());
            let culled = spec(scene.clone(), info.name, GeometryCulling::Queries, exec);
            let a = run::check_with(&plain, &loaded, &truth).expect("runs");
            let b = run::check_with(&culled, &loaded, &truth).expect("runs");
            let what = culled.command("check");
            assert!(
                b.failed_checks().is_empty(),
                "{what}: {:?}",
                b.failed_checks()
            );
            let (ra, rb) = (&a.rendered.result, &b.rendered.result);
            assert_eq!(
                run::digest(ra),
                run::digest(rb),
                "{what}: culling changed the output"
            );
            assert_eq!(ra.dropped, rb.dropped, "{what}");
            assert_eq!(
                ra.report.stats.geometry_passes, rb.report.stats.geometry_passes,
                "{what}: the same passes (the last one draws nothing)"
            );
            assert!(ra.geometry_culling.is_none());
            let g = rb.geometry_culling.as_ref().expect("culling summary");
            assert_eq!(g.objects, objects, "{what}");
            let its = &g.iterations;
            assert!(its.len() >= 2, "{what}: {its:?}");
            assert_eq!(
                its[0].objects_drawn, objects,
                "{what}: nothing culled at first"
            );
            // Objects drawn never grow back; an iteration queries exactly the objects it drew
            // (those not culled yet), the last one (which found nothing left) none.
            for w in its.windows(2) {
                assert!(w[1].objects_drawn <= w[0].objects_drawn, "{what}: {its:?}");
                assert_eq!(w[0].queries, w[0].objects_drawn, "{what}: {its:?}");
            }
            assert_eq!(its.last().unwrap().queries, 0, "{what}: {its:?}");
            if objects > 1 {
                let last = its.last().unwrap();
                assert!(
                    last.objects_drawn < objects,
                    "{what}: objects peeled completely are culled: {its:?}"
                );
            }
            // The JSON reports them.
            let json = run::summary_json(&culled, &loaded, Some(&b), &b.rendered);
            assert_eq!(json["geometry_culling"]["objects"], objects);
            assert_eq!(
                json["geometry_culling"]["iterations"][0]["objects_drawn"],
                objects
            );
        }
    }
}

#[test]
fn culling_changes_no_pixel_and_draws_fewer_objects_on_the_object_grid() {
    same_with_and_without(SceneSpec::Builtin("object-grid".into()), 27);
}

#[test]
fn several_obj_files_are_one_object_each() {
    // Teapots 20 units deep, 25 apart along -z: each behind the one before.
    let teapot = ObjFile {
        path: concat!(env!("CARGO_MANIFEST_DIR"), "/assets/teapot.obj.gz").into(),
        sha256: None,
    };
    let scene = SceneSpec::Objs {
        files: vec![teapot.clone(), teapot.clone(), teapot],
        step: [8.0, 0.0, -25.0],
        places: Vec::new(),
    };
    let s = spec(
        scene.clone(),
        "f2b",
        GeometryCulling::Queries,
        ExecConfig::ordered(),
    );
    assert!(s.command("check").contains("--obj-step 8,0,-25"));
    assert_eq!(s.command("check").matches("--obj ").count(), 3);
    same_with_and_without(scene, 3);
}

#[test]
fn algorithms_without_culling_refuse_it_by_name() {
    let s = spec(
        SceneSpec::Builtin("object-grid".into()),
        "kb-rmw",
        GeometryCulling::Queries,
        ExecConfig::ordered(),
    );
    let loaded = run::load(&s).expect("scene loads");
    let e = run::render(&s, &loaded).err().expect("refused").to_string();
    assert!(
        e.contains("--geometry-culling") && e.contains("kb-rmw") && e.contains("dual-2p"),
        "{e}"
    );
}
