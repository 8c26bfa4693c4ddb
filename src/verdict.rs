//! A check's verdict in words, before its numbers: exact, errors within what the algorithm
//! promises, a hazard found, or a violation of what the algorithm declares.

use fragrace_emu::HazardCounts;
use fragrace_kernels::{Capacity, HazardClass};

use crate::run::Checked;

/// What kind of outcome a check had.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum VerdictKind {
    /// Equal to the truth on every pixel; no hazard, fault, failed invariant or drop.
    Exact,
    /// Differences the algorithm declares: it approximates (compared as an image) or drops,
    /// and counts, what it cannot keep (a full pool, coplanar fragments a peel cannot
    /// separate).
    WithinPromise,
    /// A hazard-prone algorithm showed its race (hazards seen, or results that differ).
    HazardFound,
    /// Something the algorithm's declared class rules out: a hazard-free algorithm that
    /// races or differs beyond what it drops, a fault, a failed invariant.
    Violation,
}

/// A verdict: its kind and one sentence.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Verdict {
    pub kind: VerdictKind,
    pub text: String,
}

/// The verdict of a check (`hazards`: summed over every schedule run, which may be more
/// than `c`'s own).
pub fn verdict(c: &Checked, hazards: &HazardCounts) -> Verdict {
    let info = &c.rendered.info;
    let r = &c.rendered.result;
    let m = &c.metrics;
    let faults = r.report.stats.faulted;
    let failed: Vec<String> = c.failed_checks().iter().map(|c| c.name.clone()).collect();
    let approximate = info.capacity == Capacity::Image;
    let hz = format!(
        "{} lost updates, {} races, {} torn records",
        hazards.lost_updates, hazards.races, hazards.torn
    );
    let v = |kind, text: String| Verdict { kind, text };
    if faults > 0 || !failed.is_empty() {
        let why = if faults > 0 {
            format!("{faults} invocations faulted")
        } else {
            format!("invariants failed: {}", failed.join("; "))
        };
        return v(
            VerdictKind::Violation,
            format!("VIOLATION: {} ({}): {why}", info.name, info.hazard.name()),
        );
    }
    if info.hazard == HazardClass::HazardProne
        && (hazards.total() > 0 || m.error_pixels > 0 || r.dropped > 0)
    {
        let detail = if hazards.total() > 0 {
            hz
        } else if m.error_pixels > 0 {
            format!(
                "{} pixels differ from the truth (the hazard detector runs under --exec scheduled only)",
                m.error_pixels
            )
        } else {
            format!("{} fragments dropped", r.dropped)
        };
        return v(
            VerdictKind::HazardFound,
            format!(
                "hazard found: {} is hazard-prone, and its race showed: {detail}",
                info.name
            ),
        );
    }
    if hazards.total() > 0 {
        return v(
            VerdictKind::Violation,
            format!(
                "VIOLATION: {} is {} but the detector saw {hz}",
                info.name,
                info.hazard.name()
            ),
        );
    }
    if m.error_pixels > 0 && !approximate && r.dropped == 0 {
        return v(
            VerdictKind::Violation,
            format!(
                "VIOLATION: {} is {} but {} pixels differ from the truth",
                info.name,
                info.hazard.name(),
                m.error_pixels
            ),
        );
    }
    if m.error_pixels > 0 || r.dropped > 0 {
        let why = if approximate {
            "it approximates the composite (compared as an image, within 1/255 per channel)"
                .to_string()
        } else {
            format!(
                "it drops, and counts, fragments it cannot keep ({} dropped)",
                r.dropped
            )
        };
        return v(
            VerdictKind::WithinPromise,
            format!(
                "errors within what {} promises: {why}; {} of {} covered pixels differ",
                info.name, m.error_pixels, m.covered_pixels
            ),
        );
    }
    v(
        VerdictKind::Exact,
        format!(
            "exact: {} matches the truth on all {} covered pixels, with no hazard, fault or failed invariant",
            info.name, m.covered_pixels
        ),
    )
}

/// The verdict for a newcomer, in three plain sentences: what was found, what it means, what
/// to run next (`replay`: the command that reruns the worst run; `picture`: the file with
/// the truth, the algorithm and their difference, when one was written).
pub fn plain_words(
    c: &Checked,
    verdict: &Verdict,
    replay: &str,
    picture: Option<&std::path::Path>,
) -> [String; 3] {
    let info = &c.rendered.info;
    let m = &c.metrics;
    let lost = if m.expected > 0 {
        100.0 * (1.0 - m.captured as f64 / m.expected as f64)
    } else {
        0.0
    };
    let found = match verdict.kind {
        VerdictKind::Exact => format!(
            "Found: nothing wrong; {} kept every fragment it should, on all {} covered pixels.",
            info.name, m.covered_pixels
        ),
        _ if m.error_pixels > 0 => format!(
            "Found: {} lost {lost:.1}% of the fragments it should have kept; {} of {} covered pixels are wrong.",
            info.name, m.error_pixels, m.covered_pixels
        ),
        _ => format!(
            "Found: no pixel is wrong, but {}",
            verdict.text
        ),
    };
    let means = match verdict.kind {
        VerdictKind::Exact => format!(
            "Means: under the schedules tried, {} behaved as its class ({}) promises.",
            info.name,
            info.hazard.name()
        ),
        VerdictKind::HazardFound => format!(
            "Means: {} is hazard-prone: invocations of one pixel read and write its storage without a lock, so which fragments survive depends on the order a GPU runs them in; this order lost some.",
            info.name
        ),
        VerdictKind::WithinPromise => format!(
            "Means: the differences are the ones {} declares (it approximates or drops, and counts what it drops); not a race.",
            info.name
        ),
        VerdictKind::Violation => format!(
            "Means: {} is declared {}, so this is a bug in the algorithm (or in the emulator): it should not happen under any schedule.",
            info.name,
            info.hazard.name()
        ),
    };
    let look = picture
        .map(|p| {
            format!(
                "look at {} (truth, {}, difference); ",
                p.display(),
                info.name
            )
        })
        .unwrap_or_default();
    let safer: Vec<&'static str> = fragrace_kernels::algorithms()
        .iter()
        .map(|a| a.info())
        .filter(|a| a.family == info.family && a.hazard != HazardClass::HazardProne)
        .map(|a| a.name)
        .take(2)
        .collect();
    let alternative = if info.hazard == HazardClass::HazardProne && !safer.is_empty() {
        format!("; the same family without the race: {}", safer.join(", "))
    } else {
        String::new()
    };
    let next =
        format!("Next: {look}replay the worst run bit for bit with `{replay}`{alternative}.");
    [found, means, next]
}
