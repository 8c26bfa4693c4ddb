//! Scene input: built-in scenes have the properties their names promise, the OBJ loader
//! matches the llvmpipe reference (`oit.py`) and fails with the right error, never a panic,
//! and the camera reproduces `oit.py`'s matrices.

use std::collections::{HashMap, HashSet};
use std::io::Write as _;
use std::path::{Path, PathBuf};

use fragrace::scene::builtin::{self, SplitMix64};
use fragrace::scene::{
    builtin_names, camera_rig, content_hash, load_obj, load_obj_with_hash, parse_obj_bytes,
    prim_color, prim_color_rgba8, Camera, Scene, SceneError,
};
use fragrace_emu::geometry::Mesh;
use glam::{DMat4, DVec3, DVec4, Mat4};

fn asset(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("assets")
        .join(name)
}

fn gunzip(bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(bytes), &mut out).unwrap();
    out
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    enc.write_all(bytes).unwrap();
    enc.finish().unwrap()
}

fn temp_file(name: &str, bytes: &[u8]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fragrace-scenes-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

fn parse(text: &str) -> Result<Mesh, SceneError> {
    parse_obj_bytes(text.as_bytes())
}

/// Bit-exact identity of a mesh, to pin the built-ins (case files name them and must replay).
fn mesh_hash(mesh: &Mesh) -> String {
    let mut bytes = Vec::new();
    for p in &mesh.positions {
        for c in p.to_array() {
            bytes.extend_from_slice(&c.to_bits().to_le_bytes());
        }
    }
    for t in &mesh.indices {
        for i in t {
            bytes.extend_from_slice(&i.to_le_bytes());
        }
    }
    content_hash(&bytes)[..16].to_owned()
}

// ------------------------------------------------------------------------------ topology

/// Every undirected edge in exactly two triangles, every directed edge in at most one
/// (consistent orientation), and a positive signed volume (outward, CCW from outside).
fn assert_closed_outward(mesh: &Mesh, what: &str) {
    let mut directed = HashSet::new();
    let mut undirected: HashMap<(u32, u32), u32> = HashMap::new();
    for t in &mesh.indices {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            assert!(
                directed.insert((a, b)),
                "{what}: directed edge {a}->{b} used twice"
            );
            *undirected.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    assert!(
        undirected.values().all(|&n| n == 2),
        "{what}: an edge is not shared by exactly two triangles"
    );
    assert!(signed_volume(mesh) > 0.0, "{what}: not oriented outwards");
}

fn signed_volume(mesh: &Mesh) -> f64 {
    mesh.indices
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize].as_dvec3());
            a.dot(b.cross(c)) / 6.0
        })
        .sum()
}

fn sub_mesh(mesh: &Mesh, tris: std::ops::Range<usize>) -> Mesh {
    Mesh {
        positions: mesh.positions.clone(),
        normals: None,
        indices: mesh.indices[tris].to_vec(),
    }
}

// ------------------------------------------------------------------------------ built-ins

#[test]
fn every_builtin_loads_valid_and_normalised() {
    for &name in builtin_names() {
        let scene = Scene::builtin(name).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(scene.name, name);
        scene.mesh.validate().unwrap();
        assert!(scene.mesh.triangle_count() > 0, "{name}");
        let (lo, hi) = scene.mesh.bounds().unwrap();
        assert!(
            ((lo + hi) / 2.0).abs().max_element() < 1e-6,
            "{name}: not centred"
        );
        assert!(
            ((hi - lo).max_element() - 1.0).abs() < 1e-6,
            "{name}: largest extent not 1"
        );
        let r = scene
            .mesh
            .positions
            .iter()
            .map(|p| p.length())
            .fold(0.0f32, f32::max);
        assert!(
            (r - scene.radius).abs() < 1e-6,
            "{name}: radius {} vs {r}",
            scene.radius
        );
        // Deterministic.
        assert_eq!(Scene::builtin(name).unwrap().mesh, scene.mesh, "{name}");
    }
}

#[test]
fn builtins_are_pinned_bit_for_bit() {
    // If one of these changes, every case file naming that scene stops replaying: change
    // it on purpose only (and say so in the changelog).
    let pins = [
        ("cubes", "25fd329f8de6e8ab"),
        ("coplanar-stack", "0963a1304c4bc055"),
        ("spheres", "6b94eb5fb8637165"),
        ("hairball", "20badeb8f183d5a4"),
        ("random-triangles:7:100", "4763b25af6aeaba9"),
    ];
    let got: Vec<(&str, String)> = pins
        .iter()
        .map(|(n, _)| (*n, mesh_hash(&builtin::mesh(n).unwrap())))
        .collect();
    for ((name, want), (_, got_hash)) in pins.iter().zip(&got) {
        assert_eq!(got_hash, want, "{name} changed; all: {got:?}");
    }
}

#[test]
fn unknown_builtin_lists_the_names() {
    let err = Scene::builtin("cube").unwrap_err();
    assert!(matches!(err, SceneError::UnknownBuiltin { .. }));
    let msg = err.to_string();
    for name in builtin_names() {
        assert!(msg.contains(name), "{msg}");
    }
    for bad in [
        "coplanar-stack:0",
        "coplanar-stack:x",
        "coplanar-stack:1:2",
        "cubes:3",
        "bunny:1",
        "random-triangles:1:0",
    ] {
        assert!(
            matches!(Scene::builtin(bad), Err(SceneError::BuiltinParams { .. })),
            "{bad}"
        );
    }
}

#[test]
fn cubes_have_exactly_coplanar_faces_from_different_cubes() {
    for mesh in [builtin::cubes(), Scene::builtin("cubes").unwrap().mesh] {
        assert_eq!(mesh.triangle_count(), 36);
        for cube in 0..3 {
            assert_closed_outward(&sub_mesh(&mesh, 12 * cube..12 * cube + 12), "cube");
        }
        // Axis-aligned planes: (axis, coordinate bits) -> cubes with a triangle in it.
        let mut planes: HashMap<(usize, u32), HashSet<usize>> = HashMap::new();
        for (tri, t) in mesh.indices.iter().enumerate() {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize].to_array());
            for (axis, &x) in a.iter().enumerate() {
                if x == b[axis] && x == c[axis] {
                    planes
                        .entry((axis, x.to_bits()))
                        .or_default()
                        .insert(tri / 12);
                }
            }
        }
        let shared = planes.values().filter(|cubes| cubes.len() >= 2).count();
        // y = +-0.5 (A, B), z = +-0.5 (A, B, C), x = 0 (A, C).
        assert!(
            shared >= 5,
            "only {shared} planes shared between cubes: {planes:?}"
        );
    }
}

#[test]
fn coplanar_stack_quads_are_identical() {
    for (name, n) in [
        ("coplanar-stack", 8),
        ("coplanar-stack:3", 3),
        ("coplanar-stack:1", 1),
    ] {
        let mesh = Scene::builtin(name).unwrap().mesh;
        assert_eq!(mesh.triangle_count(), 2 * n, "{name}");
        let quad = |q: usize| -> Vec<[u32; 3]> {
            mesh.indices[2 * q..2 * q + 2]
                .iter()
                .flat_map(|t| t.map(|i| mesh.positions[i as usize].to_array().map(f32::to_bits)))
                .collect()
        };
        for q in 1..n {
            assert_eq!(quad(q), quad(0), "{name}: quad {q}");
            // Distinct primitives (own vertices), not the same triangle drawn twice.
            assert_ne!(mesh.indices[2 * q], mesh.indices[0]);
        }
        // Flat: every fragment of every quad has the same depth from the default view.
        assert!(mesh.positions.iter().all(|p| p.z == mesh.positions[0].z));
    }
    assert_eq!(
        builtin::coplanar_stack(8),
        builtin::mesh("coplanar-stack").unwrap()
    );
}

#[test]
fn spheres_are_three_closed_nested_surfaces() {
    let mesh = builtin::spheres();
    let per = mesh.triangle_count() / 3;
    assert_eq!(mesh.triangle_count(), 3 * per);
    for s in 0..3 {
        assert_closed_outward(&sub_mesh(&mesh, s * per..(s + 1) * per), "sphere");
    }
    let scene = Scene::builtin("spheres").unwrap();
    assert_closed_outward(&scene.mesh, "spheres");
    assert_eq!(
        scene.mesh.normals.as_ref().map(Vec::len),
        Some(scene.mesh.positions.len())
    );
    // Nested: a central pixel's ray from the default camera crosses six surfaces. (Not the
    // exact centre ray: it runs along the outer sphere's seam, where this closed-interval
    // ray test counts a shared edge twice; a watertight rasterizer must not.)
    let rig = Camera::default().rig(scene.radius, 512, 512);
    let (origin, dir) = pixel_ray(rig.view_proj.inverse(), 256, 256, 512, 512);
    assert_eq!(ray_hits(&scene.mesh, origin, dir), 6);
}

#[test]
fn hairball_is_big_closed_and_deep_at_the_centre() {
    let scene = Scene::builtin("hairball").unwrap();
    let n = scene.mesh.triangle_count();
    assert!((50_000..=150_000).contains(&n), "{n} triangles");
    let per_tube = 6 * builtin::HAIRBALL_SEGMENTS;
    assert_eq!(n, builtin::HAIRBALL_CURVES * per_tube);
    for tube in 0..builtin::HAIRBALL_CURVES {
        assert_closed_outward(
            &sub_mesh(&scene.mesh, tube * per_tube..(tube + 1) * per_tube),
            "tube",
        );
    }
    // Depth complexity at the centre of a 512x512 default view, counted geometrically (each
    // ray-triangle hit is one fragment): the exact centre and the four central pixel centres.
    let (w, h) = (512, 512);
    let rig = Camera::default().rig(scene.radius, w, h);
    let centre = ray_hits(&scene.mesh, rig.eye, -rig.eye);
    assert!(centre > 50, "depth complexity {centre} at the centre");
    let inv = rig.view_proj.inverse();
    for (px, py) in [(255, 255), (256, 255), (255, 256), (256, 256)] {
        let (origin, dir) = pixel_ray(inv, px, py, w, h);
        let hits = ray_hits(&scene.mesh, origin, dir);
        assert!(hits > 50, "depth complexity {hits} at pixel ({px}, {py})");
    }
}

/// The ray through a pixel centre, from the near plane.
fn pixel_ray(inv_view_proj: DMat4, px: u32, py: u32, w: u32, h: u32) -> (DVec3, DVec3) {
    let ndc_x = 2.0 * (f64::from(px) + 0.5) / f64::from(w) - 1.0;
    let ndc_y = 2.0 * (f64::from(py) + 0.5) / f64::from(h) - 1.0;
    let unproject = |z: f64| {
        let p = inv_view_proj * DVec4::new(ndc_x, ndc_y, z, 1.0);
        p.truncate() / p.w
    };
    let (near, far) = (unproject(-1.0), unproject(1.0));
    (near, far - near)
}

/// Number of triangles a ray (t > 0) crosses (Moller-Trumbore, f64).
fn ray_hits(mesh: &Mesh, origin: DVec3, dir: DVec3) -> usize {
    mesh.indices
        .iter()
        .filter(|t| {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize].as_dvec3());
            let (e1, e2) = (b - a, c - a);
            let p = dir.cross(e2);
            let det = e1.dot(p);
            if det.abs() < 1e-18 {
                return false;
            }
            let s = origin - a;
            let u = s.dot(p) / det;
            let q = s.cross(e1);
            let v = dir.dot(q) / det;
            let t = e2.dot(q) / det;
            (0.0..=1.0).contains(&u) && v >= 0.0 && u + v <= 1.0 && t > 0.0
        })
        .count()
}

#[test]
fn random_triangles_are_seeded_and_hit_the_hard_cases() {
    let a = builtin::random_triangles(42, 2000);
    assert_eq!(a, builtin::random_triangles(42, 2000));
    assert_ne!(a, builtin::random_triangles(43, 2000));
    assert_eq!(a.triangle_count(), 2000);
    a.validate().unwrap();
    assert!(a.positions.iter().all(|p| p.abs().max_element() <= 2.0));
    let distinct: HashSet<[u32; 3]> = a.indices.iter().copied().collect();
    assert!(distinct.len() < 1950, "too few exact repeats");
    let mut edges = HashSet::new();
    let shared = a
        .indices
        .iter()
        .filter(|t| {
            (0..3).any(|k| !edges.insert((t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]))))
        })
        .count();
    assert!(shared > 200, "only {shared} triangles share an edge");
    assert_eq!(
        Scene::builtin("random-triangles:42:2000")
            .unwrap()
            .mesh
            .triangle_count(),
        2000
    );
}

#[test]
fn deterministic_sin_cos_is_accurate() {
    let mut rng = SplitMix64::new(1);
    for _ in 0..10_000 {
        let x = rng.range(-50.0, 50.0);
        let (s, c) = builtin::sin_cos(x);
        assert!(
            (s - x.sin()).abs() < 1e-13 && (c - x.cos()).abs() < 1e-13,
            "{x}"
        );
    }
}

// ------------------------------------------------------------------------------ shipped meshes

#[test]
fn shipped_meshes_match_the_reference_loader() {
    // Vertex and triangle counts and bounding-sphere radii from oit.py's load_obj + normalise.
    for (file, vertices, triangles, radius) in [
        ("bunny.obj.gz", 1839, 3674, 0.670116889075993),
        ("teapot.obj.gz", 792, 992, 0.5193312955440182),
        ("dragon_res4.obj.gz", 5205, 11102, 0.5388322587947597),
    ] {
        let mesh = load_obj(asset(file)).unwrap();
        assert_eq!(
            (mesh.positions.len(), mesh.triangle_count()),
            (vertices, triangles),
            "{file}"
        );
        let scene = Scene::from_obj(asset(file)).unwrap();
        assert!(
            (f64::from(scene.radius) - radius).abs() < 1e-6,
            "{file}: radius {} vs {radius}",
            scene.radius
        );
    }
    assert_eq!(
        Scene::builtin("bunny").unwrap().mesh,
        Scene::from_obj(asset("bunny.obj.gz")).unwrap().mesh
    );
    assert_eq!(Scene::builtin("teapot").unwrap().mesh.triangle_count(), 992);
}

#[test]
fn obj_keeps_file_order_like_the_reference() {
    // The first bunny vertex and triangle, as in the file (oit.py keeps file order).
    let mesh = load_obj(asset("bunny.obj.gz")).unwrap();
    assert_eq!(mesh.positions[0].to_array(), [1.3019, 0.122622, 2.55006]);
    let text = String::from_utf8(gunzip(&std::fs::read(asset("bunny.obj.gz")).unwrap())).unwrap();
    let first_face: Vec<u32> = text
        .lines()
        .find(|l| l.starts_with("f "))
        .unwrap()
        .split_whitespace()
        .skip(1)
        .map(|s| s.parse::<u32>().unwrap() - 1)
        .collect();
    assert_eq!(mesh.indices[0].to_vec(), first_face);
}

#[test]
fn content_hash_is_sha256_of_the_raw_bytes() {
    assert_eq!(
        content_hash(b"abc"),
        "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
    );
    let bytes = std::fs::read(asset("teapot.obj.gz")).unwrap();
    let (_, hash) = load_obj_with_hash(asset("teapot.obj.gz")).unwrap();
    assert_eq!(hash, content_hash(&bytes));
}

// ------------------------------------------------------------------------------ OBJ forms

#[test]
fn obj_face_forms_polygons_and_relative_indices() {
    let v = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 1.5 0\nvt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\n";
    let tris = |body: &str| parse(&format!("{v}{body}")).unwrap().indices;
    assert_eq!(tris("f 1 2 3\n"), vec![[0, 1, 2]]);
    assert_eq!(tris("f 1/1/1 2/2/1 3/3/1\n"), vec![[0, 1, 2]]);
    assert_eq!(tris("f 1//1 2//1 3//1\n"), vec![[0, 1, 2]]);
    assert_eq!(tris("f 1/1 2/2 3/3\n"), vec![[0, 1, 2]]);
    // Relative indices: -1 is the last vertex defined so far.
    assert_eq!(
        tris("f -5 -4 -3\nf -1/-1/-1 -2/-2/-1 -3/-3/-1\n"),
        vec![[0, 1, 2], [4, 3, 2]]
    );
    // Polygons as fans (v0, vi, vi+1), as oit.py triangulates them.
    assert_eq!(tris("f 1 2 3 4 5\n"), vec![[0, 1, 2], [0, 2, 3], [0, 3, 4]]);
    assert_eq!(tris("f 1 2 3 4\n"), vec![[0, 1, 2], [0, 2, 3]]);
    // Points and lines are not surfaces; groups, materials, comments are ignored.
    assert_eq!(
        tris("o a\ng b\nusemtl m\nmtllib x.mtl\ns 1\n# c\nl 1 2 3\nf 1 2\nf 3\nf 1 2 3\n"),
        vec![[0, 1, 2]]
    );
    // Unreferenced vertices are kept (they count in the bounds, as in oit.py).
    assert_eq!(parse(&format!("{v}f 1 2 3\n")).unwrap().positions.len(), 5);
    // Forward references are allowed (tobj and oit.py allow them).
    assert_eq!(
        parse("f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n")
            .unwrap()
            .indices,
        vec![[0, 1, 2]]
    );
    // CRLF, BOM, w, vertex colours.
    let m = parse("\u{feff}v 0 0 0\r\nv 2 0 0 2\r\nv 0 1 0 0.5 0.5 0.5\r\nf 1 2 3\r\n").unwrap();
    assert_eq!(m.positions[1].x, 1.0);
    assert_eq!(m.positions.len(), 3);
}

#[test]
fn obj_plain_and_gzip_are_detected_by_content() {
    let text = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    let plain = parse_obj_bytes(text).unwrap();
    assert_eq!(parse_obj_bytes(&gzip(text)).unwrap(), plain);
    // A gzip file without .gz, a plain file without .obj.
    assert_eq!(
        load_obj(temp_file("model.bin", &gzip(text))).unwrap(),
        plain
    );
    assert_eq!(load_obj(temp_file("model.txt", text)).unwrap(), plain);
    // Concatenated gzip members (what `cat a.gz b.gz` gives) are one stream.
    let mut two = gzip(b"v 0 0 0\nv 1 0 0\n");
    two.extend(gzip(b"v 0 1 0\nf 1 2 3\n"));
    assert_eq!(parse_obj_bytes(&two).unwrap(), plain);
}

// ------------------------------------------------------------------------------ OBJ errors

#[test]
fn obj_errors_are_typed_and_say_where() {
    let missing = Path::new("/nonexistent/dir/model.obj");
    let err = load_obj(missing).unwrap_err();
    assert!(matches!(err, SceneError::NotFound { .. }), "{err}");
    assert!(err.to_string().contains("model.obj"), "{err}");

    let err = load_obj(temp_file("plain.obj.gz", b"v 0 0 0\n")).unwrap_err();
    assert!(matches!(err, SceneError::NotGzip { .. }), "{err}");

    let gz = std::fs::read(asset("teapot.obj.gz")).unwrap();
    for cut in [3, 10, gz.len() / 2, gz.len() - 4] {
        let err = parse_obj_bytes(&gz[..cut]).unwrap_err();
        assert!(
            matches!(err, SceneError::CorruptGzip { .. }),
            "cut {cut}: {err}"
        );
    }
    let mut flipped = gz.clone();
    flipped[gz.len() / 2] ^= 0x55;
    assert!(matches!(
        parse_obj_bytes(&flipped),
        Err(SceneError::CorruptGzip { .. })
    ));

    let err = parse("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n").unwrap_err();
    assert!(
        matches!(
            err,
            SceneError::NonFiniteVertex {
                line: 2,
                vertex: 2,
                ..
            }
        ),
        "{err}"
    );
    for bad in ["v inf 0 0", "v 0 1e39 0", "v 1 2 3 1e-45"] {
        let err = parse(&format!("v 0 0 0\n{bad}\nv 0 1 0\nf 1 2 3\n")).unwrap_err();
        assert!(
            matches!(err, SceneError::NonFiniteVertex { line: 2, .. }),
            "{bad}: {err}"
        );
    }

    let err = parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99\n").unwrap_err();
    assert!(
        matches!(
            err,
            SceneError::FaceIndexOutOfRange {
                line: 4,
                index: 99,
                vertices: 3,
                ..
            }
        ),
        "{err}"
    );
    assert!(
        err.to_string().contains(":4:") && err.to_string().contains("99"),
        "{err}"
    );
    for (bad, index) in [
        ("f 0 1 2", 0),
        ("f 1 2 -4", -4),
        ("f 1 2 -99999999999999", -99999999999999),
        ("f 1 2 4294967296", 4294967296),
    ] {
        let err = parse(&format!("v 0 0 0\nv 1 0 0\nv 0 1 0\n{bad}\n")).unwrap_err();
        assert!(
            matches!(err, SceneError::FaceIndexOutOfRange { index: i, .. } if i == index),
            "{bad}: {err}"
        );
    }
    // A relative index counts only the vertices defined before its line.
    let err = parse("v 0 0 0\nv 1 0 0\nf -1 -2 -3\nv 0 1 0\n").unwrap_err();
    assert!(
        matches!(
            err,
            SceneError::FaceIndexOutOfRange {
                line: 3,
                index: -3,
                vertices: 2,
                ..
            }
        ),
        "{err}"
    );

    for (bad, line) in [
        ("v 0 0\n", 1),
        ("v 0 0 0\nv 0 x 0\n", 2),
        ("v 0 0 0 1 1\n", 1),
        ("v 0 0 0 0\n", 1),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 three\n", 4),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/x 2 3\n", 4),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1/1/1 2 3\n", 4),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf /1 2 3\n", 4),
    ] {
        let err = parse(bad).unwrap_err();
        assert!(
            matches!(err, SceneError::MalformedObj { line: l, .. } if l == line),
            "{bad:?}: {err}"
        );
    }

    for empty in [
        "",
        "# nothing\n",
        "v 0 0 0\nv 1 0 0\n",
        "v 0 0 0\nv 1 0 0\nf 1 2\n",
    ] {
        assert!(
            matches!(parse(empty), Err(SceneError::EmptyMesh { .. })),
            "{empty:?}"
        );
    }
    // A mesh whose vertices all coincide cannot be framed.
    assert!(matches!(
        Scene::from_mesh("dot", parse("v 1 1 1\nf 1 1 1\n").unwrap()),
        Err(SceneError::DegenerateMesh { .. })
    ));
}

#[test]
fn obj_never_panics_on_truncated_or_mutated_input() {
    let text = gunzip(&std::fs::read(asset("teapot.obj.gz")).unwrap());
    // Truncated anywhere (mid-number, mid-line): a mesh or an error, never a panic.
    for cut in (0..text.len())
        .step_by(97)
        .chain(text.len() - 200..text.len())
    {
        let _ = parse_obj_bytes(&text[..cut]);
    }
    let mut rng = SplitMix64::new(99);
    // Garbage.
    for len in [1, 2, 10, 100, 1000, 10_000] {
        let bytes: Vec<u8> = (0..len).map(|_| rng.next_u64() as u8).collect();
        assert!(parse_obj_bytes(&bytes).is_err());
        let mut gz = vec![0x1f, 0x8b];
        gz.extend(&bytes);
        assert!(parse_obj_bytes(&gz).is_err());
    }
    // OBJ-shaped garbage: random lines of keywords and numbers.
    let words = [
        "v",
        "f",
        "vt",
        "vn",
        "o",
        "g",
        "l",
        "#",
        "1",
        "-1",
        "0",
        "2/3",
        "1//2",
        "-9223372036854775808",
        "nan",
        "1e40",
        "/",
        "//",
        "\u{feff}",
        "é",
        "\t",
    ];
    for _ in 0..3000 {
        let mut s = String::new();
        for _ in 0..rng.below(12) {
            s.push_str(words[rng.below(words.len() as u64) as usize]);
            s.push(if rng.below(4) == 0 { '\n' } else { ' ' });
        }
        let _ = parse(&s);
    }
    // Byte mutations of a real file.
    let small = &text[..text.len().min(4000)];
    for _ in 0..2000 {
        let mut bytes = small.to_vec();
        for _ in 0..1 + rng.below(8) {
            let i = rng.below(bytes.len() as u64) as usize;
            bytes[i] = rng.next_u64() as u8;
        }
        let _ = parse_obj_bytes(&bytes);
    }
}

// ------------------------------------------------------------------------------ camera

/// Row-major matrices printed by `oit.camera(...)[0]` (numpy, float64).
type Rows = [[f64; 4]; 4];

/// `oit.camera`'s arguments (radius, azimuth, elevation, width, height, fovy, fill).
type CameraArgs = (f64, f64, f64, u32, u32, f64, f64);

/// (arguments, matrix, (distance, near, far)).
fn reference_cameras() -> Vec<(CameraArgs, Rows, (f64, f64, f64))> {
    vec![
        (
            (0.8660254037844386, 0.0, 0.0, 512, 512, 60.0, 0.8),
            [
                [1.7320508075688774, 0.0, 0.0, 0.0],
                [0.0, 1.7320508075688774, 0.0, 0.0],
                [0.0, 0.0, -2.339064861882205, 0.8664218974218656],
                [0.0, 0.0, -1.0, 2.065338955232288],
            ],
            (2.065338955232288, 1.187320415933371, 2.960678002606894),
        ),
        (
            (0.75, 30.0, 20.0, 640, 480, 60.0, 0.8),
            [
                [
                    1.1250000000000002,
                    0.0,
                    -0.649519052838329,
                    3.925816070913635e-17,
                ],
                [
                    -0.2961981327260238,
                    1.6275953626987476,
                    -0.5130302149885032,
                    -1.2793773677544738e-17,
                ],
                [
                    -1.0990009951251591,
                    -0.8000072993089875,
                    -1.9035255611255322,
                    0.7503433735624516,
                ],
                [
                    -0.46984631039295416,
                    -0.3420201433256687,
                    -0.8137976813493738,
                    1.7886360026567734,
                ],
            ],
            (1.7886360026567731, 1.0282496426302055, 2.5640223626833407),
        ),
        (
            // Near the pole: the `up` special case.
            (1.2, -135.0, 89.95, 300, 500, 45.0, 0.6),
            [
                [
                    -2.8451779686442458,
                    0.0,
                    2.845177968644246,
                    4.439459362288698e-19,
                ],
                [
                    1.70710613116851,
                    0.0021067985080824568,
                    1.7071061311685098,
                    3.087969886760181e-18,
                ],
                [
                    0.003924008892520823,
                    -6.359127000976474,
                    0.003924008892520823,
                    1.2050540145686668,
                ],
                [
                    0.0006170669964236504,
                    -0.9999996192282494,
                    0.0006170669964236503,
                    8.136356763691522,
                ],
            ],
            (8.136356763691522, 6.866993196054606, 9.429720331328436),
        ),
        (
            (0.7, 210.0, -60.0, 256, 256, 60.0, 0.8),
            [
                [-1.5, 0.0, 0.8660254037844389, 4.285680677843548e-17],
                [
                    -0.7500000000000002,
                    0.8660254037844389,
                    -1.2990381056766578,
                    -1.9751352901951005e-16,
                ],
                [
                    0.5847662154705515,
                    2.0256895914895288,
                    1.0128447957447646,
                    0.7003204819916204,
                ],
                [
                    0.2500000000000001,
                    0.8660254037844386,
                    0.4330127018922194,
                    1.6693936024796547,
                ],
            ],
            (1.6693936024796547, 0.9596996664548583, 2.393087538504451),
        ),
    ]
}

#[test]
fn camera_matches_oit_py() {
    for ((radius, az, el, w, h, fovy, fill), rows, (distance, near, far)) in reference_cameras() {
        let rig = camera_rig(radius, az, el, w, h, fovy, fill);
        let want = DMat4::from_cols_array_2d(&rows).transpose();
        let diff = (rig.view_proj - want)
            .to_cols_array()
            .iter()
            .fold(0.0f64, |m, d| m.max(d.abs()));
        assert!(
            diff < 1e-12,
            "camera {az} {el}: max diff {diff}\n{:?}",
            rig.view_proj
        );
        assert!(
            (rig.distance - distance).abs() < 1e-12
                && (rig.near - near).abs() < 1e-12
                && (rig.far - far).abs() < 1e-12
        );
        // The f32 matrix is the f64 one rounded, column-major.
        let m32 = fragrace::scene::camera(radius, az, el, w, h, fovy, fill);
        assert_eq!(m32, rig.view_proj.as_mat4());
        assert_eq!(m32.row(3).z, rows[3][2] as f32);
        assert_eq!(m32.row(0).x, rows[0][0] as f32);
        // Through Camera (f32 fields).
        let cam = Camera {
            azimuth: az as f32,
            elevation: el as f32,
            fovy: fovy as f32,
            fill: fill as f32,
            ..Camera::default()
        };
        let vp = cam.view_proj(radius as f32, w, h);
        let diff = (vp - want.as_mat4())
            .to_cols_array()
            .iter()
            .fold(0.0f32, |m, d| m.max(d.abs()));
        assert!(diff < 1e-5, "Camera {cam:?}: {diff}");
    }
}

#[test]
fn camera_frames_the_bounding_sphere() {
    // The eye is on +Z at azimuth 0, on +X at 90; the origin projects to the centre; the
    // bounding sphere's silhouette spans `fill` of the smaller dimension.
    let r = 0.8f64;
    for (az, axis) in [(0.0, DVec3::Z), (90.0, DVec3::X)] {
        let rig = camera_rig(r, az, 0.0, 400, 300, 60.0, 0.8);
        assert!((rig.eye.normalize() - axis).length() < 1e-12);
        let o = rig.view_proj * DVec4::W;
        assert!(o.x.abs() < 1e-12 && o.y.abs() < 1e-12);
        let z = -1.0 + 2.0 * (rig.distance - r) / rig.distance; // inside the near..far range
        assert!(z.is_finite());
        // A point on the silhouette, straight up from the centre as seen from the eye.
        let f = -rig.eye.normalize();
        let up = DVec3::Y;
        let tangent_angle = (r / rig.distance).asin();
        let dir = f * tangent_angle.cos() + up * tangent_angle.sin();
        let p = rig.eye + dir * (rig.distance * tangent_angle.cos());
        let clip = rig.view_proj * p.extend(1.0);
        assert!((clip.y / clip.w - 0.8).abs() < 1e-9, "{}", clip.y / clip.w);
        assert!(clip.z / clip.w > -1.0 && clip.z / clip.w < 1.0);
    }
}

#[test]
fn camera_defaults_and_serde() {
    let cam = Camera::default();
    assert_eq!(
        (cam.azimuth, cam.elevation, cam.fovy, cam.fill),
        (0.0, 0.0, 60.0, 0.8)
    );
    let json = serde_json::to_string(&Camera::new(30.0, 20.0)).unwrap();
    assert_eq!(
        serde_json::from_str::<Camera>(&json).unwrap(),
        Camera::new(30.0, 20.0)
    );
    // Omitted fields take the defaults, so case files can be terse.
    assert_eq!(
        serde_json::from_str::<Camera>(r#"{"azimuth": 45}"#).unwrap(),
        Camera::new(45.0, 0.0)
    );
    // f32 fields widen through their decimal form: fill 0.8 is oit.py's 0.8 exactly.
    let from_f32 = Camera::new(30.0, 20.0).rig(0.75, 640, 480).view_proj;
    let from_f64 = camera_rig(0.75, 30.0, 20.0, 640, 480, 60.0, 0.8).view_proj;
    assert_eq!(from_f32, from_f64);
    // Cameras that cannot frame anything are refused, not turned into NaN matrices.
    assert!(Camera::default().validate(512, 512).is_ok());
    assert!(Camera {
        fill: 2.0,
        ..Camera::default()
    }
    .validate(64, 32)
    .is_ok());
    for (cam, w, h) in [
        (
            Camera {
                fovy: 0.0,
                ..Camera::default()
            },
            8,
            8,
        ),
        (
            Camera {
                fovy: 180.0,
                ..Camera::default()
            },
            8,
            8,
        ),
        (
            Camera {
                fill: 0.0,
                ..Camera::default()
            },
            8,
            8,
        ),
        (
            Camera {
                fill: f32::INFINITY,
                ..Camera::default()
            },
            8,
            8,
        ),
        (
            Camera {
                azimuth: f32::NAN,
                ..Camera::default()
            },
            8,
            8,
        ),
        (Camera::default(), 0, 8),
    ] {
        assert!(
            matches!(cam.validate(w, h), Err(SceneError::BadCamera { .. })),
            "{cam:?} {w}x{h}"
        );
    }
    // Scene::view_proj is the camera's with the scene's radius.
    let scene = Scene::builtin("cubes").unwrap();
    let vp: Mat4 = scene.view_proj(&Camera::default(), 512, 512);
    assert_eq!(vp, Camera::default().view_proj(scene.radius, 512, 512));
}

#[test]
fn prim_color_matches_oit_py() {
    // hash32 and the packed RGBA8 values computed by the reference's formula in numpy.
    for (id, rgb, packed) in [
        (
            0u32,
            [
                0.20000000298023224,
                0.20000000298023224,
                0.20000000298023224,
            ],
            0xff333333u32,
        ),
        (
            1,
            [0.8023529648780823, 0.6517647504806519, 0.6298039555549622],
            0xffa1a6cd,
        ),
        (
            2,
            [0.6047059297561646, 0.30352941155433655, 0.25960785150527954],
            0xff424d9a,
        ),
        (
            12345,
            [0.9749019742012024, 0.9905882477760315, 0.34431374073028564],
            0xff58fdf9,
        ),
        (
            u32::MAX,
            [0.43215686082839966, 0.6078431606292725, 0.5262745022773743],
            0xff869b6e,
        ),
    ] {
        let c = prim_color(id);
        assert_eq!(
            [c[0], c[1], c[2], c[3]],
            [rgb[0] as f32, rgb[1] as f32, rgb[2] as f32, 1.0],
            "{id}"
        );
        assert_eq!(prim_color_rgba8(id), packed, "{id}");
    }
}
