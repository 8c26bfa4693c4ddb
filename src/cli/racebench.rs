//! `fragrace racebench`: the detector measured on the labelled race benchmark.

use super::error::CliError;
use crate::racebench::{self, BenchConfig, BenchPolicy, BenchResult};

/// The options of `racebench`.
#[derive(Clone, Debug, clap::Args)]
pub struct RacebenchOptions {
    /// Schedules per kernel and policy (runs, for `parallel`).
    #[arg(long, default_value_t = 200)]
    pub schedules: u64,
    /// Comma-separated policies (scheduled policy names, or `parallel`).
    #[arg(long, default_value = "random,pct:2,pct:3,warp:32,far-first,parallel")]
    pub policies: String,
    /// Comma-separated kernel names (default: all).
    #[arg(long)]
    pub kernels: Option<String>,
    /// Worker threads of the sweep (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Run every schedule even after a racy kernel's race was found (a precision run: every
    /// report is seen). By default a racy kernel stops at its first true report.
    #[arg(long)]
    pub all_schedules: bool,
    /// The full result as JSON.
    #[arg(long)]
    pub json: bool,
}

/// `racebench`: the sweep, its table (or JSON) printed.
pub fn cmd_racebench(a: &RacebenchOptions) -> Result<(), CliError> {
    let policies = a
        .policies
        .split(',')
        .filter(|s| !s.is_empty())
        .map(BenchPolicy::parse)
        .collect::<Result<Vec<_>, _>>()?;
    let cfg = BenchConfig {
        schedules: a.schedules,
        policies,
        kernels: a
            .kernels
            .as_deref()
            .map(|k| k.split(',').map(str::to_string).collect())
            .unwrap_or_default(),
        threads: a
            .threads
            .unwrap_or_else(fragrace_emu::exec::default_threads),
        stop_at_first: !a.all_schedules,
    };
    let r = racebench::run(&cfg)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        print_text(&r);
    }
    Ok(())
}

fn secs(s: Option<f64>) -> String {
    s.map_or("-".to_string(), |s| format!("{:.1} ms", s * 1e3))
}

fn print_text(r: &BenchResult) {
    let policies: Vec<&str> = r.totals.iter().map(|t| t.policy.as_str()).collect();
    println!(
        "racebench: {} kernels x {} policies, {} schedules each ({} threads)",
        r.kernels.len(),
        policies.len(),
        r.schedules,
        r.threads
    );
    println!("cell: schedules to the first true report (wall time); '-' not found; FA false alarm; o: oracle saw a wrong result");
    print!("{:<30} {:<9}", "kernel", "label");
    for p in &policies {
        print!(" {p:>18}");
    }
    println!("  reported / label");
    for m in &r.kernels {
        print!("{:<30} {:<9}", m.name, m.label.name());
        let mut reported = Vec::new();
        for p in &policies {
            let c = r
                .cells
                .iter()
                .find(|c| c.kernel == m.name && c.policy == *p)
                .expect("a cell per kernel and policy");
            let mut s = match c.schedules_to_first {
                Some(n) => format!("{n} ({})", secs(c.seconds_to_first)),
                None => "-".to_string(),
            };
            if !c.false_alarms.is_empty() {
                s.push_str(" FA");
            }
            if c.oracle_violations > 0 && !c.found {
                s.push_str(" o");
            }
            print!(" {s:>18}");
            for w in &c.reported {
                if !reported.contains(w) {
                    reported.push(w.clone());
                }
            }
        }
        let label: Vec<String> = m
            .words
            .iter()
            .map(|w| {
                if w.slots.is_empty() {
                    w.buffer.to_string()
                } else {
                    format!("{}[+{:?}]", w.buffer, w.slots)
                }
            })
            .collect();
        let kinds: Vec<&str> = m.kinds.iter().map(|k| k.name()).collect();
        let lim = m
            .limitation
            .map_or(String::new(), |l| format!(" [{}]", l.name()));
        println!(
            "  {} / {} {}{lim}",
            if reported.is_empty() {
                "nothing".to_string()
            } else {
                reported.join(", ")
            },
            kinds.join("|"),
            label.join(",")
        );
    }
    println!();
    println!(
        "{:<12} {:>6} {:>9} {:>10} {:>12} {:>12} {:>12}  missed / false alarms",
        "policy", "found", "recall", "precision", "median", "worst", "+oracle"
    );
    for t in &r.totals {
        println!(
            "{:<12} {:>6} {:>8.0}% {:>9.0}% {:>12} {:>12} {:>9}/{:<2}  {} / {}",
            t.policy,
            format!("{}/{}", t.found, t.racy),
            t.recall * 100.0,
            t.precision * 100.0,
            secs(t.median_seconds_to_detection),
            secs(t.worst_seconds_to_detection),
            t.found_with_oracle,
            t.racy,
            if t.missed.is_empty() {
                "-".to_string()
            } else {
                t.missed.join(",")
            },
            if t.false_alarm_kernels.is_empty() {
                "-".to_string()
            } else {
                t.false_alarm_kernels.join(",")
            }
        );
    }
    println!(
        "best-policy recall {:.0}%, precision {:.0}% (without the declared limitations: {:.0}%, {:.0}%); {:.1} s",
        r.best_policy_recall * 100.0,
        r.overall_precision * 100.0,
        r.best_policy_recall_without_limitations * 100.0,
        r.overall_precision_without_limitations * 100.0,
        r.seconds
    );
}
