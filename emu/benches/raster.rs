//! Binning and rasterizing large meshes, timed: the 871K-triangle dragon (when its file is
//! there) and a synthetic mesh of 871K sub-pixel triangles, at 512x512 on 1 and 2 threads,
//! best of 30 (`cargo bench -p fragrace-emu --bench raster`). It prints wall times; compare
//! builds with it side by side, in one run, on one machine.

use fragrace_emu::raster::*;
use glam::{Vec3, Vec4};

// The rasterizer tests' mesh helpers (viewport, camera, OBJ reading), not a copy of them.
#[allow(dead_code)] // the bench uses only some of the tests' helpers
#[path = "../tests/raster/common.rs"]
mod common;
use common::{bounding_sphere, camera, load_obj_gz, vp};

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

/// The 871K-triangle Stanford dragon at 512x512 (`DRAGON` names the file; without it, the
/// project's models next to the repository).
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

fn main() {
    // `cargo bench` passes `--bench`; a filter argument (`cargo bench -- NAME`) picks one.
    let filter: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let wanted = |name: &str| filter.is_empty() || filter.iter().any(|f| name.contains(f.as_str()));
    if wanted("dragon") {
        time_dragon_512();
    }
    if wanted("synthetic") {
        time_synthetic_871k();
    }
}
