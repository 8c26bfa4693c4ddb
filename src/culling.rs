//! Occupancy culling as the product reports it: which algorithms take it, the checks of a
//! culled run (Lemma 2.1, the early test's count), and what culling saved against the same
//! run without it.
//!
//! The stage itself is `fragrace_kernels::occupancy`; this module only measures it. It knows
//! no k-buffer either: it compares two runs of whatever algorithm the spec names.

use fragrace_kernels::occupancy::CullTest;
use fragrace_kernels::oracle::Metrics;
use fragrace_kernels::{AlgoError, AlgoResult, Algorithm, Check};
use serde_json::json;

use crate::run::{self, Loaded, Rendered, RunError, RunSpec};

/// Refuses occupancy culling for an algorithm that does not take it, and a `d` out of its
/// range for the spec's k, before anything is allocated.
pub fn validate(spec: &RunSpec, algo: &dyn Algorithm) -> Result<(), RunError> {
    let Some(occ) = spec.params.occupancy else {
        return Ok(());
    };
    if !algo.takes_occupancy() {
        let takers: Vec<&str> = fragrace_kernels::algorithms()
            .iter()
            .filter(|a| a.takes_occupancy())
            .map(|a| a.info().name)
            .collect();
        return Err(RunError::Algo(AlgoError::Invalid(format!(
            "--occupancy: `{}` does not run behind occupancy culling; the algorithms that do: {}",
            spec.algo,
            takers.join(", ")
        ))));
    }
    occ.validate(spec.params.k)?;
    Ok(())
}

/// The checks of a culled run, from the oracle's metrics: Lemma 2.1 (none of a pixel's k
/// nearest true fragments is beyond its bound) and, single-sampled, that the peel pass's
/// early test killed exactly the true fragments beyond their bounds.
pub fn checks(m: &Metrics, r: &AlgoResult) -> Vec<Check> {
    let Some(c) = &r.culling else {
        return Vec::new();
    };
    let mut v = Vec::new();
    if let Some(viol) = m.lemma_2_1_violations {
        v.push(Check::new(
            "Lemma 2.1: the k nearest fragments of every pixel pass the culling test",
            viol == 0,
            format!("{viol} of the k nearest true fragments beyond their pixel's bound"),
        ));
    }
    if let (Some(want), 1) = (m.culled_truth, c.samples) {
        let (name, who) = match c.test {
            CullTest::EarlyDepth => (
                "the early test culled exactly the fragments beyond the bound",
                "early-culled",
            ),
            CullTest::Shader => (
                "the capture kernel's test culled exactly the fragments beyond the bound",
                "shader-culled",
            ),
        };
        v.push(Check::new(
            name,
            want == c.culled_fragments,
            format!(
                "{who} {}, true fragments beyond their bound {want}",
                c.culled_fragments
            ),
        ));
    }
    v
}

/// The same run without culling (for what culling saved), or `None` when the spec has none.
pub fn baseline(spec: &RunSpec, loaded: &Loaded) -> Result<Option<Rendered>, RunError> {
    if spec.params.occupancy.is_none() {
        return Ok(None);
    }
    let mut plain = spec.clone();
    plain.params.occupancy = None;
    Ok(Some(run::render(&plain, loaded)?))
}

/// The hottest address of the algorithm's passes (with culling, the peel pass's), outside
/// the stage's own buffers: buffer, index, accesses, peak concurrent accessors. Hotspots are
/// measured by the scheduled executor, and by the parallel one with `ExecConfig::contention`.
fn hottest(r: &AlgoResult) -> serde_json::Value {
    let spots = match &r.culling {
        Some(c) => &c.peel_hotspots,
        None => &r.report.stats.hotspots,
    };
    spots
        .iter()
        .filter(|h| !h.buffer.starts_with("occupancy-"))
        .max_by_key(|h| (h.peak_concurrent, h.accesses))
        .map(|h| {
            json!({ "buffer": h.buffer, "index": h.index, "accesses": h.accesses,
                    "peak_concurrent": h.peak_concurrent })
        })
        .unwrap_or(serde_json::Value::Null)
}

/// Memory operations of a run, all and atomic only, less those of `stage`.
fn ops(r: &AlgoResult, stage: Option<&fragrace_emu::Stats>) -> (u64, u64) {
    use fragrace_emu::memory::OpKind;
    let count = |s: &fragrace_emu::Stats| {
        let o = &s.ops;
        let all: u64 = o.0.iter().sum();
        (all, all - o.of(OpKind::Load) - o.of(OpKind::Store))
    };
    let (all, atomics) = count(&r.report.stats);
    let (s_all, s_atomics) = stage.map(count).unwrap_or((0, 0));
    (all - s_all, atomics - s_atomics)
}

/// The `occupancy` object of a run's JSON summary: the stage's parameters, passes, culled
/// fragments, memory next to the paper's formula, Lemma 2.1, and (with a baseline) what
/// culling saved in invocations, memory accesses and atomics, and the contention on the
/// hottest word with and without it.
pub fn summary(
    rendered: &Rendered,
    metrics: Option<&Metrics>,
    baseline: Option<&Rendered>,
) -> serde_json::Value {
    let (r, wall_ms) = (&rendered.result, rendered.wall_ms);
    let Some(c) = &r.culling else {
        return serde_json::Value::Null;
    };
    let occ = c.occupancy.expect("a culling summary names its parameters");
    let mut v = json!({
        "d": occ.d,
        "sub_intervals": occ.d * 32,
        "range": occ.range.name(),
        "test": c.test,
        "fill": occ.fill.name(),
        "passes": c.passes,
        "peel_passes": c.peel_passes,
        "culled_fragments": c.culled_fragments,
        "culled_fraction": c.culled_fraction(),
        "peel_fragments": c.peel_fragments,
        "bytes_per_pixel": c.bytes_per_pixel,
        "paper_bytes_per_pixel": c.paper_bytes_per_pixel,
        "memory_note": "fragrace stores d map words + near + far + the depth buffer per pixel; \
                        the paper's (d - k + 3) words assume k map words reused for the k-buffer's colours",
        "lemma_2_1_violations": metrics.and_then(|m| m.lemma_2_1_violations),
        "hottest_word": hottest(r),
        "stage_hazards": c.stage_hazards,
    });
    if let Some(b) = baseline {
        let (ops_with, atomics_with) = ops(r, Some(&c.stage));
        let (ops_without, atomics_without) = ops(&b.result, None);
        // k-buffer invocations: every rasterized fragment of the capture passes without
        // culling (nothing tests them before the shader); the peel passes' shaded ones with.
        // Every geometry pass rasterizes the same scene, so the unculled capture passes
        // shade the fragments of one geometry pass times the peel passes (SRAB's extra
        // geometry pass counts fragments for its loss figure, and is not a capture).
        let bs = &b.result.report.stats;
        let shaded_without = match bs.geometry_passes {
            0 => 0,
            g => bs.fragments_generated / g as u64 * c.peel_passes as u64,
        };
        let shaded_with: u64 = c
            .passes
            .iter()
            .filter(|p| p.name == "peel")
            .map(|p| p.shaded)
            .sum();
        v["without"] = json!({
            "kbuffer_invocations": shaded_without,
            "memory_ops": ops_without,
            "atomics": atomics_without,
            "hottest_word": hottest(&b.result),
            "wall_ms": b.wall_ms,
        });
        v["with"] = json!({
            "kbuffer_invocations": shaded_with,
            "memory_ops": ops_with,
            "atomics": atomics_with,
            "stage_memory_ops": c.stage.ops.0.iter().sum::<u64>(),
            "hottest_word": hottest(r),
            "wall_ms": wall_ms,
        });
        v["saved"] = json!({
            "kbuffer_invocations": shaded_without as i64 - shaded_with as i64,
            "memory_ops": ops_without as i64 - ops_with as i64,
            "atomics": atomics_without as i64 - atomics_with as i64,
            "invocation_ratio": if shaded_without > 0 {
                shaded_with as f64 / shaded_without as f64 } else { 1.0 },
        });
    }
    v
}
