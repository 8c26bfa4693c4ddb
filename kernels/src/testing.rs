//! What the unit tests of every family share (one copy, so that a test scene or an
//! assertion means the same thing in every module): scene pieces and frames, the executors
//! a test sweeps, runs compared with the truth by the oracle, and the assertions every
//! exact (hazard-free) algorithm owes.

use fragrace_emu::{ExecConfig, ExecMode, Mesh, Policy, ScheduleConfig};
use glam::{Mat4, Vec3};

use crate::algo::{AlgoResult, Algorithm, Frame, Params};
use crate::basic::Truth;
use crate::oracle::{self, Metrics};

// Scenes and frames.

/// `mesh` through the identity view-projection (NDC = clip) at `width` x `height` pixels.
pub fn frame_sized(mesh: &Mesh, width: u32, height: u32) -> Frame<'_> {
    Frame {
        mesh,
        objects: &[],
        view_proj: Mat4::IDENTITY,
        width,
        height,
    }
}

/// Appends a quad of two triangles over NDC `[x0, x1] x [y0, y1]` (`r = [x0, x1, y0, y1]`)
/// at NDC depth `z + tilt * x`.
pub fn tilted_quad(mesh: &mut Mesh, r: [f32; 4], z: f32, tilt: f32) {
    let b = mesh.positions.len() as u32;
    for (x, y) in [(r[0], r[2]), (r[1], r[2]), (r[1], r[3]), (r[0], r[3])] {
        mesh.positions.push(Vec3::new(x, y, z + tilt * x));
    }
    mesh.indices.push([b, b + 1, b + 2]);
    mesh.indices.push([b, b + 2, b + 3]);
}

/// `n` identical quads: one layer of `n` coplanar fragments per covered pixel.
pub fn coplanar_stack(n: usize) -> Mesh {
    let mut mesh = Mesh::default();
    for _ in 0..n {
        tilted_quad(&mut mesh, [-0.8, 0.8, -0.8, 0.8], 0.1, 0.0);
    }
    mesh
}

/// At 8 x 8 pixels the RMW k-buffer under a random schedule has an EPR of about 0.6; at
/// 16 x 16, about 0.04 (fewer fragments of one pixel in the scheduler's window at once).
///
/// `n` overlapping axis-aligned quads at constant depths in a shuffled (not depth)
/// order, each offset a little so that depth complexity varies from pixel to pixel, plus
/// an exact duplicate of quad 0 (coplanar fragments, depth-fighting paper section 1) and
/// two quads sharing one depth. Identity view-projection: NDC = clip.
pub fn quads(n: usize) -> Mesh {
    let mut m = Mesh::default();
    let mut quad = |x0: f32, y0: f32, x1: f32, y1: f32, z: f32| {
        let b = m.positions.len() as u32;
        m.positions.extend([
            Vec3::new(x0, y0, z),
            Vec3::new(x1, y0, z),
            Vec3::new(x1, y1, z),
            Vec3::new(x0, y1, z),
        ]);
        m.indices.push([b, b + 1, b + 2]);
        m.indices.push([b, b + 2, b + 3]);
    };
    for i in 0..n {
        // A permutation of the depth levels (7 is coprime with every power of two).
        let level = (i * 7 + 3) % n.max(1);
        let z = -0.8 + 1.6 * level as f32 / n as f32;
        let o = (i % 5) as f32 * 0.08;
        let p = (i % 3) as f32 * 0.1;
        quad(-0.9 + o, -0.85 + p, 0.55 + o * 0.5, 0.7 - p, z);
    }
    // Coplanar: a duplicate of quad 0, and a quad at quad 1's depth.
    let z0 = -0.8 + 1.6 * (3 % n.max(1)) as f32 / n as f32;
    quad(-0.9, -0.85, 0.55, 0.7, z0);
    let z1 = -0.8 + 1.6 * ((7 + 3) % n.max(1)) as f32 / n as f32;
    quad(-0.3, -0.5, 0.9, 0.9, z1);
    m
}

/// `mesh` at `size` x `size` pixels.
pub fn frame(mesh: &Mesh, size: u32) -> Frame<'_> {
    frame_sized(mesh, size, size)
}

/// Appends a quad over NDC `[x0, x1] x [y0, y1]` whose depth goes from `z0` (left) to
/// `z1` (right).
pub fn quad(m: &mut Mesh, [x0, y0, x1, y1]: [f32; 4], z0: f32, z1: f32) {
    let b = m.positions.len() as u32;
    m.positions.extend([
        Vec3::new(x0, y0, z0),
        Vec3::new(x1, y0, z1),
        Vec3::new(x1, y1, z1),
        Vec3::new(x0, y1, z0),
    ]);
    m.indices.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
}

/// Overlapping quads of several depths and slopes, two of them coplanar (equal depths,
/// different primitives), some pixels uncovered, depth complexity up to 6.
pub fn layers() -> Mesh {
    let mut m = Mesh::default();
    quad(&mut m, [-0.9, -0.9, 0.5, 0.6], 0.2, 0.2);
    quad(&mut m, [-0.5, -0.7, 0.9, 0.9], -0.6, 0.4);
    quad(&mut m, [-0.8, -0.2, 0.3, 0.8], 0.5, -0.5);
    quad(&mut m, [-0.8, -0.2, 0.3, 0.8], 0.5, -0.5); // coplanar with the previous one
    quad(&mut m, [-0.3, -0.95, 0.7, 0.1], 0.0, 0.0);
    quad(&mut m, [-1.0, -1.0, 1.0, 1.0], 0.9, 0.7);
    quad(&mut m, [0.6, 0.6, 0.95, 0.95], -0.2, -0.1);
    m
}

/// `count` full-screen quads of distinct depths: every pixel holds `count` fragments.
pub fn stack(count: usize) -> Mesh {
    let mut m = Mesh::default();
    for i in 0..count {
        let z = -0.8 + 1.6 * i as f32 / count as f32;
        quad(&mut m, [-1.0, -1.0, 1.0, 1.0], z, z + 0.05);
    }
    m
}

// Executors.

/// Scheduled executor with `policy`, `seed` and the default window.
pub fn scheduled(policy: Policy, seed: u64) -> ExecConfig {
    ExecConfig::scheduled(policy, seed)
}

/// Ordered, parallel(2), parallel(4) with small batches (fragments of one pixel on
/// different threads), parallel(3) with lanes run to completion instead of in lockstep,
/// and scheduled under every policy with `seeds` seeds each, plus lockstep forward
/// progress (`simt`) and a wide window.
pub fn executors(seeds: u64) -> Vec<(String, ExecConfig)> {
    let mut v = vec![
        ("ordered".to_string(), ExecConfig::ordered()),
        ("parallel(2)".to_string(), ExecConfig::parallel(2)),
        (
            "parallel(4) batch 8".to_string(),
            ExecConfig {
                batch: 8,
                ..ExecConfig::parallel(4)
            },
        ),
        (
            "parallel(3) without lockstep".to_string(),
            ExecConfig {
                lockstep: false,
                ..ExecConfig::parallel(3)
            },
        ),
    ];
    for policy in Policy::all() {
        for seed in 0..seeds {
            v.push((
                format!("scheduled {policy} seed {seed}"),
                scheduled(policy.clone(), seed),
            ));
        }
    }
    // Lockstep forward progress: spinning lanes hold their warp-mates back.
    v.push((
        "scheduled random simt 32".to_string(),
        ExecConfig {
            mode: ExecMode::Scheduled(ScheduleConfig {
                simt: 32,
                ..Default::default()
            }),
            ..scheduled(Policy::Random, 0)
        },
    ));
    // A wide window: more fragments of one pixel in flight at once.
    v.push((
        "scheduled random window 256".to_string(),
        ExecConfig {
            mode: ExecMode::Scheduled(ScheduleConfig {
                window: 256,
                ..Default::default()
            }),
            ..ExecConfig::default()
        },
    ));
    v
}

/// Ordered, parallel, and scheduled under several policies and seeds.
pub fn executor_configs() -> Vec<ExecConfig> {
    let mut v = vec![
        ExecConfig::ordered(),
        ExecConfig::parallel(2),
        ExecConfig::parallel(4),
    ];
    for seed in 0..3 {
        v.push(ExecConfig::scheduled(Policy::Random, seed));
    }
    v.push(ExecConfig::scheduled(Policy::Pct { depth: 3 }, 7));
    v.push(ExecConfig::scheduled(Policy::Warp { lanes: 8 }, 1));
    v.push(ExecConfig::scheduled(Policy::Reverse, 0));
    v.push(ExecConfig::scheduled(Policy::FarFirst, 0));
    v
}

// Runs and assertions.

/// Runs `algo` and compares it with the truth.
pub fn run(
    algo: &dyn Algorithm,
    frame: &Frame<'_>,
    params: &Params,
    exec: &ExecConfig,
) -> (AlgoResult, Metrics) {
    let result = algo.run(frame, params, exec).expect("the algorithm runs");
    let truth = Truth::capture(frame, 1).expect("truth runs");
    let m = oracle::compare(&algo.info(), &result, &truth, params);
    (result, m)
}

/// Asserts that every check of `r` passed.
pub fn assert_checks(r: &AlgoResult, what: &str) {
    for c in &r.checks {
        assert!(c.passed, "{what}: check `{}` failed: {}", c.name, c.detail);
    }
    assert_eq!(
        r.report.stats.faulted, 0,
        "{what}: faults {:?}",
        r.report.faults
    );
}

/// Runs a hazard-free algorithm under every executor: EPR 0, checks pass, no faults, and
/// the resolve's image is the composite of the capture.
/// Two sizes of the 16-quad scene: 8 x 8 (every pixel's fragments in flight together)
/// and 16 x 16 (more pixels, varied depth complexity).
pub fn assert_exact_everywhere(algo: &dyn Algorithm, params: &Params, seeds: u64) {
    let mesh = quads(16);
    for (size, (what, exec)) in [8, 16]
        .into_iter()
        .flat_map(|s| executors(seeds).into_iter().map(move |e| (s, e)))
    {
        let frame = frame(&mesh, size);
        let (r, m) = run(algo, &frame, params, &exec);
        let what = format!("{} at {size} x {size} under {what}", algo.info().name);
        assert!(m.covered_pixels > 0, "{what}: the scene covers pixels");
        assert_eq!(
            m.error_pixels, 0,
            "{what}: EPR {} (first error at {:?})",
            m.epr, m.first_error
        );
        assert_checks(&r, &what);
        assert_image_matches_capture(&r, params, &what);
    }
}

/// The full-screen resolve's image equals the host composite of the read-back capture.
pub fn assert_image_matches_capture(r: &AlgoResult, params: &Params, what: &str) {
    let c = r.capture.as_ref().expect("capture");
    let img = r.image.as_ref().expect("image");
    assert_eq!(img.len(), c.pixels(), "{what}: one texel per pixel");
    for (p, &got) in img.iter().enumerate() {
        let want = crate::common::composite_frags(c.pixel(p), params.alpha, params.background);
        assert_eq!(
            got, want,
            "{what}: resolve image differs from the capture at pixel {p}"
        );
    }
}

/// Runs `algo` and asserts what a hazard-free A-buffer owes: EPR 0 against truth, every
/// check passing, nothing dropped, every fragment captured.
pub fn assert_exact(
    algo: &dyn Algorithm,
    frame: &Frame<'_>,
    params: &Params,
    exec: &ExecConfig,
) -> AlgoResult {
    let info = algo.info();
    let r = algo.run(frame, params, exec).expect("runs");
    let truth = Truth::capture(frame, 1).expect("truth");
    let m = oracle::compare(&info, &r, &truth, params);
    let what = format!("{} under {:?}", info.name, exec.mode);
    for c in &r.checks {
        assert!(c.passed, "{what}: check `{}` failed: {}", c.name, c.detail);
    }
    assert_eq!(
        m.epr, 0.0,
        "{what}: EPR {} (first error at {:?})",
        m.epr, m.first_error
    );
    assert_eq!(m.captured, m.generated, "{what}");
    assert_eq!(r.dropped, 0, "{what}");
    assert!(m.generated > 0, "{what}: empty scene");
    r
}

/// `assert_exact` with the default parameters on [`layers`] at 24 x 20 under every one of
/// [`executor_configs`], and no hazard reported: what every hazard-free A-buffer owes.
pub fn assert_exact_and_hazard_free_everywhere(algo: &dyn Algorithm) {
    let mesh = layers();
    let f = frame_sized(&mesh, 24, 20);
    for exec in executor_configs() {
        let r = assert_exact(algo, &f, &Params::default(), &exec);
        assert_eq!(
            r.report.hazards.total(),
            0,
            "{} under {:?}: {:?}",
            algo.info().name,
            exec.mode,
            r.report.hazard_list.first()
        );
    }
}
