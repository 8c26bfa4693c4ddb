//! Coverage: the standard sample positions, the top-left fill rule, every sample of a
//! tiling covered exactly once, MSAA masks, and the fragments of random and degenerate-ish
//! triangles against a brute-force reference.

use fragrace_emu::raster::*;
use glam::{Vec3, Vec4};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use std::collections::HashMap;

use super::common::*;

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
