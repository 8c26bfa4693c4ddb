//! What no paper could show: the race benchmark's recall and precision per schedule policy
//! (`fragrace racebench`, kernels/src/racebench): kernels labelled racy or race-free, each
//! run under every policy, the detector's reports against the labels.

use serde_json::json;

use super::{ctx, Figure, Paper, PaperConfig, Progress, ReportError, Section, Table};
use crate::plot::{LinePlot, Series};
use crate::racebench::{self, BenchConfig, BenchPolicy};
use crate::run::{self, RunSpec, SceneSpec};
use fragrace_kernels::HazardClass;

/// In-flight windows of the hazard-rate figure (`--window`: invocations in flight at once,
/// what stands for a GPU's occupancy).
pub const WINDOWS: [usize; 6] = [1, 2, 4, 8, 16, 64];

/// Per hazard-prone algorithm, per window: the fraction of `seeds` scheduled runs (policy
/// random) with a hazard, and their mean EPR, on `cubes` at 32x32.
pub fn hazard_rates(
    seeds: u64,
    progress: &dyn Progress,
) -> Result<(Vec<Series>, Vec<Series>), ReportError> {
    let mut base = RunSpec::new(SceneSpec::Builtin("cubes".into()), "truth");
    base.width = 32;
    base.height = 32;
    let loaded = ctx(run::load(&base), || "cubes".into())?;
    let truth = ctx(run::truth(&base, &loaded), || "cubes: the truth".into())?;
    let (mut rates, mut eprs) = (Vec::new(), Vec::new());
    for algo in fragrace_kernels::algorithms() {
        let info = algo.info();
        if info.hazard != HazardClass::HazardProne {
            continue;
        }
        let (mut rate, mut epr) = (Vec::new(), Vec::new());
        for w in WINDOWS {
            progress.step(&format!("hazards: {} with window {w}", info.name));
            let mut hit = 0;
            let mut sum = 0.0;
            for seed in 0..seeds {
                let mut s = base.clone();
                s.algo = info.name.into();
                s.exec = ctx(
                    run::exec_config("scheduled", "random", seed, Some(1), w)
                        .map_err(run::RunError::from),
                    || format!("window {w}"),
                )?;
                let c = ctx(run::check_with(&s, &loaded, &truth), || {
                    format!("{} with window {w}, seed {seed}", info.name)
                })?;
                hit += u32::from(c.hazards().total() > 0);
                sum += c.metrics.epr;
            }
            rate.push(((w as f64).log2(), f64::from(hit) / seeds as f64));
            epr.push(((w as f64).log2(), sum / seeds as f64));
        }
        rates.push(Series {
            name: info.name.into(),
            points: rate,
        });
        eprs.push(Series {
            name: info.name.into(),
            points: epr,
        });
    }
    Ok((rates, eprs))
}

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
    let seeds = if cfg.quick { 6 } else { 50 };
    let (rates, eprs) = hazard_rates(seeds, progress)?;
    let what = format!("{seeds} seeds per point, policy random, cubes 32x32");
    s.figures.push(Figure {
        id: "hazards-rate-window".into(),
        caption: format!(
            "Fraction of scheduled runs in which the detector saw a hazard, against the \
             in-flight window, for every hazard-prone algorithm ({what})."
        ),
        plot: LinePlot::new(
            "Runs with a hazard against the in-flight window",
            "log2 of the in-flight window (--window: invocations at once; 6 = 64)",
            "runs with a hazard (fraction)",
            rates,
        ),
        command: cfg.command(Paper::Hazards),
    });
    s.figures.push(Figure {
        id: "hazards-epr-window".into(),
        caption: format!("Mean error pixel rate of the same runs ({what})."),
        plot: LinePlot::new(
            "Mean EPR against the in-flight window",
            "log2 of the in-flight window (--window: invocations at once; 6 = 64)",
            "mean error pixel rate (fraction of covered pixels)",
            eprs,
        ),
        command: cfg.command(Paper::Hazards),
    });
    Ok(s)
}
