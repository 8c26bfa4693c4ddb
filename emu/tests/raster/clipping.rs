//! Facing, depth and perspective-correct barycentrics, and clipping: near and far planes,
//! behind the eye, the guard band, and clipped meshes that stay watertight.

use fragrace_emu::raster::*;
use glam::{Mat4, Vec3, Vec4};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

use super::common::*;

/// Outward-facing faces of a convex mesh viewed from outside are front-facing with the
/// default counter-clockwise rule (the icosphere's faces wind counter-clockwise seen from out).
#[test]
fn front_facing_follows_opengl_convention() {
    let v = vp(32, 32);
    // Counter-clockwise in NDC (y up).
    let ccw = [
        Vec4::new(-0.5, -0.5, 0.0, 1.0),
        Vec4::new(0.5, -0.5, 0.0, 1.0),
        Vec4::new(0.0, 0.5, 0.0, 1.0),
    ];
    let cases = [
        (FrontFace::Ccw, [0u32, 1, 2], true),
        (FrontFace::Ccw, [0, 2, 1], false),
        (FrontFace::Cw, [0, 1, 2], false),
        (FrontFace::Cw, [0, 2, 1], true),
    ];
    for (ff, idx, front) in cases {
        for cull in [CullMode::None, CullMode::Back, CullMode::Front] {
            let st = RasterState {
                front_face: ff,
                cull,
                ..RasterState::default()
            };
            let b = bin(&ccw, &[idx], &st, v);
            let frags = all_frags(&b);
            let culled = (cull == CullMode::Back && !front) || (cull == CullMode::Front && front);
            if culled {
                assert!(frags.is_empty() && b.tris.is_empty());
            } else {
                assert!(frags.len() > 50);
                assert_eq!(b.tris.len(), 1);
                assert_eq!(b.tris[0].front_facing, front, "{ff:?} {idx:?}");
            }
        }
    }
    // The sphere: faces towards the camera are front-facing.
    let (verts, faces) = icosphere(1);
    let m = camera(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, 1.0, 0.1, 10.0);
    let pos: Vec<Vec4> = verts.iter().map(|p| m * p.extend(1.0)).collect();
    let b = bin(&pos, &faces, &RasterState::default(), v);
    for t in &b.tris {
        let [a, bb, c] = faces[t.source as usize].map(|i| verts[i as usize]);
        let n = (bb - a).cross(c - a);
        let towards = n.dot(Vec3::new(0.0, 0.0, 3.0) - a) > 0.0;
        assert_eq!(t.front_facing, towards);
    }
}

/// Ray-casting reference for a triangle in eye space: barycentrics and window depth of the
/// point seen through window position (x, y), if the ray hits the triangle's plane.
fn ray_hit(tri: [Vec3; 3], proj: Mat4, v: Viewport, x: f64, y: f64) -> Option<([f64; 3], f64)> {
    let inv = proj.inverse();
    let ndc_x = (x / v.width as f64 * 2.0 - 1.0) as f32;
    let ndc_y = (1.0 - y / v.height as f64 * 2.0) as f32;
    let near = inv * Vec4::new(ndc_x, ndc_y, -1.0, 1.0);
    let far = inv * Vec4::new(ndc_x, ndc_y, 1.0, 1.0);
    let (o, d) = (
        (near / near.w).truncate(),
        (far / far.w).truncate() - (near / near.w).truncate(),
    );
    let [a, b, c] = tri.map(|p| p.as_dvec3());
    let (o, d) = (o.as_dvec3(), d.as_dvec3());
    let n = (b - a).cross(c - a);
    let denom = n.dot(d);
    if denom.abs() < 1e-12 {
        return None;
    }
    let t = n.dot(a - o) / denom;
    let p = o + d * t;
    let area = n.length_squared();
    let w0 = (b - p).cross(c - p).dot(n) / area;
    let w1 = (c - p).cross(a - p).dot(n) / area;
    let w2 = 1.0 - w0 - w1;
    let clip = proj.as_dmat4() * p.extend(1.0);
    Some(([w0, w1, w2], (clip.z / clip.w + 1.0) / 2.0))
}

#[test]
fn perspective_correct_barycentrics_and_linear_depth() {
    let v = vp(128, 96);
    let proj = Mat4::perspective_rh_gl(60f32.to_radians(), 128.0 / 96.0, 0.5, 50.0);
    let mut rng = SmallRng::seed_from_u64(3);
    for _ in 0..20 {
        // A steeply slanted triangle in front of the camera.
        let tri = [0, 1, 2].map(|_| {
            Vec3::new(
                rng.gen_range(-3.0..3.0),
                rng.gen_range(-2.0..2.0),
                -rng.gen_range(1.0..30.0),
            )
        });
        let pos: Vec<Vec4> = tri.iter().map(|p| proj * p.extend(1.0)).collect();
        let b = bin(&pos, &[[0, 1, 2]], &state(X1), v);
        for f in all_frags(&b) {
            let t = &b.tris[f.tri as usize];
            let (x, y) = (f.x as f32 + 0.5, f.y as f32 + 0.5);
            let (bary, depth) = ray_hit(tri, proj, v, x as f64, y as f64).unwrap();
            let got = t.bary_at(x, y);
            for k in 0..3 {
                assert!(
                    (got[k] as f64 - bary[k]).abs() < 2e-3,
                    "bary {got:?} vs {bary:?}"
                );
            }
            assert!(
                (t.depth_at(x, y) as f64 - depth).abs() < 1e-4,
                "depth {} vs {depth}",
                t.depth_at(x, y)
            );
        }
        // Depth is a plane in screen space: second differences vanish.
        if let Some(t) = b.tris.first() {
            let (x, y) = (40.3f32, 30.7f32);
            let d = |dx: f32, dy: f32| t.depth_at(x + dx, y + dy) as f64;
            if (0.0..1.0).contains(&d(0.0, 0.0))
                && d(0.0, 0.0) > 0.0
                && d(2.0, 2.0) < 1.0
                && d(2.0, 2.0) > 0.0
            {
                assert!((d(1.0, 0.0) - d(0.0, 0.0) - (d(2.0, 1.0) - d(1.0, 1.0))).abs() < 1e-6);
            }
        }
    }
}

/// Identical vertices give bit-identical depths and pixels whatever the vertex order.
#[test]
fn identical_vertices_give_identical_depths() {
    let v = vp(64, 64);
    let proj = camera(Vec3::new(0.2, 0.1, 2.0), Vec3::ZERO, 1.0, 0.1, 10.0);
    let p = [
        Vec3::new(-0.7, -0.6, 0.3),
        Vec3::new(0.8, -0.3, -0.5),
        Vec3::new(0.1, 0.9, 0.1),
    ];
    let pos: Vec<Vec4> = p.iter().map(|p| proj * p.extend(1.0)).collect();
    let orders = [
        [0u32, 1, 2],
        [1, 2, 0],
        [2, 0, 1],
        [0, 2, 1],
        [2, 1, 0],
        [1, 0, 2],
    ];
    let b = bin(&pos, &orders, &state(X1), v);
    let mut per: Vec<Vec<(u32, u32, u32)>> = vec![Vec::new(); 6];
    for f in all_frags(&b) {
        let t = &b.tris[f.tri as usize];
        let d = t.depth_at(f.x as f32 + 0.5, f.y as f32 + 0.5);
        per[t.source as usize].push((f.x, f.y, d.to_bits()));
    }
    assert!(per[0].len() > 100);
    for o in &mut per {
        o.sort();
    }
    for k in 1..6 {
        assert_eq!(per[0], per[k], "order {:?}", orders[k]);
    }
}

/// A large floor quad passing beside and behind the eye is clipped at the near plane: the
/// visible part matches ray casting, nothing comes from behind the eye, and the pieces of one
/// clipped triangle never cover a pixel twice.
#[test]
fn near_plane_clipping() {
    let v = vp(80, 60);
    let (near, far) = (0.5, 100.0);
    let proj = Mat4::perspective_rh_gl(70f32.to_radians(), 80.0 / 60.0, near, far);
    let view = Mat4::look_at_rh(Vec3::new(0.0, 1.0, 0.0), Vec3::new(0.3, 0.6, -5.0), Vec3::Y);
    // Floor y = 0 from z = +20 (behind the eye) to z = -40.
    let quad = [
        Vec3::new(-30.0, 0.0, 20.0),
        Vec3::new(30.0, 0.0, 20.0),
        Vec3::new(30.0, 0.0, -40.0),
        Vec3::new(-30.0, 0.0, -40.0),
    ];
    let eye: Vec<Vec3> = quad.iter().map(|p| view.transform_point3(*p)).collect();
    let pos: Vec<Vec4> = eye.iter().map(|p| proj * p.extend(1.0)).collect();
    let idx = [[0u32, 1, 2], [0, 2, 3]];
    let b = bin(&pos, &idx, &state(X1), v);
    assert_eq!(b.rejected, 0);
    let frags = all_frags(&b);
    assert_no_duplicates(&b, &frags);
    let counts = sample_counts(&frags, 1);
    let mut checked = 0;
    for y in 0..v.height {
        for x in 0..v.width {
            let (cx, cy) = (x as f64 + 0.5, y as f64 + 0.5);
            let got = counts.get(&(x, y, 0)).copied().unwrap_or(0);
            assert!(got <= 1, "pixel ({x},{y}) covered {got} times");
            // Reference: hit the floor plane in front of the near plane, inside the quad.
            let hit = ray_hit([eye[0], eye[1], eye[2]], proj, v, cx, cy);
            let Some((_, depth)) = hit else { continue };
            let inv = proj.inverse();
            let ndc = Vec4::new(
                (cx / 40.0 - 1.0) as f32,
                (1.0 - cy / 30.0) as f32,
                (depth * 2.0 - 1.0) as f32,
                1.0,
            );
            let e = inv * ndc;
            let e = e.truncate() / e.w;
            let w = view.inverse().transform_point3(e);
            let visible =
                (0.0..=1.0).contains(&depth) && w.x.abs() < 30.0 && w.z < 20.0 && w.z > -40.0;
            // Skip samples within a small distance of the far/near boundary of visibility.
            if (depth - 1.0).abs() < 1e-3 || depth.abs() < 1e-3 {
                continue;
            }
            assert_eq!(got, u32::from(visible), "pixel ({x},{y}) depth {depth}");
            checked += 1;
        }
    }
    assert!(checked > 3000);
    // Every fragment's depth is in range and the barycentrics are of the source triangle.
    for f in &frags {
        let t = &b.tris[f.tri as usize];
        let (x, y) = (f.x as f32 + 0.5, f.y as f32 + 0.5);
        let d = t.depth_at(x, y);
        assert!((0.0..=1.0).contains(&d));
        // The pixel-centre form kernels read (`Fragment::depth`) is the same bits.
        assert_eq!(t.depth_at_center(f.x, f.y).to_bits(), d.to_bits());
        let src = idx[t.source as usize].map(|i| eye[i as usize]);
        let (want, wd) = ray_hit(src, proj, v, x as f64, y as f64).unwrap();
        let got = t.bary_at(x, y);
        for k in 0..3 {
            assert!(
                (got[k] as f64 - want[k]).abs() < 5e-3,
                "{got:?} vs {want:?}"
            );
        }
        assert!((d as f64 - wd).abs() < 1e-3, "depth {d} vs {wd}");
    }
    // Clipping produced more setup triangles than sources.
    assert!(b.tris.len() > 2);
}

/// Triangles crossing the far plane are clipped there; triangles entirely behind the eye or
/// beyond the far plane produce nothing.
#[test]
fn far_plane_and_behind_the_eye() {
    let v = vp(32, 32);
    // NDC z from -0.5 to 3 (beyond far) along x, w = 1.
    let pos = [
        Vec4::new(-0.9, -0.9, -0.5, 1.0),
        Vec4::new(0.9, -0.9, 3.0, 1.0),
        Vec4::new(-0.9, 0.9, -0.5, 1.0),
    ];
    let b = bin(&pos, &[[0, 1, 2]], &state(X1), v);
    let frags = all_frags(&b);
    assert!(!frags.is_empty());
    for f in &frags {
        let d = b.tris[f.tri as usize].depth_at(f.x as f32 + 0.5, f.y as f32 + 0.5);
        assert!(d <= 1.0);
        // z_win = (z_ndc + 1) / 2 with z_ndc = -0.5 + 3.5 * (x_ndc + 0.9) / 1.8 roughly; the
        // far plane z_ndc = 1 is at x_ndc = -0.9 + 1.8 * 1.5 / 3.5.
        let x_ndc = (f.x as f64 + 0.5) / 16.0 - 1.0;
        assert!(
            x_ndc <= -0.9 + 1.8 * 1.5 / 3.5 + 0.07,
            "fragment beyond the far plane at x {}",
            f.x
        );
    }
    // All behind the eye (w < 0) or all in front of the near plane: nothing.
    for p in [
        [
            Vec4::new(-0.5, -0.5, 0.0, -1.0),
            Vec4::new(0.5, -0.5, 0.0, -1.0),
            Vec4::new(0.0, 0.5, 0.0, -1.0),
        ],
        [
            Vec4::new(-0.5, -0.5, -2.0, 1.0),
            Vec4::new(0.5, -0.5, -2.0, 1.0),
            Vec4::new(0.0, 0.5, -3.0, 1.0),
        ],
        [
            Vec4::new(-0.5, -0.5, 0.0, 0.0),
            Vec4::new(0.5, -0.5, 0.0, 0.0),
            Vec4::new(0.0, 0.5, 0.0, 0.0),
        ],
    ] {
        let b = bin(&p, &[[0, 1, 2]], &state(X1), v);
        assert!(all_frags(&b).is_empty());
        assert_eq!(b.rejected, 0);
    }
}

/// Huge triangles (vertices far outside the screen, beyond the guard band) forming a quad
/// cover every pixel of the viewport exactly once.
#[test]
fn guard_band_and_huge_triangles() {
    let v = vp(50, 40);
    for s in [1.0f32, 1e3, 1e5, 1e7] {
        let pos = [
            Vec4::new(-s, -s, 0.0, 1.0),
            Vec4::new(s * 1.3, -s, 0.2, 1.0),
            Vec4::new(s * 1.3, s * 0.9, 0.1, 1.0),
            Vec4::new(-s, s * 0.9, -0.1, 1.0),
        ];
        let b = bin(&pos, &[[0, 1, 2], [0, 2, 3]], &state(X1), v);
        let frags = all_frags(&b);
        let counts = sample_counts(&frags, 1);
        if s == 1.0 {
            continue; // does not cover the whole screen
        }
        assert_eq!(counts.len(), (v.width * v.height) as usize, "scale {s}");
        assert!(counts.values().all(|&n| n == 1), "scale {s}");
        for f in &frags {
            let d = b.tris[f.tri as usize].depth_at(f.x as f32 + 0.5, f.y as f32 + 0.5);
            assert!((0.0..=1.0).contains(&d));
        }
    }
}

/// A perspective grid crossing the near plane (many clipped triangles sharing clipped edges)
/// stays watertight: each sample at most once, and every sample whose ray meets the visible
/// floor (checked by ray casting, away from the near and far planes) is covered.
#[test]
fn clipped_mesh_stays_watertight() {
    let v = vp(64, 64);
    let proj = Mat4::perspective_rh_gl(90f32.to_radians(), 1.0, 1.0, 100.0);
    let view = Mat4::look_at_rh(Vec3::new(0.0, 0.5, 0.0), Vec3::new(0.0, 0.2, -3.0), Vec3::Y);
    let n = 24;
    let mut world = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            world.push(Vec3::new(
                -6.0 + 12.0 * i as f32 / n as f32,
                0.0,
                6.0 - 12.0 * j as f32 / n as f32,
            ));
        }
    }
    let eye: Vec<Vec3> = world.iter().map(|p| view.transform_point3(*p)).collect();
    let pos: Vec<Vec4> = eye.iter().map(|p| proj * p.extend(1.0)).collect();
    let mut idx = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let at = |i: usize, j: usize| (j * (n + 1) + i) as u32;
            idx.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            idx.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    let plane = [eye[0], eye[n], eye[(n + 1) * (n + 1) - 1]];
    for samples in [SampleCount::X1, SampleCount::X8] {
        let b = bin(&pos, &idx, &state(samples), v);
        assert!(!b.tris.is_empty());
        let frags = all_frags(&b);
        assert_no_duplicates(&b, &frags);
        let counts = sample_counts(&frags, samples.count());
        assert!(counts.values().all(|&c| c == 1), "a sample covered twice");
        let mut checked = 0;
        for y in 0..64 {
            for x in 0..64 {
                for (s, &(sx, sy)) in samples.positions().iter().enumerate() {
                    let (cx, cy) = (x as f64 + sx as f64, y as f64 + sy as f64);
                    let Some((_, depth)) = ray_hit(plane, proj, v, cx, cy) else {
                        continue;
                    };
                    let ndc = Vec4::new(
                        (cx / 32.0 - 1.0) as f32,
                        (1.0 - cy / 32.0) as f32,
                        (depth * 2.0 - 1.0) as f32,
                        1.0,
                    );
                    let e = proj.inverse() * ndc;
                    let w = view.inverse().transform_point3(e.truncate() / e.w);
                    if depth > 0.01 && depth < 0.99 && w.x.abs() < 5.9 && w.z.abs() < 5.9 {
                        assert_eq!(
                            counts.get(&(x, y, s)),
                            Some(&1),
                            "hole at ({x},{y}) sample {s}"
                        );
                        checked += 1;
                    }
                }
            }
        }
        assert!(checked > 500 * samples.count(), "{checked}");
    }
}
