//! Binning: tiles, scissor and submission order; the same fragments for every tile size,
//! thread count and unbinned chunking; and fingerprints of setup for before/after checks.

use fragrace_emu::raster::*;
use glam::{Vec3, Vec4};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use std::collections::HashMap;

use super::common::*;

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
