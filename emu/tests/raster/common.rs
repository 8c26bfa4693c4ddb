//! What the rasterizer's tests share: viewports, states, binning a mesh, the brute-force
//! sample masks, meshes (jittered grids, icospheres, OBJ files) and a camera.

use fragrace_emu::raster::*;
use glam::{Mat4, Vec3, Vec4};
use rand::rngs::SmallRng;
use rand::Rng;
use std::collections::HashMap;

pub const X1: SampleCount = SampleCount::X1;

pub fn vp(w: u32, h: u32) -> Viewport {
    Viewport {
        width: w,
        height: h,
    }
}

/// Small tiles (8 pixels) so that the small test scenes straddle many tile borders.
pub fn state(samples: SampleCount) -> RasterState {
    RasterState {
        samples,
        tile_size: 8,
        ..RasterState::default()
    }
}

/// Clip-space position (w = 1) of a window position in pixels (y down).
pub fn px(x: f64, y: f64, v: Viewport) -> Vec4 {
    Vec4::new(
        (x / v.width as f64 * 2.0 - 1.0) as f32,
        (1.0 - y / v.height as f64 * 2.0) as f32,
        0.0,
        1.0,
    )
}

/// Every fragment of every tile, in tile order.
pub fn all_frags(b: &Binned) -> Vec<Fragment> {
    let mut out = Vec::new();
    for t in 0..b.tile_count() {
        b.raster_tile(t, |f| out.push(f));
    }
    out
}

pub fn bin(pos: &[Vec4], idx: &[[u32; 3]], st: &RasterState, v: Viewport) -> Binned {
    bin_triangles(pos, idx, st, v, 2)
}

/// Per-sample coverage count: `(x, y, sample) -> count`.
pub fn sample_counts(frags: &[Fragment], n: usize) -> HashMap<(u32, u32, usize), u32> {
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
pub fn assert_no_duplicates(b: &Binned, frags: &[Fragment]) {
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

/// A grid mesh over `rect` (pixels) with jittered interior vertices, some moved exactly onto
/// pixel centres or the 1/16 sample grid, random diagonals and random windings; the diagonal
/// is chosen so that no triangle folds over (the mesh tiles the rectangle exactly).
pub fn jittered_grid(
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

pub fn icosphere(subdiv: usize) -> (Vec<Vec3>, Vec<[u32; 3]>) {
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

pub fn camera(eye: Vec3, target: Vec3, aspect: f32, near: f32, far: f32) -> Mat4 {
    Mat4::perspective_rh_gl(50f32.to_radians(), aspect, near, far)
        * Mat4::look_at_rh(eye, target, Vec3::Y)
}

/// Reads a gzipped OBJ with `gzip -dc` (test-only; the product has its own loader).
/// Centre and radius of the bounding box's circumscribed sphere (`verts` not empty).
pub fn bounding_sphere(verts: &[Vec3]) -> (Vec3, f32) {
    let (mut lo, mut hi) = (verts[0], verts[0]);
    for p in verts {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    ((lo + hi) * 0.5, (hi - lo).length() * 0.5)
}

pub fn load_obj_gz(path: &str) -> Option<(Vec<Vec3>, Vec<[u32; 3]>)> {
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
