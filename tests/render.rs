//! The renderer: shaded OBJ+MTL scenes, Beer-Lambert translucency and Fresnel, exact
//! algorithms' pictures equal to the truth's, `check`'s three panels, turntables, scene files
//! and bad input.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use fragrace::render::{self, Look, Overrides, Shade};
use fragrace::run::{self, RunSpec, SceneSpec};
use fragrace::scene::{Camera, Projection};
use fragrace_emu::ExecConfig;
use glam::Vec3;

fn asset(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("assets")
        .join(name)
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("fragrace-render-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn fragrace(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fragrace"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(o: &Output) -> String {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// A run of `algo` on an OBJ seen orthographically straight along -Z.
fn straight_on(obj: &Path, algo: &str, size: u32) -> RunSpec {
    let mut s = RunSpec::new(
        SceneSpec::Obj {
            path: obj.to_path_buf(),
            sha256: None,
        },
        algo,
    );
    s.camera = Camera {
        projection: Projection::Orthographic,
        ..Camera::default()
    };
    s.width = size;
    s.height = size;
    s.exec = ExecConfig::ordered();
    s
}

/// The pixel (column, row) a scene point falls in.
fn pixel_of(loaded: &run::Loaded, spec: &RunSpec, p: Vec3) -> usize {
    let c = loaded.view_proj * p.extend(1.0);
    let (x, y) = (c.x / c.w, c.y / c.w);
    let px = ((x + 1.0) / 2.0 * spec.width as f32) as usize;
    let py = ((1.0 - y) / 2.0 * spec.height as f32) as usize;
    py * spec.width as usize + px
}

/// The shaded image of `spec` under `look` (and `overrides`), with the loaded scene.
fn shaded(spec: &RunSpec, look: &Look, overrides: &Overrides) -> (Vec<[f32; 4]>, run::Loaded) {
    let loaded = run::load(spec).unwrap();
    let r = run::render(spec, &loaded).unwrap();
    let surface = render::run::surface(&loaded, overrides).unwrap();
    let view = render::run::view(spec, &loaded, &surface);
    let (img, stats) = render::image(&spec.algo, &r.result, &view, look).unwrap();
    assert_eq!(stats.without_primitive, 0);
    assert!(stats.fragments > 0);
    (img, loaded)
}

fn close(got: [f32; 4], want: [f32; 4], what: &str) {
    for c in 0..4 {
        assert!(
            (got[c] - want[c]).abs() <= 1.0 / 255.0,
            "{what}: channel {c}: got {got:?}, want {want:?}"
        );
    }
}

/// Acceptance: a shipped OBJ+MTL scene of two objects with different `Kd` and `d` (one
/// through `d`, one through `Tr`): known pixels have the composite of their materials.
#[test]
fn obj_mtl_scene_of_two_objects_has_its_materials_at_known_pixels() {
    let spec = straight_on(&asset("scenes/two-squares.obj"), "ll", 64);
    // Seen straight on, every normal faces the eye: lit colour = Kd (no highlight).
    let look = Look {
        specular: 0.0,
        ..Look::default()
    };
    let (img, loaded) = shaded(&spec, &look, &Overrides::default());
    let surface = loaded.scene.surface.as_ref().expect("an OBJ has a surface");
    assert!(surface.warnings.is_empty(), "{:?}", surface.warnings);
    let (red, blue) = ([0.9, 0.1, 0.1], [0.1, 0.2, 0.9]);
    let (a_red, a_blue) = (0.5, 0.8);
    let over = |c: [f32; 3], a: f32, under: [f32; 3]| -> [f32; 3] {
        [0, 1, 2].map(|i| c[i] * a + under[i] * (1.0 - a))
    };
    let white = [1.0; 3];
    let with_alpha = |c: [f32; 3], a: f32| [c[0], c[1], c[2], a];
    let front_only = over(red, a_red, white);
    let back_only = over(blue, a_blue, white);
    let both = over(red, a_red, back_only);
    let at = |x: f32| img[pixel_of(&loaded, &spec, Vec3::new(x, 0.0, 0.0))];
    close(at(-0.3), with_alpha(front_only, a_red), "front square only");
    close(at(0.3), with_alpha(back_only, a_blue), "back square only");
    close(
        at(0.0),
        with_alpha(both, 1.0 - (1.0 - a_red) * (1.0 - a_blue)),
        "front over back",
    );
    close(
        img[pixel_of(&loaded, &spec, Vec3::new(0.0, 0.45, 0.0))],
        [1.0, 1.0, 1.0, 0.0],
        "background",
    );
    // --color and --opacity replace the MTL's, per object (one object here).
    let (img, loaded) = shaded(
        &spec,
        &look,
        &Overrides {
            colors: vec![[0.0, 1.0, 0.0]],
            opacities: vec![1.0],
        },
    );
    close(
        img[pixel_of(&loaded, &spec, Vec3::new(0.0, 0.0, 0.0))],
        [0.0, 1.0, 0.0, 1.0],
        "opaque green",
    );
}

/// Acceptance: through a slab of known thickness, Beer-Lambert translucency is
/// exp(-sigma l) per channel within 1/255; Fresnel multiplies by 1 at normal incidence.
#[test]
fn translucency_through_a_slab_is_beer_lambert() {
    // A 1 x 1 x 0.5 box: seen along Z, l = 0.5 at the centre.
    let spec = straight_on(&asset("scenes/slab.obj"), "ll", 48);
    let sigma = 2.0;
    let kd = [0.0, 0.5, 1.0];
    let overrides = Overrides {
        colors: vec![kd],
        opacities: vec![],
    };
    for shade in [Shade::Translucent, Shade::Fresnel] {
        let look = Look {
            shade,
            sigma,
            ..Look::default()
        };
        let (img, loaded) = shaded(&spec, &look, &overrides);
        let want = kd.map(|k| (-sigma * (1.0 - k) * 0.5).exp());
        for p in [Vec3::ZERO, Vec3::new(0.3, -0.2, 0.0)] {
            close(
                img[pixel_of(&loaded, &spec, p)],
                [want[0], want[1], want[2], 1.0],
                shade.name(),
            );
        }
        assert!((want[0] - (-1.0f32).exp()).abs() < 1e-6);
    }
    // At 60 degrees the ray through the centre crosses front and back faces at cos 0.5:
    // l = 0.5 / cos = 1, and Fresnel transmits (1 - 0.5^5) at each face.
    let mut tilted = spec.clone();
    tilted.camera.azimuth = 60.0;
    for shade in [Shade::Translucent, Shade::Fresnel] {
        let look = Look {
            shade,
            sigma,
            ..Look::default()
        };
        let (img, loaded) = shaded(&tilted, &look, &overrides);
        let ft = if shade == Shade::Fresnel {
            (1.0 - 0.5f32.powi(5)).powi(2)
        } else {
            1.0
        };
        let want = kd.map(|k| (-sigma * (1.0 - k) * 1.0).exp() * ft);
        close(
            img[pixel_of(&loaded, &tilted, Vec3::ZERO)],
            [want[0], want[1], want[2], 1.0],
            &format!("{} at 60 degrees", shade.name()),
        );
    }
}

/// Acceptance: with shading on, every algorithm the oracle finds exact gives the truth's
/// picture within 1/255 per channel (the truth's k nearest fragments for the k-buffers, its
/// nearest for `opaque`), and there are many of them.
#[test]
fn exact_algorithms_give_the_truths_shaded_picture() {
    use fragrace_kernels::algo::Capture;
    use fragrace_kernels::{AlgoResult, Capacity};
    let mut spec = RunSpec::new(SceneSpec::Builtin("spheres".into()), "truth");
    spec.width = 40;
    spec.height = 40;
    spec.camera = Camera::new(30.0, 20.0);
    spec.exec = ExecConfig::ordered();
    spec.params.k = 4;
    let loaded = run::load(&spec).unwrap();
    let truth = run::truth(&spec, &loaded).unwrap();
    let surface = render::run::surface(&loaded, &Overrides::default()).unwrap();
    let view = render::run::view(&spec, &loaded, &surface);
    // The truth cut to what an algorithm of `capacity` keeps.
    let kept = |capacity: Capacity| -> AlgoResult {
        let t = truth.capture.as_ref().unwrap();
        let keep = match capacity {
            Capacity::KNearest => spec.params.k as usize,
            Capacity::Nearest => 1,
            _ => usize::MAX,
        };
        let lists = (0..t.pixels()).map(|p| t.pixel(p).iter().take(keep).copied().collect());
        AlgoResult {
            capture: Some(Capture::from_lists(t.width, t.height, lists)),
            ..AlgoResult::default()
        }
    };
    let mut exact = Vec::new();
    for shade in [Shade::Lit, Shade::Fresnel] {
        let look = Look {
            shade,
            ..Look::default()
        };
        for algo in fragrace_kernels::algorithms() {
            let info = algo.info();
            if matches!(info.capacity, Capacity::Count | Capacity::Image) {
                continue;
            }
            let mut s = spec.clone();
            s.algo = info.name.to_string();
            let Ok(c) = run::check_with(&s, &loaded, &truth) else {
                continue;
            };
            if c.metrics.error_pixels > 0 || c.rendered.result.capture.is_none() {
                continue;
            }
            let (got, stats) = render::image(info.name, &c.rendered.result, &view, &look).unwrap();
            if stats.without_primitive > 0 {
                // Depths only (the bucket schemes): lit shading needs primitives.
                continue;
            }
            let (want, _) = render::image("truth", &kept(info.capacity), &view, &look).unwrap();
            for p in 0..got.len() {
                for ch in 0..4 {
                    assert!(
                        (got[p][ch] - want[p][ch]).abs() <= 1.0 / 255.0,
                        "{} {}: pixel {p}: {:?} vs truth {:?}",
                        info.name,
                        shade.name(),
                        got[p],
                        want[p]
                    );
                }
            }
            exact.push(info.name);
        }
    }
    assert!(exact.len() >= 30, "only {exact:?} were exact");
}

/// Acceptance: `check --out compare.png` of kb-rmw has non-zero difference pixels exactly
/// where `check` reports error pixels (its errors heatmap), read back from the PNGs.
#[test]
fn compare_png_differs_exactly_at_the_error_pixels() {
    let d = tmp("compare");
    let png = d.join("compare.png");
    let (w, h) = (64u32, 64u32);
    let o = fragrace(&[
        "check",
        "--scene",
        "hairball",
        "--algo",
        "kb-rmw",
        "--k",
        "4",
        "--exec",
        "scheduled",
        "--seed",
        "3",
        "--width",
        "64",
        "--height",
        "64",
        "--out",
        png.to_str().unwrap(),
        "--heatmap",
        d.to_str().unwrap(),
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(ok(&o).lines().last().unwrap()).unwrap();
    let errors = v["error_pixels"].as_u64().unwrap();
    assert!(errors > 0 && errors < u64::from(w * h) / 2, "{v}");
    let pic = image::open(&png).unwrap().to_rgb8();
    let heat = image::open(d.join("errors.png")).unwrap().to_rgb8();
    // The layout of `render::picture::panels`: panels 8 pixels apart under their titles.
    let gap = 8;
    assert_eq!(pic.width(), 3 * w + 4 * gap);
    let title = pic.height() - h - gap;
    assert!((14..=60).contains(&title), "{title}");
    let x0 = gap + 2 * (w + gap);
    let mut marked = 0;
    for y in 0..h {
        for x in 0..w {
            let diff = pic.get_pixel(x0 + x, title + y).0 != [0, 0, 0];
            let error = heat.get_pixel(x, y).0 != [0, 0, 0];
            assert_eq!(diff, error, "pixel ({x}, {y})");
            marked += u64::from(diff);
        }
    }
    assert_eq!(marked, errors);
    // The title bar has words in it (dark pixels on white).
    let inked = (0..3 * w)
        .filter(|&x| (0..title).any(|y| pic.get_pixel(x, y).0[0] < 100))
        .count();
    assert!(inked > 50, "{inked}");
}

/// `count --out` is a depth-complexity picture with a legend bar; `--turntable N` writes
/// an animated GIF of N frames, or N numbered PNGs.
#[test]
fn depth_complexity_legend_and_turntables() {
    let d = tmp("pictures");
    let dc = d.join("dc.png");
    ok(&fragrace(&[
        "render",
        "--scene",
        "spheres",
        "--algo",
        "count",
        "--width",
        "96",
        "--height",
        "96",
        "--out",
        dc.to_str().unwrap(),
    ]));
    let pic = image::open(&dc).unwrap().to_rgb8();
    assert!(pic.width() > 96 + 16, "a legend beside the image");
    // The bar's top is the largest count's colour (white on the ramp).
    let top = (96..pic.width())
        .flat_map(|x| (0..40).map(move |y| (x, y)))
        .any(|(x, y)| pic.get_pixel(x, y).0 == [255, 255, 255]);
    assert!(top);
    let gif = d.join("turn.gif");
    ok(&fragrace(&[
        "render",
        "--scene",
        "cubes",
        "--algo",
        "ll",
        "--width",
        "32",
        "--height",
        "32",
        "--turntable",
        "3",
        "--out",
        gif.to_str().unwrap(),
    ]));
    use image::AnimationDecoder;
    let frames = image::codecs::gif::GifDecoder::new(std::io::BufReader::new(
        std::fs::File::open(&gif).unwrap(),
    ))
    .unwrap()
    .into_frames()
    .collect_frames()
    .unwrap();
    assert_eq!(frames.len(), 3);
    assert_ne!(frames[0].buffer(), frames[1].buffer(), "views differ");
    let pngs = d.join("turn.png");
    ok(&fragrace(&[
        "render",
        "--scene",
        "cubes",
        "--algo",
        "ll",
        "--width",
        "32",
        "--height",
        "32",
        "--turntable",
        "2",
        "--out",
        pngs.to_str().unwrap(),
    ]));
    for i in 0..2 {
        assert!(d.join(format!("turn-{i:03}.png")).exists());
    }
}

/// Bad input: a missing or malformed MTL gives a warning and default materials; an opacity
/// outside [0, 1] is an error naming it and the range; a scene file's unknown key is an
/// error naming the key and its line.
#[test]
fn bad_materials_and_scene_files() {
    let d = tmp("bad");
    let obj = |name: &str, mtllib: &str| {
        let p = d.join(name);
        std::fs::write(
            &p,
            format!("mtllib {mtllib}\nusemtl glass\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
        )
        .unwrap();
        p
    };
    let missing = obj("missing.obj", "nowhere.mtl");
    std::fs::write(d.join("broken.mtl"), "newmtl glass\nKd 1 oops 0\n").unwrap();
    let broken = obj("broken.obj", "broken.mtl");
    for (path, why) in [
        (&missing, "material file not found"),
        (&broken, "malformed material file"),
    ] {
        let o = fragrace(&[
            "render",
            "--obj",
            path.to_str().unwrap(),
            "--algo",
            "ll",
            "--width",
            "16",
            "--height",
            "16",
            "--out",
            d.join("x.png").to_str().unwrap(),
        ]);
        ok(&o);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("warning:") && err.contains(why), "{err}");
        assert!(err.contains("default"), "{err}");
    }
    // The default material replaced the unreadable one.
    let mut spec = straight_on(&missing, "ll", 8);
    spec.camera.projection = Projection::Perspective;
    let loaded = run::load(&spec).unwrap();
    let s = loaded.scene.surface.as_ref().unwrap();
    assert!(s
        .triangle_material
        .iter()
        .all(|&m| s.materials[m as usize] == fragrace::scene::Material::default_for(0)));

    // Opacity out of range: the command line, an MTL and a scene file.
    let o = fragrace(&[
        "render",
        "--scene",
        "cubes",
        "--opacity",
        "1.5",
        "--out",
        "x.png",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("1.5") && err.contains("[0, 1]"),
        "{err}"
    );
    std::fs::write(d.join("dense.mtl"), "newmtl glass\nKd 1 1 1\nd 1.25\n").unwrap();
    let dense = obj("dense.obj", "dense.mtl");
    let o = fragrace(&[
        "render",
        "--obj",
        dense.to_str().unwrap(),
        "--width",
        "8",
        "--height",
        "8",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("1.25") && err.contains("[0, 1]"),
        "{err}"
    );
    let scene = |name: &str, text: &str| {
        let p = d.join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let opaque = scene(
        "opacity.json",
        "{\n  \"objects\": [ { \"obj\": \"missing.obj\", \"opacity\": -0.5 } ]\n}\n",
    );
    let o = fragrace(&["render", "--scene-file", opaque.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("-0.5") && err.contains("[0, 1]"),
        "{err}"
    );
    let typo = scene(
        "typo.json",
        "{\n  \"objects\": [\n    { \"obj\": \"missing.obj\",\n      \"colour\": [1, 0, 0] }\n  ]\n}\n",
    );
    let o = fragrace(&["render", "--scene-file", typo.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("`colour`") && err.contains("line 4"),
        "{err}"
    );
}

/// The shipped scene file: two OBJ objects placed, one recoloured, through its camera; the
/// objects keep their materials (the MTL's, and the file's override).
#[test]
fn shipped_scene_file_renders_with_its_materials() {
    let d = tmp("scene-file");
    let out = d.join("scene.png");
    let o = fragrace(&[
        "render",
        "--scene-file",
        asset("scenes/two-squares.json").to_str().unwrap(),
        "--algo",
        "ll",
        "--width",
        "64",
        "--height",
        "64",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(ok(&o).lines().last().unwrap()).unwrap();
    assert_eq!(v["azimuth"], 25.0);
    let spec = RunSpec::new(
        SceneSpec::File {
            path: asset("scenes/two-squares.json"),
            sha256: None,
        },
        "ll",
    );
    let loaded = run::load(&spec).unwrap();
    let s = loaded.scene.surface.as_ref().unwrap();
    assert_eq!(loaded.scene.objects.len(), 2);
    let green = loaded.scene.objects[1].start as usize;
    let m = &s.materials[s.triangle_material[green] as usize];
    assert_eq!((m.color, m.opacity), ([0.3, 0.8, 0.4], 0.6));
    let m = &s.materials[s.triangle_material[0] as usize];
    assert_eq!((m.name.as_str(), m.opacity), ("red", 0.5));
    let pic = image::open(&out).unwrap().to_rgb8();
    let c = |p: &image::Rgb<u8>| p.0.map(i32::from);
    assert!(pic.pixels().any(|p| c(p)[1] > c(p)[0] + 40), "green shows");
    assert!(pic.pixels().any(|p| c(p)[0] > c(p)[2] + 40), "red shows");
}

/// The OBJ pre-pass keeps `vn` normals per triangle corner (fans of polygons) and each
/// triangle's `usemtl`; unusable normals are left out with a warning, never an error.
#[test]
fn obj_extras_normals_and_materials() {
    use fragrace::scene::obj::parse_obj_bytes_with_extras;
    let text = b"mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nvn 0 0 -1\n\
usemtl a\nf 1//1 2//1 3//1 4//1\nusemtl b\nf 1//2 3//2 2//2\nusemtl a\nf 1//-1 4//-1 3//-1\n";
    let (mesh, ex) = parse_obj_bytes_with_extras(text).unwrap();
    assert_eq!(mesh.indices.len(), 4);
    assert_eq!(ex.material_names, ["a", "b"]);
    assert_eq!(ex.triangle_material, [0, 0, 1, 0]);
    assert_eq!(ex.mtllibs, ["m.mtl"]);
    let (normals, corners) = ex.normals.expect("every face has vn");
    assert_eq!(normals, [Vec3::Z, -Vec3::Z]);
    assert_eq!(corners, [[0, 0, 0], [0, 0, 0], [1, 1, 1], [1, 1, 1]]);
    assert!(ex.warnings.is_empty(), "{:?}", ex.warnings);
    // A normal index past the defined ones, and faces without normals beside faces with.
    for bad in [
        &b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//7\n"[..],
        &b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\nf 1 3 2\n"[..],
    ] {
        let (mesh, ex) = parse_obj_bytes_with_extras(bad).unwrap();
        assert!(!mesh.indices.is_empty());
        assert!(ex.normals.is_none());
        assert!(
            ex.warnings[0].contains("smooth normals"),
            "{:?}",
            ex.warnings
        );
    }
}

/// `--place X,Y,Z` puts each `--obj` file where it is told (one per file, in order).
#[test]
fn obj_files_take_a_placement_each() {
    let slab = asset("scenes/slab.obj");
    let file = || run::ObjFile {
        path: slab.clone(),
        sha256: None,
    };
    let spec = RunSpec::new(
        SceneSpec::Objs {
            files: vec![file(), file()],
            step: [0.0; 3],
            places: vec![[0.0, 0.0, 0.0], [2.0, 1.0, 0.0]],
        },
        "ll",
    );
    let loaded = run::load(&spec).unwrap();
    let s = &loaded.scene;
    assert_eq!(s.objects.len(), 2);
    let centre = |r: &std::ops::Range<u32>| {
        let ids: Vec<u32> = s.mesh.indices[r.start as usize..r.end as usize]
            .iter()
            .flatten()
            .copied()
            .collect();
        ids.iter()
            .map(|&i| s.mesh.positions[i as usize])
            .sum::<Vec3>()
            / ids.len() as f32
    };
    // Normalised together: the 3-unit-wide scene (x from -0.5 to 2.5) scaled to 1.
    let moved = centre(&s.objects[1]) - centre(&s.objects[0]);
    assert!(
        (moved - Vec3::new(2.0, 1.0, 0.0) / 3.0).length() < 1e-5,
        "{moved}"
    );
    assert!(spec.command("render").contains("--place 2,1,0"));
    let o = fragrace(&[
        "render",
        "--obj",
        slab.to_str().unwrap(),
        "--obj",
        slab.to_str().unwrap(),
        "--place",
        "1,0,0",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("once per file"),
        "{err}"
    );
}

/// The renderer's camera options: unset, the peer's orbit matrix bit for bit; `look_at`
/// projects to the image centre; twice the distance, half the size on screen; an
/// orthographic camera keeps sizes whatever the depth.
#[test]
fn camera_options() {
    let (r, w, h) = (0.8f32, 64u32, 48u32);
    let orbit = Camera::new(30.0, 20.0);
    let same = Camera {
        fovy: 60.0,
        ..orbit
    };
    assert_eq!(same.view_proj(r, w, h), orbit.view_proj(r, w, h));
    let ndc = |c: &Camera, p: Vec3| {
        let v = c.view_proj(r, w, h) * p.extend(1.0);
        v.truncate() / v.w
    };
    let at = Camera {
        look_at: Some([0.2, -0.1, 0.3]),
        distance: Some(2.0),
        ..orbit
    };
    let centre = ndc(&at, Vec3::new(0.2, -0.1, 0.3));
    assert!(centre.x.abs() < 1e-5 && centre.y.abs() < 1e-5, "{centre}");
    assert!(centre.z > -1.0 && centre.z < 1.0);
    let far = Camera {
        distance: Some(4.0),
        ..at
    };
    // A point beside the one looked at, seen at twice the distance: half as far off centre.
    let side = Vec3::new(0.2, 0.0, 0.3);
    let (near_y, far_y) = (ndc(&at, side).y, ndc(&far, side).y);
    assert!((near_y / far_y - 2.0).abs() < 0.05, "{near_y} vs {far_y}");
    let ortho = |d| Camera {
        projection: Projection::Orthographic,
        distance: Some(d),
        ..at
    };
    let (a, b) = (ndc(&ortho(2.0), side), ndc(&ortho(4.0), side));
    assert!(
        (a.y - b.y).abs() < 1e-5 && a.z > -1.0 && a.z < 1.0,
        "{a} vs {b}"
    );
    // Out of range: refused with the value.
    let bad = Camera {
        distance: Some(-1.0),
        ..orbit
    };
    assert!(bad.validate(w, h).unwrap_err().to_string().contains("-1"));
}
