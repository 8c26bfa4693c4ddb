//! Shrinking: reduce a failing run (fewer triangles, a smaller viewport, fewer invocations
//! in flight, a shorter schedule) while it still fails the same way, so that a reported
//! case is small enough to read.
//!
//! "Still fails the same way" means the reduced run still shows the *primary* anomaly of
//! the original (invariant violation, then error pixels, lost update, torn record, race,
//! fault, in that order of importance).

use std::time::{Duration, Instant};

use fragrace_emu::{ExecMode, Policy};

use crate::case::{Observation, Size};
use crate::run::{self, RunSpec, SceneSpec};

/// The result of shrinking.
pub struct Shrunk {
    pub spec: RunSpec,
    pub observed: Observation,
    pub before: Size,
    pub after: Size,
}

fn primary(sig: &[&'static str]) -> Option<&'static str> {
    [
        "invariant",
        "error-pixels",
        "lost-update",
        "torn",
        "race",
        "fault",
    ]
    .into_iter()
    .find(|k| sig.contains(k))
}

/// Runs a spec; `Some(observation)` when it shows `kind`.
fn fails(spec: &RunSpec, kind: &str) -> Option<Observation> {
    let loaded = run::load(spec).ok()?;
    let truth = run::truth(spec, &loaded).ok()?;
    let c = run::check_with(spec, &loaded, &truth).ok()?;
    let o = Observation::of(&c);
    o.signature().contains(&kind).then_some(o)
}

fn size_of(spec: &RunSpec, triangles: usize, schedule_steps: usize) -> Size {
    Size {
        triangles,
        pixels: spec.width as u64 * spec.height as u64,
        window: match &spec.exec.mode {
            ExecMode::Scheduled(s) => s.window,
            _ => 0,
        },
        schedule_steps,
    }
}

/// Shrinks `spec` (which produced `observed`) for at most `budget`.
pub fn shrink(spec: &RunSpec, observed: &Observation, budget: Duration) -> Option<Shrunk> {
    let start = Instant::now();
    let out_of_time = || start.elapsed() > budget;
    let kind = primary(&observed.signature())?;
    let loaded = run::load(spec).ok()?;
    let triangles = loaded.scene.mesh.triangle_count();
    let before = size_of(spec, triangles, 0);

    // 1. The scene as inline triangles, exactly as normalised (the camera keeps its radius).
    let mut cur = spec.clone();
    let mesh = &loaded.scene.mesh;
    cur.scene = SceneSpec::Inline {
        positions: mesh.positions.iter().map(|p| p.to_array()).collect(),
        indices: mesh.indices.clone(),
        radius: Some(loaded.scene.radius),
    };
    let mut best = fails(&cur, kind).map(|o| (cur.clone(), o));
    if best.is_none() {
        // Not reproducible inline (should not happen): keep the original scene.
        cur = spec.clone();
        best = Some((cur.clone(), observed.clone()));
    }

    // 2. Only the triangles over the first bad pixel, then delta debugging.
    if let (SceneSpec::Inline { .. }, Some((x, y))) = (
        &cur.scene,
        observed.first_error.or(first_hazard_pixel(observed)),
    ) {
        let keep = triangles_over(&cur, &loaded, x, y);
        if !keep.is_empty() && keep.len() < triangles {
            let cand = with_triangles(&cur, &keep);
            if let Some(o) = fails(&cand, kind) {
                cur = cand;
                best = Some((cur.clone(), o));
            }
        }
    }
    let mut chunks = 2usize;
    // ddmin: `chunks` changes inside the loop on purpose (coarser after a success).
    #[allow(clippy::mut_range_bound)]
    while !out_of_time() {
        let n = tri_count(&cur);
        if n <= 1 || chunks > n {
            break;
        }
        let size = n.div_ceil(chunks);
        let mut reduced = false;
        for c in 0..chunks {
            if out_of_time() {
                break;
            }
            let keep: Vec<usize> = (0..n).filter(|i| i / size != c).collect();
            if keep.is_empty() {
                continue;
            }
            let cand = with_triangles(&cur, &keep);
            if let Some(o) = fails(&cand, kind) {
                cur = cand;
                best = Some((cur.clone(), o));
                chunks = (chunks - 1).max(2);
                reduced = true;
                break;
            }
        }
        if !reduced {
            chunks *= 2;
        }
    }

    // 3. A smaller viewport.
    while !out_of_time() && cur.width > 8 && cur.height > 8 {
        let mut cand = cur.clone();
        cand.width /= 2;
        cand.height /= 2;
        match fails(&cand, kind) {
            Some(o) => {
                cur = cand;
                best = Some((cur.clone(), o));
            }
            None => break,
        }
    }

    // 4. Fewer invocations in flight.
    while !out_of_time() {
        let ExecMode::Scheduled(s) = &cur.exec.mode else {
            break;
        };
        if s.window <= 2 {
            break;
        }
        let mut cand = cur.clone();
        if let ExecMode::Scheduled(s) = &mut cand.exec.mode {
            s.window /= 2;
        }
        match fails(&cand, kind) {
            Some(o) => {
                cur = cand;
                best = Some((cur.clone(), o));
            }
            None => break,
        }
    }

    // 5. The schedule itself, recorded, then cut short (the rest runs earliest-first).
    let mut steps = 0;
    if let ExecMode::Scheduled(_) = &cur.exec.mode {
        if let Some(bytes) = recorded_schedule(&cur) {
            let mut cand = cur.clone();
            if let ExecMode::Scheduled(s) = &mut cand.exec.mode {
                s.policy = Policy::Bytes(bytes.clone());
                s.record = false;
            }
            if let Some(o) = fails(&cand, kind) {
                cur = cand;
                best = Some((cur.clone(), o));
                steps = bytes.len();
                let mut len = bytes.len();
                while !out_of_time() && len > 1 {
                    let half = len / 2;
                    let mut cand = cur.clone();
                    if let ExecMode::Scheduled(s) = &mut cand.exec.mode {
                        s.policy = Policy::Bytes(bytes[..half].to_vec());
                    }
                    match fails(&cand, kind) {
                        Some(o) => {
                            cur = cand;
                            best = Some((cur.clone(), o));
                            len = half;
                            steps = half;
                        }
                        None => break,
                    }
                }
            }
        }
    }
    let (spec, observed) = best?;
    let after = size_of(
        &spec,
        tri_count(&spec).max(if matches!(spec.scene, SceneSpec::Inline { .. }) {
            0
        } else {
            triangles
        }),
        steps,
    );
    Some(Shrunk {
        spec,
        observed,
        before,
        after,
    })
}

fn first_hazard_pixel(o: &Observation) -> Option<(u32, u32)> {
    let h = o.first_hazard.as_ref()?;
    let inside = h.split("pixel (").nth(1)?.split(')').next()?;
    let mut it = inside.split(", ");
    Some((it.next()?.parse().ok()?, it.next()?.parse().ok()?))
}

fn tri_count(spec: &RunSpec) -> usize {
    match &spec.scene {
        SceneSpec::Inline { indices, .. } => indices.len(),
        _ => 0,
    }
}

/// The same inline scene with only the triangles at positions `keep`.
fn with_triangles(spec: &RunSpec, keep: &[usize]) -> RunSpec {
    let mut s = spec.clone();
    if let SceneSpec::Inline {
        positions,
        indices,
        radius,
    } = &spec.scene
    {
        let mut map = vec![u32::MAX; positions.len()];
        let mut new_pos = Vec::new();
        let mut new_idx = Vec::with_capacity(keep.len());
        for &t in keep {
            let tri = indices[t].map(|v| {
                let v = v as usize;
                if map[v] == u32::MAX {
                    map[v] = new_pos.len() as u32;
                    new_pos.push(positions[v]);
                }
                map[v]
            });
            new_idx.push(tri);
        }
        s.scene = SceneSpec::Inline {
            positions: new_pos,
            indices: new_idx,
            radius: *radius,
        };
    }
    s
}

/// Triangles whose screen bounding box (one pixel of margin) holds pixel (x, y), and any
/// that cross w = 0 (their box is unknown).
fn triangles_over(spec: &RunSpec, loaded: &run::Loaded, x: u32, y: u32) -> Vec<usize> {
    let m = loaded.view_proj;
    let mesh = &loaded.scene.mesh;
    let (w, h) = (spec.width as f32, spec.height as f32);
    let screen = |p: glam::Vec3| {
        let c = m * p.extend(1.0);
        if c.w <= 1e-6 {
            return None;
        }
        Some(((c.x / c.w + 1.0) * 0.5 * w, (1.0 - c.y / c.w) * 0.5 * h))
    };
    let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
    mesh.indices
        .iter()
        .enumerate()
        .filter(|(_, t)| {
            let s: Vec<_> = t
                .iter()
                .map(|&v| screen(mesh.positions[v as usize]))
                .collect();
            if s.iter().any(|p| p.is_none()) {
                return true;
            }
            let s: Vec<(f32, f32)> = s.into_iter().flatten().collect();
            let (x0, x1) = (
                s.iter().map(|p| p.0).fold(f32::MAX, f32::min),
                s.iter().map(|p| p.0).fold(f32::MIN, f32::max),
            );
            let (y0, y1) = (
                s.iter().map(|p| p.1).fold(f32::MAX, f32::min),
                s.iter().map(|p| p.1).fold(f32::MIN, f32::max),
            );
            px >= x0 - 1.0 && px <= x1 + 1.0 && py >= y0 - 1.0 && py <= y1 + 1.0
        })
        .map(|(i, _)| i)
        .collect()
}

/// Runs a scheduled spec with recording on and returns its schedule.
fn recorded_schedule(spec: &RunSpec) -> Option<Vec<u8>> {
    let mut s = spec.clone();
    if let ExecMode::Scheduled(sc) = &mut s.exec.mode {
        sc.record = true;
    }
    let loaded = run::load(&s).ok()?;
    let r = run::render(&s, &loaded).ok()?;
    r.result.report.schedule
}
