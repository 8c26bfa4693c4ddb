//! Scenes and assertions shared by the A-buffers' unit tests.

use fragrace_emu::{ExecConfig, Mesh, Policy};
use glam::Vec3;

use crate::algo::{AlgoResult, Algorithm, Frame, Params};
use crate::basic::Truth;
use crate::oracle;
pub use crate::test_scenes::frame;

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

/// Ordered, parallel, and scheduled under several policies and seeds.
pub fn executors() -> Vec<ExecConfig> {
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
/// [`executors`], and no hazard reported: what every hazard-free A-buffer owes.
pub fn assert_exact_and_hazard_free_everywhere(algo: &dyn Algorithm) {
    let mesh = layers();
    let f = frame(&mesh, 24, 20);
    for exec in executors() {
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
