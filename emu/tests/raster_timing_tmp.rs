use fragrace_emu::raster::*;
use glam::{Mat4, Vec3, Vec4};
use std::time::Instant;

fn load_obj_gz(path: &str) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let out = std::process::Command::new("gzip")
        .arg("-dc")
        .arg(path)
        .output()
        .unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    let mut v = Vec::new();
    let mut f = Vec::new();
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f32> = it.take(3).map(|s| s.parse().unwrap()).collect();
                v.push(Vec3::new(c[0], c[1], c[2]));
            }
            Some("f") => {
                let c: Vec<u32> = it
                    .take(3)
                    .map(|s| s.split('/').next().unwrap().parse::<u32>().unwrap() - 1)
                    .collect();
                f.push([c[0], c[1], c[2]]);
            }
            _ => {}
        }
    }
    (v, f)
}

#[test]
#[ignore]
fn time_dragon() {
    let (v, f) = load_obj_gz("/work/shared/models/dragon.obj.gz");
    let (mut lo, mut hi) = (v[0], v[0]);
    for p in &v {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let c = (lo + hi) * 0.5;
    let r = (hi - lo).length() * 0.5;
    let view = Mat4::look_at_rh(c + Vec3::new(0.0, 0.0, 2.2 * r), c, Vec3::Y);
    let proj = Mat4::perspective_rh_gl(45f32.to_radians(), 1.0, 0.1 * r, 10.0 * r);
    let vp = proj * view;
    let clip: Vec<Vec4> = v.iter().map(|p| vp * p.extend(1.0)).collect();
    let state = RasterState::default();
    let viewport = Viewport {
        width: 512,
        height: 512,
    };
    for threads in [1, 2] {
        let mut best = (1e9f64, 1e9f64);
        for _ in 0..20 {
            let t0 = Instant::now();
            let b = bin_triangles(&clip, &f, &state, viewport, threads);
            let t1 = Instant::now();
            let next = std::sync::atomic::AtomicUsize::new(0);
            let total = std::sync::atomic::AtomicUsize::new(0);
            std::thread::scope(|s| {
                for _ in 0..threads {
                    s.spawn(|| {
                        let mut n = 0usize;
                        loop {
                            let t = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                            if t >= b.tile_count() {
                                break;
                            }
                            b.raster_tile(t, |fr| {
                                n += fr.coverage as usize;
                            });
                        }
                        total.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
                    });
                }
            });
            let t2 = Instant::now();
            best.0 = best.0.min((t1 - t0).as_secs_f64() * 1e3);
            best.1 = best.1.min((t2 - t1).as_secs_f64() * 1e3);
            if best.0 > 1e8 {
                println!("{} {}", b.tris.len(), total.into_inner());
            }
        }
        println!(
            "threads {threads}: min bin {:.2} ms, min raster {:.2} ms",
            best.0, best.1
        );
    }
}

#[test]
#[ignore]
fn prof_dragon() {
    let (v, f) = load_obj_gz("/work/shared/models/dragon.obj.gz");
    let (mut lo, mut hi) = (v[0], v[0]);
    for p in &v {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let c = (lo + hi) * 0.5;
    let r = (hi - lo).length() * 0.5;
    let view = Mat4::look_at_rh(c + Vec3::new(0.0, 0.0, 2.2 * r), c, Vec3::Y);
    let proj = Mat4::perspective_rh_gl(45f32.to_radians(), 1.0, 0.1 * r, 10.0 * r);
    let vp = proj * view;
    let clip: Vec<Vec4> = v.iter().map(|p| vp * p.extend(1.0)).collect();
    let state = RasterState::default();
    let viewport = Viewport {
        width: 512,
        height: 512,
    };
    let ticks = || -> f64 {
        let st = std::fs::read_to_string("/proc/self/stat").unwrap();
        let after = &st[st.rfind(')').unwrap() + 2..];
        let v: Vec<&str> = after.split_whitespace().collect();
        (v[11].parse::<f64>().unwrap() + v[12].parse::<f64>().unwrap()) * 10.0
    };
    let mut n = 0;
    let iters = 60;
    let c0 = ticks();
    for _ in 0..iters {
        let b = bin_triangles(&clip, &f, &state, viewport, 1);
        n += b.tris.len();
    }
    let c1 = ticks();
    let b = bin_triangles(&clip, &f, &state, viewport, 1);
    let c2 = ticks();
    for _ in 0..iters {
        for t in 0..b.tile_count() {
            b.raster_tile(t, |fr| n += fr.coverage as usize);
        }
    }
    let c3 = ticks();
    let (tb, tr) = ((c1 - c0) / iters as f64, (c3 - c2) / iters as f64);
    println!("{n} cpu: bin {tb:.2} ms raster {tr:.2} ms");
}
