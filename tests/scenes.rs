//! Built-in scenes have the properties their names promise: closed, normalised, pinned bit
//! for bit (case files name them and must replay), deep where they say so.

use std::collections::{HashMap, HashSet};

use fragrace::scene::builtin::{self, SplitMix64};
use fragrace::scene::{builtin_names, content_hash, Camera, Scene, SceneError};
use fragrace_emu::geometry::Mesh;
use glam::{DMat4, DVec3, DVec4};

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
