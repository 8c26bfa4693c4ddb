//! Full-screen resolves that declare what they write at pixels no geometry reached
//! (`KernelInfo::with_untouched_output`) skip those pixels on the fused path, a GPU's
//! coarse coverage mask. The differential sweep proves the skip exact under every executor
//! (the oracle checks each uncovered pixel against the background); this file checks that
//! the skip happens at all, so that a resolve that stops declaring, or a run that stops
//! tracking coverage, is noticed instead of silently costing a kernel per empty pixel.

use fragrace::run::{self, RunSpec, SceneSpec};
use fragrace::scene::Camera;
use fragrace_emu::ExecConfig;
use fragrace_kernels::HazardClass;

/// The algorithms whose last full-screen pass skips untouched pixels under `parallel
/// --no-lockstep` (the interlock ones' capture passes too run on the fused path there, by
/// tile ownership, and mark the blocks they reach).
const SKIPPING: &[&str] = &[
    "ll",
    "fab",
    "sb",
    "dfb",
    "bun-ll",
    "kb-rmw",
    "kb-multipass",
    "srab",
    "kb-atomic32",
    "kb-atomic64",
    "kb-spinlock",
    "kb-interlock",
    "kb-interlock-unordered",
    "kplus",
    "kplus-heap",
    "skb-ofm",
    "wboit",
    "skb-ofm-unordered",
    "dfb-sfm",
    "kb-ofm",
];

#[test]
fn resolves_skip_the_pixels_no_geometry_reached() {
    let size = 64;
    let mut base = RunSpec::new(SceneSpec::Builtin("teapot".into()), "truth");
    base.width = size;
    base.height = size;
    base.camera = Camera::new(30.0, 15.0);
    let loaded = run::load(&base).unwrap();
    let truth = run::truth(&base, &loaded).unwrap();
    let mut failures = Vec::new();
    for &algo in SKIPPING {
        let mut s = base.clone();
        s.algo = algo.into();
        s.exec = ExecConfig {
            lockstep: false,
            ..ExecConfig::parallel(2)
        };
        let c = run::check_with(&s, &loaded, &truth)
            .unwrap_or_else(|e| panic!("{}: {e}", s.command("check")));
        // A hazard-free algorithm gives the ordered executor's error pixels (none when it
        // is exact; WBOIT approximates the composite everywhere it draws).
        let mut ordered = s.clone();
        ordered.exec = ExecConfig::ordered();
        let expected = run::check_with(&ordered, &loaded, &truth)
            .unwrap_or_else(|e| panic!("{}: {e}", ordered.command("check")))
            .metrics
            .error_pixels;
        let stats = &c.rendered.result.report.stats;
        let failed: Vec<_> = c.failed_checks().iter().map(|k| k.name.clone()).collect();
        let info = fragrace_kernels::algorithm(algo).unwrap().info();
        let exact = info.hazard == HazardClass::HazardFree;
        // The teapot at 64 x 64 leaves most 8 x 8 blocks empty; each skipped block is 64
        // full-screen invocations not run.
        if stats.skipped < 64 || !failed.is_empty() || (exact && c.metrics.error_pixels != expected)
        {
            failures.push(format!(
                "{algo}: {} invocations skipped, failed checks {failed:?}, {} error pixels \
                 ({expected} under ordered)\n    {}",
                stats.skipped,
                c.metrics.error_pixels,
                s.command("check")
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
