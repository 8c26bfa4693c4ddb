//! The invariants the A-buffers check on every run ([`crate::AlgoResult::checks`]).
//!
//! An A-buffer keeps every fragment (`Capacity::All`), so whatever its memory layout (fixed
//! arrays, count-scan-store ranges, linked lists, buckets), what it read back must satisfy
//! the same properties: no fragment stored twice, the resolve's order front to back (where
//! the resolve writes its order back, [`CaptureOrder`]), the resolve image the composite of
//! exactly the captured fragments, no faulted invocation
//! ([`capture_checks`], run by [`super::run::AbRun::finish`] for every algorithm of the
//! family). The count-scan-store A-buffers (DFB, SB) share three more ([`count_store_check`],
//! [`ranges_check`], [`stored_once_check`]). One copy of each keeps the check names, which
//! the tests and reports match on, and their details identical across algorithms.

use fragrace_emu::PassReport;

use crate::algo::{Capture, Check, Params};
use crate::common::{self, composite_frags};

/// Whose order a capture is in: what [`sorted_check`] can say about it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum CaptureOrder {
    /// The resolve wrote each pixel's fragments back in the order it composited them, and
    /// the capture reads them as they are: [`sorted_check`] checks the resolve's sort.
    Resolve,
    /// The resolve sorted its own copy and wrote nothing back (the list A-buffers); the host
    /// sorted the capture. [`sorted_check`] would only check the host's sort, so it is not
    /// run: the resolve's order shows in [`image_check`], which composites the capture in
    /// its order.
    Host,
}

/// The checks every A-buffer runs on its capture, its resolve image and its merged report,
/// in this order: [`duplicate_check`], [`sorted_check`] (for a capture in the resolve's
/// order), [`image_check`], [`fault_check`].
pub(super) fn capture_checks(
    capture: &Capture,
    order: CaptureOrder,
    image: &[[f32; 4]],
    params: &Params,
    report: &PassReport,
) -> Vec<Check> {
    let mut checks = vec![duplicate_check(capture)];
    if order == CaptureOrder::Resolve {
        checks.push(sorted_check(capture));
    }
    checks.push(image_check(image, capture, params));
    checks.push(fault_check(report));
    checks
}

/// The resolve kernel wrote, for every pixel, the composite of exactly the fragments the
/// capture holds, in the capture's order (the image and the capture come from the same
/// memory, not one from the other).
pub(super) fn image_check(image: &[[f32; 4]], capture: &Capture, params: &Params) -> Check {
    let mut bad = 0usize;
    let mut first = None;
    for (p, got) in image.iter().enumerate().take(capture.pixels()) {
        let want = composite_frags(capture.pixel(p), params.alpha, params.background);
        if (0..4).any(|c| {
            let d = (got[c] - want[c]).abs();
            d.is_nan() || d > 1e-6
        }) {
            bad += 1;
            first.get_or_insert(p);
        }
    }
    Check::new(
        "resolve image is the composite of the captured fragments",
        bad == 0,
        format!("{bad} pixels differ{}", first_at(first)),
    )
}

/// No invocation of any pass faulted (out-of-bounds, watchdog, panic).
pub(super) fn fault_check(report: &PassReport) -> Check {
    let first = report
        .faults
        .first()
        .map(|f| format!(": first {f:?}"))
        .unwrap_or_default();
    Check::new(
        "no invocation faulted",
        report.stats.faulted == 0,
        format!("{} faulted{first}", report.stats.faulted),
    )
}

/// The captured fragments of every pixel are in front-to-back order (the resolve sorted them).
pub(super) fn sorted_check(capture: &Capture) -> Check {
    let bad = (0..capture.pixels())
        .filter(|&p| {
            capture
                .pixel(p)
                .windows(2)
                .any(|w| common::depth_order(&w[0], &w[1]).is_gt())
        })
        .count();
    Check::new(
        "resolve order is front to back",
        bad == 0,
        format!("{bad} pixels out of order"),
    )
}

/// No (depth, primitive) pair appears twice in one pixel (a single draw gives each primitive
/// at most one fragment per pixel, so a duplicate means a fragment was stored twice).
pub(super) fn duplicate_check(capture: &Capture) -> Check {
    let mut bad = 0usize;
    let mut first = None;
    for p in 0..capture.pixels() {
        let mut v: Vec<(u32, u32)> = capture
            .pixel(p)
            .iter()
            .map(|f| (f.depth.to_bits(), f.prim))
            .collect();
        v.sort_unstable();
        if v.windows(2).any(|w| w[0] == w[1]) {
            bad += 1;
            first.get_or_insert(p);
        }
    }
    Check::new(
        "no fragment stored twice in a pixel",
        bad == 0,
        format!("{bad} pixels with a duplicate{}", first_at(first)),
    )
}

/// `", first at pixel p"`, or nothing.
fn first_at(first: Option<usize>) -> String {
    first
        .map(|p| format!(", first at pixel {p}"))
        .unwrap_or_default()
}

/// Covered pixels' ranges `(start, len)` are pairwise disjoint and together cover exactly
/// `[0, total)` (the offset table of a count-scan-store A-buffer).
pub(super) fn ranges_check(ranges: &[(u32, u32)], total: u32) -> Check {
    let mut r: Vec<(u64, u64)> = ranges
        .iter()
        .filter(|r| r.1 > 0)
        .map(|&(s, l)| (s as u64, l as u64))
        .collect();
    r.sort_unstable();
    let mut next = 0u64;
    let mut problem = None;
    for &(s, l) in &r {
        if s != next {
            problem = Some(if s < next {
                format!("range at {s} overlaps the previous one (ending at {next})")
            } else {
                format!("gap [{next}, {s})")
            });
            break;
        }
        next = s + l;
    }
    if problem.is_none() && next != total as u64 {
        problem = Some(format!("ranges end at {next}, total is {total}"));
    }
    Check::new(
        "ranges disjoint and covering [0, total)",
        problem.is_none(),
        problem.unwrap_or_else(|| format!("{} ranges, total {total}", r.len())),
    )
}

/// Per pixel, the store pass filled exactly what the count pass counted.
pub(super) fn count_store_check(counts: &[u32], fill: &[u32]) -> Check {
    let bad: Vec<usize> = (0..counts.len())
        .filter(|&p| counts[p] != fill[p])
        .collect();
    Check::new(
        "count pass equals store pass (per pixel)",
        bad.is_empty(),
        match bad.first() {
            Some(&p) => format!(
                "{} pixels differ; pixel {p}: counted {}, stored {}",
                bad.len(),
                counts[p],
                fill[p]
            ),
            None => format!(
                "{} fragments in {} pixels",
                counts.iter().map(|&c| c as u64).sum::<u64>(),
                counts.len()
            ),
        },
    )
}

/// A count-scan-store A-buffer has room for every fragment it counted, so it must store
/// each generated fragment once and drop none (`dropped` counts stores past a pixel's
/// counted range, which only a disagreement between the passes can cause).
pub(super) fn stored_once_check(stored: u64, dropped: u64, generated: u64) -> Check {
    Check::new(
        "every generated fragment stored exactly once",
        stored + dropped == generated && dropped == 0,
        format!("stored {stored}, dropped {dropped}, generated {generated}"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_check_finds_overlaps_and_gaps() {
        assert!(ranges_check(&[(0, 2), (2, 3), (5, 1)], 6).passed);
        assert!(ranges_check(&[(5, 1), (0, 2), (2, 3), (9, 0)], 6).passed);
        assert!(!ranges_check(&[(0, 2), (1, 3)], 4).passed);
        assert!(!ranges_check(&[(0, 2), (3, 3)], 6).passed);
        assert!(!ranges_check(&[(0, 2)], 3).passed);
    }
}
