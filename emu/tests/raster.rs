//! Rasterizer tests through the public API: fill rule, watertightness, clipping, depth and
//! perspective-correct barycentrics, MSAA coverage, culling, binning invariance.
use fragrace_emu::raster::*;
use glam::{Mat4, Vec3, Vec4};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use std::collections::HashMap;

const X1: SampleCount = SampleCount::X1;

fn vp(w: u32, h: u32) -> Viewport {
    Viewport {
        width: w,
        height: h,
    }
}

/// Small tiles (8 pixels) so that the small test scenes straddle many tile borders.
fn state(samples: SampleCount) -> RasterState {
    RasterState {
        samples,
        tile_size: 8,
        ..RasterState::default()
    }
}

/// Clip-space position (w = 1) of a window position in pixels (y down).
fn px(x: f64, y: f64, v: Viewport) -> Vec4 {
    Vec4::new(
        (x / v.width as f64 * 2.0 - 1.0) as f32,
        (1.0 - y / v.height as f64 * 2.0) as f32,
        0.0,
        1.0,
    )
}

/// Every fragment of every tile, in tile order.
fn all_frags(b: &Binned) -> Vec<Fragment> {
    let mut out = Vec::new();
    for t in 0..b.tile_count() {
        b.raster_tile(t, |f| out.push(f));
    }
    out
}

fn bin(pos: &[Vec4], idx: &[[u32; 3]], st: &RasterState, v: Viewport) -> Binned {
    bin_triangles(pos, idx, st, v, 2)
}

/// Per-sample coverage count: `(x, y, sample) -> count`.
fn sample_counts(frags: &[Fragment], n: usize) -> HashMap<(u32, u32, usize), u32> {
    let mut m = HashMap::new();
    for f in frags {
        for s in 0..n {
            if f.coverage & (1 << s) != 0 {
                *m.entry((f.x, f.y, s)).or_insert(0) += 1;
            }
        }
    }
    m
}

/// Fragments of one source triangle must never repeat a pixel.
fn assert_no_duplicates(b: &Binned, frags: &[Fragment]) {
    let mut seen = HashMap::new();
    for f in frags {
        let src = b.tris[f.tri as usize].source;
        assert!(
            seen.insert((src, f.x, f.y), ()).is_none(),
            "duplicate fragment of source {src} at ({}, {})",
            f.x,
            f.y
        );
    }
}

/// The window-space fixed-point snap the rasterizer documents: round((ndc + 1) / 2 * W * 256).
fn snap(p: Vec4, v: Viewport) -> [i64; 2] {
    let (x, y, w) = (p.x as f64, p.y as f64, p.w as f64);
    let iw = 1.0 / w;
    let fx = (x * iw + 1.0) * v.width as f64 * 128.0;
    let fy = (1.0 - y * iw) * v.height as f64 * 128.0;
    [(fx + 0.5).floor() as i64, (fy + 0.5).floor() as i64]
}

/// Independent brute-force reference: coverage of pixel (x, y) by a triangle (no clipping).
fn reference_mask(t: [[i64; 2]; 3], x: u32, y: u32, samples: SampleCount) -> u8 {
    let area =
        (t[1][0] - t[0][0]) * (t[2][1] - t[0][1]) - (t[1][1] - t[0][1]) * (t[2][0] - t[0][0]);
    if area == 0 {
        return 0;
    }
    let t = if area > 0 { t } else { [t[0], t[2], t[1]] };
    let mut m = 0;
    for (s, &(sx, sy)) in samples.positions().iter().enumerate() {
        let p = [
            x as i64 * 256 + (sx * 256.0) as i64,
            y as i64 * 256 + (sy * 256.0) as i64,
        ];
        let inside = (0..3).all(|i| {
            let (a, b) = (t[i], t[(i + 1) % 3]);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let e = dx * (p[1] - a[1]) - dy * (p[0] - a[0]);
            // y-down screen: top edge = horizontal with the interior below; left = dy < 0.
            e > 0 || (e == 0 && (dy < 0 || (dy == 0 && dx > 0)))
        });
        m |= u8::from(inside) << s;
    }
    m
}

#[test]
fn sample_positions_are_the_standard_ones() {
    assert_eq!(SampleCount::X1.positions(), &[(0.5, 0.5)]);
    assert_eq!(SampleCount::X2.positions(), &[(0.75, 0.75), (0.25, 0.25)]);
    let p4: Vec<(i32, i32)> = SampleCount::X4
        .positions()
        .iter()
        .map(|&(x, y)| ((x * 16.0) as i32 - 8, (y * 16.0) as i32 - 8))
        .collect();
    assert_eq!(p4, vec![(-2, -6), (6, -2), (-6, 2), (2, 6)]);
    let p8: Vec<(i32, i32)> = SampleCount::X8
        .positions()
        .iter()
        .map(|&(x, y)| ((x * 16.0) as i32 - 8, (y * 16.0) as i32 - 8))
        .collect();
    assert_eq!(
        p8,
        vec![
            (1, -3),
            (-1, 3),
            (5, 1),
            (-3, -5),
            (-5, 5),
            (-7, -1),
            (3, 7),
            (7, -7)
        ]
    );
    for s in [
        SampleCount::X1,
        SampleCount::X2,
        SampleCount::X4,
        SampleCount::X8,
    ] {
        assert_eq!(s.positions().len(), s.count());
    }
}

/// A rectangle whose corners are pixel centres: the top and left edges (through pixel
/// centres) are included, the bottom and right edges excluded, for both diagonals and windings.
#[test]
fn fill_rule_on_rectangle_through_pixel_centres() {
    let v = vp(16, 16);
    let (x0, y0, x1, y1) = (2.5, 3.5, 10.5, 9.5);
    let c = [px(x0, y0, v), px(x1, y0, v), px(x1, y1, v), px(x0, y1, v)];
    let quads: [[[u32; 3]; 2]; 4] = [
        [[0, 1, 2], [0, 2, 3]],
        [[0, 2, 1], [0, 3, 2]],
        [[1, 2, 3], [1, 3, 0]],
        [[1, 3, 2], [1, 0, 3]],
    ];
    for idx in quads {
        let b = bin(&c, &idx, &state(X1), v);
        let frags = all_frags(&b);
        let counts = sample_counts(&frags, 1);
        for y in 0..16 {
            for x in 0..16 {
                let want = u32::from((2..10).contains(&x) && (3..9).contains(&y));
                assert_eq!(
                    counts.get(&(x, y, 0)).copied().unwrap_or(0),
                    want,
                    "pixel ({x},{y}) for {idx:?}"
                );
            }
        }
    }
}

/// Single triangles with edges through pixel centres: horizontal top edge included,
/// horizontal bottom edge excluded, left edge included, right edge excluded.
#[test]
fn fill_rule_single_triangle_edges() {
    let v = vp(16, 16);
    // Right triangle: top edge y=2.5 (x 2.5..10.5), left edge x=2.5 (y 2.5..10.5), hypotenuse.
    let p = [px(2.5, 2.5, v), px(10.5, 2.5, v), px(2.5, 10.5, v)];
    for idx in [[0u32, 1, 2], [0, 2, 1]] {
        let b = bin(&p, &[idx], &state(X1), v);
        let set: Vec<(u32, u32)> = all_frags(&b).iter().map(|f| (f.x, f.y)).collect();
        assert!(
            set.contains(&(2, 2)),
            "top-left corner on a centre: top and left edges"
        );
        assert!(set.contains(&(5, 2)), "top edge");
        assert!(set.contains(&(2, 6)), "left edge");
        // Hypotenuse x + y = 13 (in centres: (x+0.5)+(y+0.5)=13): a bottom-right edge, excluded.
        assert!(
            !set.contains(&(6, 6)),
            "hypotenuse through (6.5, 6.5) is a right edge"
        );
        assert!(set.contains(&(6, 5)));
        assert!(
            !set.contains(&(10, 2)),
            "vertex (10.5, 2.5) on a centre, on the hypotenuse"
        );
    }
    // Flat-bottom triangle: bottom edge y=9.5 excluded, apex on top.
    let p = [px(6.5, 1.5, v), px(12.5, 9.5, v), px(0.5, 9.5, v)];
    let b = bin(&p, &[[0, 1, 2]], &state(X1), v);
    let ys: Vec<u32> = all_frags(&b).iter().map(|f| f.y).collect();
    assert!(
        !ys.contains(&1),
        "apex on a centre: on the right edge, so excluded"
    );
    assert!(!ys.contains(&9), "bottom edge excluded");
    assert!(ys.contains(&8));
}

/// A grid mesh over `rect` (pixels) with jittered interior vertices, some moved exactly onto
/// pixel centres or the 1/16 sample grid, random diagonals and random windings; the diagonal
/// is chosen so that no triangle folds over (the mesh tiles the rectangle exactly).
fn jittered_grid(
    rng: &mut SmallRng,
    v: Viewport,
    n: usize,
    rect: (f64, f64, f64, f64),
) -> (Vec<Vec4>, Vec<[u32; 3]>) {
    let (x0, y0, x1, y1) = rect;
    let cell = ((x1 - x0) / n as f64).min((y1 - y0) / n as f64);
    let mut xy = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let mut x = x0 + (x1 - x0) * i as f64 / n as f64;
            let mut y = y0 + (y1 - y0) * j as f64 / n as f64;
            if i > 0 && i < n && j > 0 && j < n {
                x += rng.gen_range(-0.25..0.25) * cell;
                y += rng.gen_range(-0.25..0.25) * cell;
                let (sx, sy) = match rng.gen_range(0..4) {
                    0 => (x.floor() + 0.5, y.floor() + 0.5), // on a pixel centre
                    1 => ((x * 16.0).round() / 16.0, (y * 16.0).round() / 16.0), // on the sample grid
                    _ => (x, y),
                };
                if (sx - x).abs().max((sy - y).abs()) < 0.1 * cell {
                    (x, y) = (sx, sy);
                }
            }
            xy.push((x, y));
        }
    }
    let pos: Vec<Vec4> = xy.iter().map(|&(x, y)| px(x, y, v)).collect();
    let area = |t: [u32; 3]| {
        let [a, b, c] = t.map(|i| xy[i as usize]);
        (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0)
    };
    let mut idx = Vec::new();
    let at = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    for j in 0..n {
        for i in 0..n {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            let diag1 = [[a, b, c], [a, c, d]];
            let diag2 = [[a, b, d], [b, c, d]];
            let ok = |q: &[[u32; 3]; 2]| q.iter().all(|&t| area(t) > 0.0);
            let tris = match (ok(&diag1), ok(&diag2)) {
                (true, true) => {
                    if rng.gen() {
                        diag1
                    } else {
                        diag2
                    }
                }
                (true, false) => diag1,
                (false, true) => diag2,
                _ => panic!("folded quad"),
            };
            for mut t in tris {
                if rng.gen() {
                    t.swap(1, 2);
                }
                idx.push(t);
            }
        }
    }
    (pos, idx)
}

/// A jittered grid mesh that tiles a rectangle exactly: every sample inside is covered exactly
/// once, none outside (vertices often exactly on pixel centres or sample positions).
#[test]
fn grid_mesh_covers_every_sample_exactly_once() {
    let v = vp(64, 48);
    let mut rng = SmallRng::seed_from_u64(1);
    for samples in [
        SampleCount::X1,
        SampleCount::X2,
        SampleCount::X4,
        SampleCount::X8,
    ] {
        for n in [3, 8, 20, 45] {
            let rect = (3.0, 2.0, 61.0, 45.0);
            let (pos, idx) = jittered_grid(&mut rng, v, n, rect);
            let b = bin(&pos, &idx, &state(samples), v);
            let frags = all_frags(&b);
            let counts = sample_counts(&frags, samples.count());
            for y in 0..v.height {
                for x in 0..v.width {
                    for (s, &(sx, sy)) in samples.positions().iter().enumerate() {
                        let (fx, fy) = (x as f64 + sx as f64, y as f64 + sy as f64);
                        let inside = fx > rect.0 && fx < rect.2 && fy > rect.1 && fy < rect.3;
                        let got = counts.get(&(x, y, s)).copied().unwrap_or(0);
                        assert_eq!(
                            got,
                            u32::from(inside),
                            "{samples:?} n={n} pixel ({x},{y}) sample {s}"
                        );
                    }
                }
            }
        }
    }
}

/// The same convex polygon fanned from its centre and from a vertex gives the same pixels,
/// each exactly once.
#[test]
fn fans_tile_the_same_polygon() {
    let v = vp(64, 64);
    for k in [5usize, 7, 12, 31] {
        let mut ring = Vec::new();
        for i in 0..k {
            let a = i as f64 / k as f64 * std::f64::consts::TAU + 0.1;
            ring.push(px(32.0 + 25.0 * a.cos(), 31.7 + 22.0 * a.sin(), v));
        }
        let mut pos = ring.clone();
        pos.push(px(30.3, 33.1, v));
        let c = k as u32;
        let fan_centre: Vec<[u32; 3]> = (0..k as u32).map(|i| [c, i, (i + 1) % k as u32]).collect();
        let fan_vertex: Vec<[u32; 3]> = (1..k as u32 - 1).map(|i| [0, i + 1, i]).collect();
        let pixels = |idx: &[[u32; 3]]| {
            let b = bin(&pos, idx, &state(X1), v);
            let mut p: Vec<(u32, u32)> = all_frags(&b).iter().map(|f| (f.x, f.y)).collect();
            p.sort();
            let n = p.len();
            p.dedup();
            assert_eq!(n, p.len(), "a pixel covered twice");
            p
        };
        let a = pixels(&fan_centre);
        assert!(a.len() > 1000);
        assert_eq!(a, pixels(&fan_vertex), "k = {k}");
    }
}

/// Random triangles (no clipping needed) against an independent brute-force rasterizer.
#[test]
fn matches_brute_force_reference() {
    let samples = [SampleCount::X1, SampleCount::X4, SampleCount::X8];
    check_against_reference(2, vp(40, 30), &[0.3, 2.0, 15.0, 60.0], &samples, 400);
}

/// Small one-sample triangles (boxes up to 4x4 pixels) have their coverage computed at
/// setup and are rasterized from it, in every tile they straddle (8-pixel tiles here).
#[test]
fn small_triangles_match_brute_force_reference() {
    check_against_reference(5, vp(48, 40), &[0.4, 0.9, 1.5, 2.2], &[X1], 1500);
}

/// Random triangles of the given sizes (half-extents in pixels, in turn) against
/// [`reference_mask`] on every pixel, for each sample count.
fn check_against_reference(
    seed: u64,
    v: Viewport,
    scales: &[f64],
    sample_counts: &[SampleCount],
    count: u32,
) {
    let mut rng = SmallRng::seed_from_u64(seed);
    for &samples in sample_counts {
        let mut pos = Vec::new();
        let mut idx = Vec::new();
        for t in 0..count {
            let scale = scales[t as usize % scales.len()];
            let (cx, cy) = (
                rng.gen_range(-5.0..v.width as f64 + 5.0),
                rng.gen_range(-5.0..v.height as f64 + 5.0),
            );
            for _ in 0..3 {
                let (mut x, mut y): (f64, f64) = (
                    cx + rng.gen_range(-1.0..1.0) * scale,
                    cy + rng.gen_range(-1.0..1.0) * scale,
                );
                if rng.gen_bool(0.3) {
                    x = (x * 2.0).round() / 2.0;
                    y = (y * 2.0).round() / 2.0;
                }
                pos.push(px(x, y, v));
            }
            idx.push([3 * t, 3 * t + 1, 3 * t + 2]);
        }
        assert_matches_reference(&pos, &idx, samples, v);
    }
}

/// Bins `pos`/`idx` and checks every triangle's coverage of every pixel against the
/// brute-force reference (and that no fragment is emitted twice).
fn assert_matches_reference(pos: &[Vec4], idx: &[[u32; 3]], samples: SampleCount, v: Viewport) {
    let b = bin(pos, idx, &state(samples), v);
    let mut got: HashMap<(u32, u32, u32), u8> = HashMap::new();
    for f in all_frags(&b) {
        let src = b.tris[f.tri as usize].source;
        assert!(got.insert((src, f.x, f.y), f.coverage).is_none());
    }
    for (t, tri) in idx.iter().enumerate() {
        let s = tri.map(|i| snap(pos[i as usize], v));
        for y in 0..v.height {
            for x in 0..v.width {
                let want = reference_mask(s, x, y, samples);
                let have = got.get(&(t as u32, x, y)).copied().unwrap_or(0);
                assert_eq!(have, want, "{samples:?} triangle {t} {s:?} pixel ({x},{y})");
            }
        }
    }
}

fn icosphere(subdiv: usize) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut v: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdiv {
        let mut mid = HashMap::new();
        let mut nf = Vec::new();
        let mut m = |a: u32, b: u32, v: &mut Vec<Vec3>| {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                v.push(((v[a as usize] + v[b as usize]) * 0.5).normalize());
                v.len() as u32 - 1
            })
        };
        for [a, b, c] in f {
            let (ab, bc, ca) = (m(a, b, &mut v), m(b, c, &mut v), m(c, a, &mut v));
            nf.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        f = nf;
    }
    (v, f)
}

fn camera(eye: Vec3, target: Vec3, aspect: f32, near: f32, far: f32) -> Mat4 {
    Mat4::perspective_rh_gl(50f32.to_radians(), aspect, near, far)
        * Mat4::look_at_rh(eye, target, Vec3::Y)
}

/// A closed convex mesh in perspective: every pixel is covered by as many front-facing as
/// back-facing fragments, at most one of each; back-face culling keeps exactly the front ones.
#[test]
fn closed_sphere_is_watertight() {
    let v = vp(96, 80);
    let (verts, faces) = icosphere(3);
    for (k, eye) in [
        Vec3::new(0.3, 0.2, 3.0),
        Vec3::new(-1.7, 0.9, 1.3),
        Vec3::new(0.01, 2.2, 0.02),
    ]
    .iter()
    .enumerate()
    {
        let m = camera(
            *eye,
            Vec3::new(0.05, -0.03, 0.0),
            v.width as f32 / v.height as f32,
            0.1,
            10.0,
        );
        let pos: Vec<Vec4> = verts.iter().map(|p| m * p.extend(1.0)).collect();
        for samples in [SampleCount::X1, SampleCount::X4] {
            let b = bin(&pos, &faces, &state(samples), v);
            let frags = all_frags(&b);
            assert_no_duplicates(&b, &frags);
            let mut front = HashMap::new();
            let mut back = HashMap::new();
            for f in &frags {
                let t = &b.tris[f.tri as usize];
                let map = if t.front_facing {
                    &mut front
                } else {
                    &mut back
                };
                for s in 0..samples.count() {
                    if f.coverage & (1 << s) != 0 {
                        *map.entry((f.x, f.y, s)).or_insert(0u32) += 1;
                    }
                }
            }
            assert!(front.len() > 500, "view {k}");
            assert_eq!(front.len(), back.len(), "view {k} {samples:?}");
            for (key, &n) in &front {
                assert_eq!(n, 1, "view {k} {samples:?} front at {key:?}");
                assert_eq!(
                    back.get(key),
                    Some(&1),
                    "view {k} {samples:?} back at {key:?}"
                );
            }
            // Culling back faces leaves exactly the front layer.
            let culled = RasterState {
                cull: CullMode::Back,
                samples,
                ..RasterState::default()
            };
            let b = bin(&pos, &faces, &culled, v);
            let frags = all_frags(&b);
            assert!(frags.iter().all(|f| b.tris[f.tri as usize].front_facing));
            let cf = sample_counts(&frags, samples.count());
            assert_eq!(cf.len(), front.len());
            assert!(cf.values().all(|&n| n == 1));
        }
    }
}

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

/// Two triangles sharing a slanted edge partition every MSAA sample; a vertical edge through
/// pixel centres splits each pixel's samples by the sign of their x offset.
#[test]
fn msaa_coverage_partitions_samples() {
    let v = vp(16, 16);
    for samples in [SampleCount::X2, SampleCount::X4, SampleCount::X8] {
        // Shared slanted edge.
        let pos = [
            px(0.0, 0.0, v),
            px(16.0, 0.0, v),
            px(16.0, 16.0, v),
            px(0.0, 16.0, v),
            px(3.3, 0.0, v),
            px(11.7, 16.0, v),
        ];
        let idx = [[0u32, 4, 5], [0, 5, 3], [4, 1, 2], [4, 2, 5]];
        let b = bin(&pos, &idx, &state(samples), v);
        let counts = sample_counts(&all_frags(&b), samples.count());
        assert_eq!(counts.len(), 256 * samples.count());
        assert!(counts.values().all(|&c| c == 1));
        // Vertical edge at x = 4.5 (through the centres of column 4).
        let pos = [
            px(0.0, 0.0, v),
            px(4.5, 0.0, v),
            px(4.5, 16.0, v),
            px(0.0, 16.0, v),
            px(16.0, 0.0, v),
            px(16.0, 16.0, v),
        ];
        let left = bin(&pos, &[[0, 1, 2], [0, 2, 3]], &state(samples), v);
        let right = bin(&pos, &[[1, 4, 5], [1, 5, 2]], &state(samples), v);
        let mask = |b: &Binned, x: u32, y: u32| {
            all_frags(b)
                .iter()
                .filter(|f| f.x == x && f.y == y)
                .fold(0u8, |m, f| m | f.coverage)
        };
        let expect: u8 = samples
            .positions()
            .iter()
            .enumerate()
            .filter(|(_, p)| p.0 < 0.5)
            .fold(0, |m, (s, _)| m | 1 << s);
        let all = ((1u32 << samples.count()) - 1) as u8;
        for y in 0..16 {
            assert_eq!(mask(&left, 4, y), expect, "{samples:?}");
            assert_eq!(mask(&right, 4, y), all & !expect, "{samples:?}");
            assert_eq!(mask(&left, 3, y), all);
            assert_eq!(mask(&right, 5, y), all);
        }
    }
    // One sample: the centre on the vertical edge belongs to the right triangle (left edge).
    let pos = [
        px(0.0, 0.0, v),
        px(4.5, 0.0, v),
        px(4.5, 16.0, v),
        px(0.0, 16.0, v),
    ];
    let b = bin(&pos, &[[0, 1, 2], [0, 2, 3]], &state(X1), v);
    assert!(all_frags(&b).iter().all(|f| f.x < 4 && f.coverage == 1));
}

#[test]
fn non_finite_coordinates_are_rejected() {
    let v = vp(32, 32);
    let mut pos = vec![
        Vec4::new(-0.5, -0.5, 0.0, 1.0),
        Vec4::new(0.5, -0.5, 0.0, 1.0),
        Vec4::new(0.0, 0.5, 0.0, 1.0),
    ];
    pos.push(Vec4::new(f32::NAN, 0.0, 0.0, 1.0));
    pos.push(Vec4::new(0.0, f32::INFINITY, 0.0, 1.0));
    pos.push(Vec4::new(0.0, 0.0, 0.0, f32::NEG_INFINITY));
    let idx = [[0u32, 1, 3], [0, 1, 2], [4, 1, 2], [0, 5, 2], [3, 4, 5]];
    for threads in [1, 3] {
        let b = bin_triangles(&pos, &idx, &RasterState::default(), v, threads);
        assert_eq!(b.rejected, 4);
        assert_eq!(b.tris.len(), 1);
        assert_eq!(b.tris[0].source, 1);
        assert!(!all_frags(&b).is_empty());
    }
}

#[test]
fn out_of_range_indices_do_not_panic() {
    let v = vp(32, 32);
    let pos = [
        Vec4::new(-0.5, -0.5, 0.0, 1.0),
        Vec4::new(0.5, -0.5, 0.0, 1.0),
        Vec4::new(0.0, 0.5, 0.0, 1.0),
    ];
    let b = bin(
        &pos,
        &[[0, 1, 7], [0, 1, 2], [u32::MAX, 0, 1]],
        &RasterState::default(),
        v,
    );
    assert_eq!(b.rejected, 2);
    assert_eq!(b.tris.len(), 1);
    let b = bin(&[], &[[0, 1, 2]], &RasterState::default(), v);
    assert_eq!(b.rejected, 1);
    assert!(all_frags(&b).is_empty());
    // No triangles at all.
    let b = bin(&pos, &[], &RasterState::default(), v);
    assert!(b.tris.is_empty() && all_frags(&b).is_empty());
    // Empty viewport.
    let b = bin(&pos, &[[0, 1, 2]], &RasterState::default(), vp(0, 0));
    assert_eq!(b.tile_count(), 0);
    assert!(all_frags(&b).is_empty());
}

#[test]
fn degenerate_triangles_produce_nothing() {
    let v = vp(32, 32);
    let pos = [
        px(2.5, 2.5, v),
        px(20.5, 20.5, v),
        px(11.5, 11.5, v), // collinear with the first two
        px(2.5, 2.5, v),   // duplicate of the first
        px(2.5 + 1.0 / 1024.0, 2.5, v),
    ];
    for samples in [SampleCount::X1, SampleCount::X8] {
        let b = bin(
            &pos,
            &[[0, 1, 2], [0, 3, 1], [0, 4, 3], [2, 2, 2]],
            &state(samples),
            v,
        );
        assert!(all_frags(&b).is_empty());
        assert!(b.tris.is_empty());
        assert_eq!(b.rejected, 0);
    }
}

/// Fragments are only inside the viewport and the tile, in API order, row-major per triangle.
#[test]
fn tiles_scissor_and_order() {
    let v = vp(100, 70);
    let mut rng = SmallRng::seed_from_u64(5);
    let mut pos = Vec::new();
    let mut idx = Vec::new();
    for t in 0..300u32 {
        let (cx, cy) = (rng.gen_range(-20.0..120.0), rng.gen_range(-20.0..90.0));
        let s = rng.gen_range(0.5..40.0);
        for _ in 0..3 {
            pos.push(px(cx + rng.gen_range(-s..s), cy + rng.gen_range(-s..s), v));
        }
        idx.push([3 * t, 3 * t + 1, 3 * t + 2]);
    }
    let st = RasterState {
        tile_size: 16,
        ..RasterState::default()
    };
    let b = bin(&pos, &idx, &st, v);
    assert_eq!((b.tiles_x, b.tiles_y), (7, 5));
    assert_eq!(b.tile_count(), 35);
    assert_eq!(b.tile_rect(6), (96, 0, 100, 16));
    assert_eq!(b.tile_rect(34), (96, 64, 100, 70));
    for w in b.tris.windows(2) {
        assert!(w[0].source <= w[1].source, "setup order follows API order");
    }
    for tile in 0..b.tile_count() {
        let (x0, y0, x1, y1) = b.tile_rect(tile);
        let mut last: Option<Fragment> = None;
        b.raster_tile(tile, |f| {
            assert!(f.x >= x0 && f.x < x1 && f.y >= y0 && f.y < y1);
            if let Some(l) = last {
                assert!(
                    l.tri < f.tri || (l.tri == f.tri && (l.y, l.x) < (f.y, f.x)),
                    "order"
                );
            }
            last = Some(f);
        });
        let listed: Vec<u32> = b.tile_triangles(tile).collect();
        assert!(listed.windows(2).all(|w| w[0] < w[1]));
    }
}

fn frag_set(b: &Binned) -> Vec<(u32, u32, u32, u8)> {
    let mut v: Vec<_> = all_frags(b)
        .iter()
        .map(|f| (f.tri, f.y, f.x, f.coverage))
        .collect();
    v.sort();
    v
}

/// A sphere, a floor through the near plane (clipped pieces) and a dense jittered grid:
/// about 30K triangles, so that up to 7 threads get a chunk each.
fn mixed_scene(v: Viewport) -> (Vec<Vec4>, Vec<[u32; 3]>) {
    let (verts, mut faces) = icosphere(4);
    let m = camera(Vec3::new(0.4, 0.3, 1.6), Vec3::ZERO, 1.5, 0.5, 10.0);
    let mut pos: Vec<Vec4> = verts.iter().map(|p| m * p.extend(1.0)).collect();
    let n = 40;
    let base = pos.len() as u32;
    for j in 0..=n {
        for i in 0..=n {
            let p = Vec3::new(
                -4.0 + 8.0 * i as f32 / n as f32,
                -0.9,
                4.0 - 8.0 * j as f32 / n as f32,
            );
            pos.push(m * p.extend(1.0));
        }
    }
    for j in 0..n as u32 {
        for i in 0..n as u32 {
            let at = |i: u32, j: u32| base + j * (n as u32 + 1) + i;
            faces.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            faces.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    let mut rng = SmallRng::seed_from_u64(21);
    let (gp, gi) = jittered_grid(&mut rng, v, 100, (10.0, 20.0, 290.0, 150.0));
    let base = pos.len() as u32;
    pos.extend(gp);
    faces.extend(gi.iter().map(|t| t.map(|i| i + base)));
    (pos, faces)
}

/// Tile size and thread count change nothing but the tile a fragment comes from.
#[test]
fn tile_sizes_and_threads_give_identical_output() {
    let v = vp(300, 200);
    let (pos, faces) = mixed_scene(v);
    for samples in [SampleCount::X1, SampleCount::X4] {
        let reference = bin_triangles(
            &pos,
            &faces,
            &RasterState {
                tile_size: 64,
                samples,
                ..RasterState::default()
            },
            v,
            1,
        );
        let want = frag_set(&reference);
        assert!(want.len() > 10_000);
        for ts in [8, 16, 32, 64, 128, 256] {
            for threads in [1, 2, 4, 7] {
                let st = RasterState {
                    tile_size: ts,
                    samples,
                    ..RasterState::default()
                };
                let b = bin_triangles(&pos, &faces, &st, v, threads);
                assert_eq!(b.tile_size, ts);
                assert_eq!(b.tris, reference.tris, "ts {ts} threads {threads}");
                let got = frag_set(&b);
                if got != want {
                    let missing: Vec<_> =
                        want.iter().filter(|f| !got.contains(f)).take(5).collect();
                    let extra: Vec<_> = got.iter().filter(|f| !want.contains(f)).take(5).collect();
                    panic!("ts {ts} threads {threads}: {} vs {} fragments, missing {missing:?}, extra {extra:?}", got.len(), want.len());
                }
                // Without planes: the same fragments in the same order, no setup records.
                let bare = bin_triangles_with(&pos, &faces, &st, v, threads, PlaneSetup::Skip);
                assert!(bare.tris.is_empty());
                assert_eq!(bare.setup_count() as usize, b.tris.len());
                assert_eq!(all_frags(&bare), all_frags(&b), "ts {ts} threads {threads}");
                if ts == 64 {
                    // Same tiles: same fragment sequence per tile.
                    for t in 0..b.tile_count() {
                        let (mut a, mut c) = (Vec::new(), Vec::new());
                        b.raster_tile(t, |f| a.push(f));
                        reference.raster_tile(t, |f| c.push(f));
                        assert_eq!(a, c);
                    }
                }
            }
        }
    }
    // Sizes that are not powers of two are rounded up.
    assert_eq!(effective_tile_size(48), 64);
    assert_eq!(effective_tile_size(1), MIN_TILE);
    assert_eq!(effective_tile_size(100_000), MAX_TILE);
}

/// A dense mesh of sub-pixel triangles (the case the fast paths are for) still tiles exactly.
#[test]
fn dense_subpixel_mesh_is_exact() {
    let v = vp(64, 64);
    let mut rng = SmallRng::seed_from_u64(11);
    let (pos, idx) = jittered_grid(&mut rng, v, 250, (1.0, 1.0, 63.0, 63.0));
    for samples in [SampleCount::X1, SampleCount::X2] {
        let b = bin_triangles(&pos, &idx, &state(samples), v, 3);
        let counts = sample_counts(&all_frags(&b), samples.count());
        assert_eq!(counts.len(), 62 * 62 * samples.count());
        assert!(counts.values().all(|&c| c == 1));
        // And against the brute-force reference for a sample of triangles.
        let frags = all_frags(&b);
        let mut got: HashMap<(u32, u32, u32), u8> = HashMap::new();
        for f in frags {
            got.insert((b.tris[f.tri as usize].source, f.x, f.y), f.coverage);
        }
        for t in (0..idx.len()).step_by(97) {
            let s = idx[t].map(|i| snap(pos[i as usize], v));
            for y in 0..64 {
                for x in 0..64 {
                    assert_eq!(
                        got.get(&(t as u32, x, y)).copied().unwrap_or(0),
                        reference_mask(s, x, y, samples)
                    );
                }
            }
        }
    }
}

/// Reads a gzipped OBJ with `gzip -dc` (test-only; the product has its own loader).
/// Centre and radius of the bounding box's circumscribed sphere (`verts` not empty).
fn bounding_sphere(verts: &[Vec3]) -> (Vec3, f32) {
    let (mut lo, mut hi) = (verts[0], verts[0]);
    for p in verts {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    ((lo + hi) * 0.5, (hi - lo).length() * 0.5)
}

fn load_obj_gz(path: &str) -> Option<(Vec<Vec3>, Vec<[u32; 3]>)> {
    let out = std::process::Command::new("gzip")
        .arg("-dc")
        .arg(path)
        .output()
        .ok()?;
    let text = String::from_utf8(out.stdout).ok()?;
    let (mut v, mut f) = (Vec::new(), Vec::new());
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f32> = it.take(3).filter_map(|s| s.parse().ok()).collect();
                v.push(Vec3::new(c[0], c[1], c[2]));
            }
            Some("f") => {
                let c: Vec<u32> = it
                    .take(3)
                    .filter_map(|s| s.split('/').next()?.parse::<u32>().ok())
                    .map(|i| i - 1)
                    .collect();
                f.push([c[0], c[1], c[2]]);
            }
            _ => {}
        }
    }
    (!f.is_empty()).then_some((v, f))
}

/// Best-of-`runs` wall times (ms) of `bin_triangles` and of rasterizing every tile (tiles
/// handed out to `threads` threads), and the fragment count.
fn time_frame(
    pos: &[Vec4],
    idx: &[[u32; 3]],
    v: Viewport,
    threads: usize,
    runs: usize,
) -> (f64, f64, usize) {
    let mut best = (f64::MAX, f64::MAX);
    let mut frags = 0;
    for _ in 0..runs {
        let t0 = std::time::Instant::now();
        let b = bin_triangles(pos, idx, &RasterState::default(), v, threads);
        let t1 = std::time::Instant::now();
        let next = std::sync::atomic::AtomicUsize::new(0);
        let count = std::sync::atomic::AtomicUsize::new(0);
        std::thread::scope(|s| {
            for _ in 0..threads {
                s.spawn(|| {
                    let mut n = 0;
                    loop {
                        let t = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        if t >= b.tile_count() {
                            break;
                        }
                        b.raster_tile(t, |_| n += 1);
                    }
                    count.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
                });
            }
        });
        let t2 = std::time::Instant::now();
        frags = count.into_inner();
        best.0 = best.0.min((t1 - t0).as_secs_f64() * 1e3);
        best.1 = best.1.min((t2 - t1).as_secs_f64() * 1e3);
    }
    (best.0, best.1, frags)
}

/// Timing of the 871K-triangle Stanford dragon at 512x512 (run with
/// `cargo test --release -p fragrace-emu --test raster -- --ignored --nocapture`).
#[test]
#[ignore]
fn time_dragon_512() {
    let path =
        std::env::var("DRAGON").unwrap_or_else(|_| "../../shared/models/dragon.obj.gz".into());
    let Some((verts, faces)) = load_obj_gz(&path) else {
        eprintln!("no mesh at {path}");
        return;
    };
    let (c, r) = bounding_sphere(&verts);
    let m = camera(c + Vec3::new(0.0, 0.0, 2.2 * r), c, 1.0, 0.1 * r, 10.0 * r);
    let pos: Vec<Vec4> = verts.iter().map(|p| m * p.extend(1.0)).collect();
    for threads in [1, 2] {
        let (b, r, n) = time_frame(&pos, &faces, vp(512, 512), threads, 30);
        println!("dragon {} tris, 512x512, {threads} threads: bin {b:.2} ms + raster {r:.2} ms (best of 30), {n} fragments", faces.len());
    }
}

/// Timing of a synthetic 871K-triangle mesh of sub-pixel triangles (a wavy 660x660 grid in
/// perspective, vertices shared) at 512x512.
#[test]
#[ignore]
fn time_synthetic_871k() {
    let n = 660usize;
    let m = camera(Vec3::new(0.0, 0.0, 2.4), Vec3::ZERO, 1.0, 0.1, 10.0);
    let mut pos = Vec::with_capacity((n + 1) * (n + 1));
    for j in 0..=n {
        for i in 0..=n {
            let (u, v) = (
                i as f32 / n as f32 * 2.0 - 1.0,
                j as f32 / n as f32 * 2.0 - 1.0,
            );
            let p = Vec3::new(u, v, 0.15 * (7.0 * u).sin() * (5.0 * v).cos());
            pos.push(m * p.extend(1.0));
        }
    }
    let mut idx = Vec::with_capacity(2 * n * n);
    for j in 0..n as u32 {
        for i in 0..n as u32 {
            let at = |i: u32, j: u32| j * (n as u32 + 1) + i;
            idx.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            idx.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    for threads in [1, 2] {
        let (b, r, f) = time_frame(&pos, &idx, vp(512, 512), threads, 30);
        println!("synthetic {} tris, 512x512, {threads} threads: bin {b:.2} ms + raster {r:.2} ms (best of 30), {f} fragments", idx.len());
    }
}

/// Fingerprints of everything `bin_triangles` produces (setup records, bin entry counts and
/// every fragment in tile order) for the dragon and bunny under many states, views and
/// sizes: run before and after a change to setup to check the output is bit-identical
/// (`cargo test --release -p fragrace-emu --test raster setup_fingerprints -- --ignored --nocapture`).
#[test]
#[ignore]
fn setup_fingerprints() {
    use std::hash::{Hash, Hasher};
    let dir = std::env::var("MODELS").unwrap_or_else(|_| "../../shared/models".into());
    for mesh in ["dragon", "bunny"] {
        let path = format!("{dir}/{mesh}.obj.gz");
        let Some((verts, faces)) = load_obj_gz(&path) else {
            eprintln!("no mesh at {path}");
            continue;
        };
        let (c, r) = bounding_sphere(&verts);
        // Far, near, and an eye inside the bounding box (near-plane and guard-band clipping).
        let views = [
            camera(c + Vec3::new(0.0, 0.0, 2.2 * r), c, 1.0, 0.1 * r, 10.0 * r),
            camera(
                c + Vec3::new(1.1 * r, 0.6 * r, 0.9 * r),
                c,
                1.3,
                0.05 * r,
                10.0 * r,
            ),
            camera(
                c + Vec3::new(0.1 * r, 0.05 * r, 0.2 * r),
                c,
                1.0,
                0.01 * r,
                3.0 * r,
            ),
        ];
        for (k, m) in views.iter().enumerate() {
            let pos: Vec<Vec4> = verts.iter().map(|p| *m * p.extend(1.0)).collect();
            for (size, samples, cull, tile, threads) in [
                (512, SampleCount::X1, CullMode::None, 64, 1),
                (2048, SampleCount::X1, CullMode::None, 64, 2),
                (1000, SampleCount::X1, CullMode::Back, 8, 2),
                (700, SampleCount::X2, CullMode::Front, 32, 1),
                (512, SampleCount::X4, CullMode::None, 256, 2),
                (1536, SampleCount::X8, CullMode::Back, 64, 1),
            ] {
                let st = RasterState {
                    samples,
                    cull,
                    tile_size: tile,
                    front_face: if k == 1 {
                        FrontFace::Cw
                    } else {
                        FrontFace::Ccw
                    },
                    ..RasterState::default()
                };
                let v = vp(size, size * 3 / 4);
                let b = bin_triangles(&pos, &faces, &st, v, threads);
                let mut h = std::collections::hash_map::DefaultHasher::new();
                for t in &b.tris {
                    format!("{t:?}").hash(&mut h);
                }
                let th = h.finish();
                let mut h = std::collections::hash_map::DefaultHasher::new();
                let mut n = 0u64;
                for t in 0..b.tile_count() {
                    b.raster_tile(t, |f| {
                        (f.x, f.y, f.tri, f.coverage).hash(&mut h);
                        n += 1;
                    });
                }
                println!(
                    "{mesh} view {k} {size} {samples:?} {cull:?} tile {tile}: {} tris {th:016x}, {} entries, {} rejected, {n} fragments {:016x}",
                    b.tris.len(),
                    b.bin_entries(),
                    b.rejected,
                    h.finish()
                );
            }
        }
    }
}

/// Slivers reaching far off screen whose on-screen part is a few pixels: their pixel
/// rectangle (clamped to the viewport) is small although their edges are long, so the
/// small-triangle paths must not assume short edges.
#[test]
fn long_offscreen_slivers_match_brute_force_reference() {
    let v = vp(16, 12);
    let mut rng = SmallRng::seed_from_u64(23);
    let mut pos = Vec::new();
    let mut idx = Vec::new();
    for t in 0..3000u32 {
        let far = [1e2, 3e3, 1e5, 9e5][t as usize % 4];
        // One vertex far to the left or above, two near the top-left corner.
        let (fx, fy) = if t % 2 == 0 {
            (-far, rng.gen_range(-1.0..4.0))
        } else {
            (rng.gen_range(-1.0..4.0), -far)
        };
        pos.push(px(fx, fy, v));
        for _ in 0..2 {
            pos.push(px(rng.gen_range(-0.5..4.0), rng.gen_range(-0.5..4.0), v));
        }
        idx.push([3 * t, 3 * t + 1, 3 * t + 2]);
    }
    assert_matches_reference(&pos, &idx, X1, v);
}

/// Unbinned setup ([`Prepared::setup_flat`], chunk by chunk over the whole viewport) gives
/// the binned fragments, with the same setup records, in API order within a chunk and
/// row-major within a triangle, whatever the chunk size.
#[test]
fn unbinned_chunks_give_the_binned_fragments() {
    let v = vp(300, 200);
    let (pos, faces) = mixed_scene(v);
    for (samples, cull) in [
        (SampleCount::X1, CullMode::None),
        (SampleCount::X1, CullMode::Back),
        (SampleCount::X4, CullMode::None),
        (SampleCount::X8, CullMode::Front),
    ] {
        let st = RasterState {
            samples,
            cull,
            tile_size: 16,
            ..RasterState::default()
        };
        let binned = bin_triangles(&pos, &faces, &st, v, 2);
        // (source, y, x, coverage, facing, setup record)
        let mut want: Vec<_> = all_frags(&binned)
            .iter()
            .map(|f| {
                let t = binned.tris[f.tri as usize];
                (f.source, f.y, f.x, f.coverage, f.front_facing, t)
            })
            .collect();
        let by_pixel = |v: &mut Vec<(u32, u32, u32, u8, bool, SetupTriangle)>| {
            v.sort_by_key(|w| (w.0, w.1, w.2));
        };
        by_pixel(&mut want);
        assert!(want.len() > 10_000);
        let prepared = prepare(&pos, &faces, &st, v, 2, PlaneSetup::Compute);
        assert!(prepared.well_formed(1));
        assert_eq!(prepared.triangle_count(), faces.len());
        for chunk_size in [1, 7, 512, faces.len()] {
            let mut got = Vec::new();
            let mut chunk = FlatChunk::default();
            for start in (0..faces.len()).step_by(chunk_size) {
                prepared.setup_flat(start..start + chunk_size, &mut chunk);
                assert_eq!(chunk.rejected, 0);
                let mut order = Vec::new();
                for s in &chunk.spans {
                    for x in s.x0..s.x1 {
                        let t = chunk.tris[s.tri as usize];
                        assert_eq!(t.source, s.source);
                        got.push((s.source, s.y, x, s.coverage, s.front_facing, t));
                        order.push((s.source, s.tri, s.y, x));
                    }
                }
                // API order within the chunk, row-major within a setup triangle (a merged
                // pixel of a clipped triangle's pieces carries the first piece covering it).
                assert!(
                    order.windows(2).all(|w| w[0].0 <= w[1].0),
                    "{samples:?} {cull:?} chunk {chunk_size}: out of API order"
                );
                let mut per_tri: HashMap<(u32, u32), Vec<(u32, u32)>> = HashMap::new();
                for &(source, tri, y, x) in &order {
                    per_tri.entry((source, tri)).or_default().push((y, x));
                }
                assert!(
                    per_tri.values().all(|v| v.windows(2).all(|w| w[0] < w[1])),
                    "{samples:?} {cull:?} chunk {chunk_size}: not row-major"
                );
            }
            by_pixel(&mut got);
            assert_eq!(
                got.len(),
                want.len(),
                "{samples:?} {cull:?} chunk {chunk_size}"
            );
            assert!(
                got == want,
                "{samples:?} {cull:?} chunk {chunk_size}: fragments differ"
            );
        }
    }
}

/// A mesh with a non-finite vertex or an index out of range is not well formed (the
/// unbinned path leaves it to binning, which counts and drops its triangles).
#[test]
fn well_formed_sees_bad_vertices_and_indices() {
    let v = vp(32, 32);
    let st = state(X1);
    let pos = [px(1.0, 1.0, v), px(30.0, 2.0, v), px(3.0, 30.0, v)];
    let ok = prepare(&pos, &[[0, 1, 2]], &st, v, 1, PlaneSetup::Skip);
    assert!(ok.well_formed(1));
    let bad_index = prepare(&pos, &[[0, 1, 3]], &st, v, 1, PlaneSetup::Skip);
    assert!(!bad_index.well_formed(1));
    let mut nan = pos;
    nan[1].x = f32::NAN;
    assert!(!prepare(&nan, &[[0, 1, 2]], &st, v, 1, PlaneSetup::Skip).well_formed(1));
    let mut inf = pos;
    inf[2].w = f32::INFINITY;
    assert!(!prepare(&inf, &[[0, 1, 2]], &st, v, 1, PlaneSetup::Skip).well_formed(1));
    assert!(prepare(&pos, &[], &st, v, 1, PlaneSetup::Skip).well_formed(1));
    // Many triangles, checked on several threads: a bad index in any part is found.
    let mut many = vec![[0u32, 1, 2]; 300_000];
    assert!(prepare(&pos, &many, &st, v, 4, PlaneSetup::Skip).well_formed(4));
    for at in [0, 150_000, 299_999] {
        many[at] = [0, 3, 2];
        {
            let bad = prepare(&pos, &many, &st, v, 4, PlaneSetup::Skip);
            assert!(!bad.well_formed(1) && !bad.well_formed(2) && !bad.well_formed(4));
        }
        many[at] = [0, 1, 2];
    }
}
