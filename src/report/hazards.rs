//! What no paper could show: the race benchmark's recall and precision per schedule policy
//! (`fragrace racebench`, kernels/src/racebench): kernels labelled racy or race-free, each
//! run under every policy, the detector's reports against the labels.

use serde_json::json;

use super::{Paper, PaperConfig, Progress, ReportError, Section, Table};
use crate::racebench::{self, BenchConfig, BenchPolicy};

/// The section.
pub fn section(cfg: &PaperConfig, progress: &dyn Progress) -> Result<Section, ReportError> {
    let schedules = if cfg.quick { 50 } else { 1000 };
    progress.step(&format!(
        "hazards: the race benchmark, {schedules} schedules per kernel and policy"
    ));
    let bench = BenchConfig {
        schedules,
        policies: BenchPolicy::defaults(),
        kernels: Vec::new(),
        threads: cfg.threads,
        stop_at_first: false,
    };
    bench.validate()?;
    let r = racebench::run(&bench)?;
    let mut s = Section::new(Paper::Hazards, "Hazards: the race benchmark");
    s.text.push(format!(
        "{} kernels with known races or none, {schedules} schedules each under every policy \
         ({:.1} s). Recall: racy kernels whose race the detector reported; precision: reports \
         on racy kernels over all reports. Best-policy recall {:.0}%, precision {:.0}% \
         (without the declared limitations: {:.0}%, {:.0}%).",
        r.kernels.len(),
        r.seconds,
        100.0 * r.best_policy_recall,
        100.0 * r.overall_precision,
        100.0 * r.best_policy_recall_without_limitations,
        100.0 * r.overall_precision_without_limitations,
    ));
    let rows = r
        .totals
        .iter()
        .map(|t| {
            vec![
                json!(t.policy),
                json!(format!("{}/{}", t.found, t.racy)),
                json!((t.recall * 1000.0).round() / 1000.0),
                json!((t.precision * 1000.0).round() / 1000.0),
                json!(t.found_with_oracle),
                json!(t.median_schedules_to_detection),
                json!(t.worst_schedules_to_detection),
                json!(t
                    .median_seconds_to_detection
                    .map(|x| (x * 1e4).round() / 10.0)),
                json!(t.missed.join(" ")),
                json!(t.false_alarm_kernels.join(" ")),
            ]
        })
        .collect();
    s.tables.push(Table {
        id: "hazards-racebench".into(),
        title: "Race detection: recall and precision per schedule policy".into(),
        caption: format!(
            "{schedules} schedules per kernel and policy; times to detection in milliseconds."
        ),
        columns: [
            "policy",
            "found / racy",
            "recall",
            "precision",
            "found with the oracle",
            "median schedules to detection",
            "worst schedules to detection",
            "median ms to detection",
            "missed",
            "false alarms",
        ]
        .iter()
        .map(|c| c.to_string())
        .collect(),
        rows,
        command: cfg.command(Paper::Hazards),
    });
    Ok(s)
}
