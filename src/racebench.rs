//! `fragrace racebench`: the hazard detector measured on the labelled kernels of
//! [`fragrace_kernels::racebench`]. Every kernel runs on the tiny scene's fragments under
//! each policy for a number of schedules; per kernel and policy: whether the race was
//! found, after how many schedules and how much wall time, which words and kinds were
//! reported against the label (a report on a word outside the label is a false alarm);
//! per policy: recall, precision, median and worst time to detection.
//!
//! The scheduled policies are judged on what the detector (and the executor's watchdog, for
//! hangs) reports. `parallel` has no detector: there, a race is found when the kernel's
//! oracle sees a wrong result or an invocation hangs, and a false alarm is an oracle
//! violation on a race-free kernel. Oracle violations under the scheduled policies are
//! counted too, apart (the `oracle` columns), which is how the atomics-only races that the
//! detector cannot see by design are found.

use std::collections::BTreeSet;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use fragrace_emu::{ExecConfig, Policy};
use fragrace_kernels::racebench::{self, Case, Fragments, Kind, Label, Outcome, MAX_STEPS};

/// A policy of the benchmark: a scheduled policy, or the parallel executor.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum BenchPolicy {
    Scheduled(Policy),
    /// Real threads (lockstep warps).
    Parallel {
        threads: usize,
    },
}

impl BenchPolicy {
    pub fn name(&self) -> String {
        match self {
            BenchPolicy::Scheduled(p) => p.to_string(),
            BenchPolicy::Parallel { .. } => "parallel".to_string(),
        }
    }

    /// The six: random, pct:2, pct:3, warp:32, far-first, parallel.
    pub fn defaults() -> Vec<BenchPolicy> {
        vec![
            BenchPolicy::Scheduled(Policy::Random),
            BenchPolicy::Scheduled(Policy::Pct { depth: 2 }),
            BenchPolicy::Scheduled(Policy::Pct { depth: 3 }),
            BenchPolicy::Scheduled(Policy::Warp { lanes: 32 }),
            BenchPolicy::Scheduled(Policy::FarFirst),
            BenchPolicy::Parallel { threads: 2 },
        ]
    }

    /// Parses `parallel` or a scheduled policy name (`random`, `pct:D`, ...).
    pub fn parse(s: &str) -> Result<BenchPolicy, BenchError> {
        if s == "parallel" {
            return Ok(BenchPolicy::Parallel { threads: 2 });
        }
        Ok(BenchPolicy::Scheduled(s.parse()?))
    }

    fn exec(&self, seed: u64) -> ExecConfig {
        let base = match self {
            BenchPolicy::Scheduled(p) => ExecConfig::scheduled(p.clone(), seed),
            BenchPolicy::Parallel { threads } => ExecConfig::parallel(*threads),
        };
        ExecConfig {
            max_steps: MAX_STEPS,
            max_waits: MAX_STEPS,
            ..base
        }
    }

    fn detects(&self) -> bool {
        matches!(self, BenchPolicy::Scheduled(_))
    }
}

/// A benchmark setting out of range.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error("--schedules {0} is out of range: it must be at least 1")]
    Schedules(u64),
    #[error("--threads {0} is out of range: it must be from 1 to {1}")]
    Threads(usize, usize),
    #[error("unknown kernel `{0}`; the kernels are: {1}")]
    UnknownKernel(String, String),
    #[error("--policies is empty: give at least one of random, pct:D, warp:N, far-first, reverse, fifo, parallel")]
    NoPolicy,
    #[error(transparent)]
    Policy(#[from] fragrace_emu::exec::PolicyParseError),
}

/// What to run.
#[derive(Clone, Debug)]
pub struct BenchConfig {
    /// Schedules per kernel and policy (runs, for `parallel`).
    pub schedules: u64,
    pub policies: Vec<BenchPolicy>,
    /// Kernels to run (all when empty).
    pub kernels: Vec<String>,
    /// Worker threads of the sweep (each runs one kernel and policy at a time).
    pub threads: usize,
    /// Stop a racy kernel's sweep at its first true report (time to detection only); a
    /// precision run keeps going to see every report.
    pub stop_at_first: bool,
}

impl BenchConfig {
    pub fn validate(&self) -> Result<(), BenchError> {
        if self.schedules == 0 {
            return Err(BenchError::Schedules(0));
        }
        let max = 1024;
        if self.threads == 0 || self.threads > max {
            return Err(BenchError::Threads(self.threads, max));
        }
        if self.policies.is_empty() {
            return Err(BenchError::NoPolicy);
        }
        let all: Vec<&str> = racebench::cases().iter().map(|c| c.meta().name).collect();
        for k in &self.kernels {
            if !all.contains(&k.as_str()) {
                return Err(BenchError::UnknownKernel(k.clone(), all.join(", ")));
            }
        }
        Ok(())
    }
}

/// One kernel under one policy.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Cell {
    pub kernel: &'static str,
    pub label: Label,
    pub policy: String,
    /// Executions run.
    pub runs: u64,
    /// A report on a labelled word (of a labelled kind for hangs) in some execution.
    pub found: bool,
    /// Executions up to and including the first such report.
    pub schedules_to_first: Option<u64>,
    /// Wall time from the start of this kernel's sweep to that report (seconds).
    pub seconds_to_first: Option<f64>,
    /// Every (kind, word) reported, words as `buffer[slot]` within the label's stride, or
    /// `buffer[index]` when the buffer is not in the label.
    pub reported: Vec<String>,
    /// Whether some report had a labelled kind.
    pub kind_as_labelled: bool,
    /// Reports on words outside the label (or any report on a race-free kernel).
    pub false_alarms: Vec<String>,
    /// Executions whose oracle found a wrong result.
    pub oracle_violations: u64,
    pub oracle_first: Option<u64>,
    /// The first oracle finding, in words.
    pub oracle_example: Option<String>,
    /// Faults other than hangs (a bug of the benchmark itself).
    pub faults: Vec<String>,
    pub seconds: f64,
}

/// One policy's totals.
#[derive(Clone, Debug, serde::Serialize)]
pub struct PolicyTotals {
    pub policy: String,
    pub racy: usize,
    pub found: usize,
    pub recall: f64,
    /// Kernel cells with a true report / with any report.
    pub precision: f64,
    pub false_alarm_kernels: Vec<&'static str>,
    pub missed: Vec<&'static str>,
    /// Racy kernels found by the detector or, failing that, by the oracle.
    pub found_with_oracle: usize,
    pub median_seconds_to_detection: Option<f64>,
    pub worst_seconds_to_detection: Option<f64>,
    pub median_schedules_to_detection: Option<u64>,
    pub worst_schedules_to_detection: Option<u64>,
}

/// The benchmark's result.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BenchResult {
    pub schedules: u64,
    pub threads: usize,
    pub kernels: Vec<racebench::Meta>,
    pub cells: Vec<Cell>,
    pub totals: Vec<PolicyTotals>,
    /// Over every policy: a racy kernel counts as found if its best policy found it.
    pub best_policy_recall: f64,
    pub overall_precision: f64,
    /// The same two over the kernels with no declared [`racebench::Limitation`].
    pub best_policy_recall_without_limitations: f64,
    pub overall_precision_without_limitations: f64,
    pub seconds: f64,
}

/// How a report's word reads: `buffer[slot]` (slot within the label's stride) when the
/// buffer is labelled, else `buffer[index]`.
fn word_name(meta: &racebench::Meta, buffer: &str, index: u32) -> String {
    match meta.words.iter().find(|w| w.buffer == buffer) {
        Some(w) if w.stride > 1 => format!("{buffer}[+{}]", index % w.stride),
        Some(_) => buffer.to_string(),
        None => format!("{buffer}[{index}]"),
    }
}

/// Runs one kernel under one policy.
pub fn run_cell(
    case: &dyn Case,
    frags: &Fragments,
    policy: &BenchPolicy,
    cfg: &BenchConfig,
) -> Cell {
    let meta = case.meta();
    let start = Instant::now();
    let mut cell = Cell {
        kernel: meta.name,
        label: meta.label,
        policy: policy.name(),
        runs: 0,
        found: false,
        schedules_to_first: None,
        seconds_to_first: None,
        reported: Vec::new(),
        kind_as_labelled: false,
        false_alarms: Vec::new(),
        oracle_violations: 0,
        oracle_first: None,
        oracle_example: None,
        faults: Vec::new(),
        seconds: 0.0,
    };
    let mut reported = BTreeSet::new();
    let mut alarms = BTreeSet::new();
    for s in 0..cfg.schedules {
        let out: Outcome = case.run(frags, &policy.exec(s));
        cell.runs += 1;
        let mut hit = false;
        if policy.detects() {
            for r in &out.reports {
                let (name, on_label) = match &r.word {
                    Some((b, i)) => (
                        format!("{} {}", r.kind.name(), word_name(meta, b, *i)),
                        meta.words.iter().any(|w| w.contains(b, *i)),
                    ),
                    None => (r.kind.name().to_string(), meta.kinds.contains(&Kind::Hang)),
                };
                let true_report = meta.label == Label::Racy && on_label;
                if true_report {
                    hit = true;
                    cell.kind_as_labelled |= meta.kinds.contains(&r.kind);
                } else {
                    alarms.insert(name.clone());
                }
                reported.insert(name);
            }
        } else {
            let hang = out.reports.iter().any(|r| r.kind == Kind::Hang);
            if hang || out.violation.is_some() {
                let name = if hang { "hang" } else { "oracle" };
                reported.insert(name.to_string());
                if meta.label == Label::Racy {
                    hit = true;
                    cell.kind_as_labelled |= !hang || meta.kinds.contains(&Kind::Hang);
                } else {
                    alarms.insert(name.to_string());
                }
            }
        }
        if let Some(v) = &out.violation {
            cell.oracle_violations += 1;
            if cell.oracle_first.is_none() {
                cell.oracle_first = Some(s + 1);
                cell.oracle_example = Some(v.what.clone());
            }
        }
        for f in out.faults {
            if !cell.faults.contains(&f) {
                cell.faults.push(f);
            }
        }
        if hit && !cell.found {
            cell.found = true;
            cell.schedules_to_first = Some(s + 1);
            cell.seconds_to_first = Some(start.elapsed().as_secs_f64());
            if cfg.stop_at_first {
                break;
            }
        }
    }
    cell.reported = reported.into_iter().collect();
    cell.false_alarms = alarms.into_iter().collect();
    cell.seconds = start.elapsed().as_secs_f64();
    cell
}

fn median<T: Copy + PartialOrd>(mut v: Vec<T>) -> Option<T> {
    v.sort_by(|a, b| a.partial_cmp(b).expect("finite"));
    v.get(v.len().saturating_sub(1) / 2).copied()
}

fn ratio(a: usize, b: usize) -> f64 {
    if b == 0 {
        1.0
    } else {
        a as f64 / b as f64
    }
}

/// Runs the benchmark.
pub fn run(cfg: &BenchConfig) -> Result<BenchResult, BenchError> {
    cfg.validate()?;
    let start = Instant::now();
    let frags = racebench::scene::fragments();
    let cases: Vec<Box<dyn Case>> = racebench::cases()
        .into_iter()
        .filter(|c| cfg.kernels.is_empty() || cfg.kernels.iter().any(|k| k == c.meta().name))
        .collect();
    let jobs: Vec<(usize, usize)> = (0..cases.len())
        .flat_map(|k| (0..cfg.policies.len()).map(move |p| (k, p)))
        .collect();
    let next = AtomicUsize::new(0);
    let cells = Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..cfg.threads.min(jobs.len()) {
            s.spawn(|| loop {
                let j = next.fetch_add(1, Ordering::Relaxed);
                let Some(&(k, p)) = jobs.get(j) else { break };
                let c = run_cell(cases[k].as_ref(), &frags, &cfg.policies[p], cfg);
                cells.lock().expect("no worker panics").push((j, c));
            });
        }
    });
    let mut cells = cells.into_inner().expect("no worker panics");
    cells.sort_by_key(|c| c.0);
    let cells: Vec<Cell> = cells.into_iter().map(|c| c.1).collect();
    let metas: Vec<racebench::Meta> = cases.iter().map(|c| *c.meta()).collect();
    let totals = cfg
        .policies
        .iter()
        .map(|p| totals(&p.name(), &cells, &metas, |_| true))
        .collect();
    let (best, prec) = overall(&cells, &metas, |_| true);
    let (best_nl, prec_nl) = overall(&cells, &metas, |m| m.limitation.is_none());
    Ok(BenchResult {
        schedules: cfg.schedules,
        threads: cfg.threads,
        kernels: metas,
        cells,
        totals,
        best_policy_recall: best,
        overall_precision: prec,
        best_policy_recall_without_limitations: best_nl,
        overall_precision_without_limitations: prec_nl,
        seconds: start.elapsed().as_secs_f64(),
    })
}

fn meta_of<'m>(metas: &'m [racebench::Meta], name: &str) -> &'m racebench::Meta {
    metas
        .iter()
        .find(|m| m.name == name)
        .expect("a cell of a listed kernel")
}

/// One policy's totals over the kernels `keep` keeps.
fn totals(
    policy: &str,
    cells: &[Cell],
    metas: &[racebench::Meta],
    keep: impl Fn(&racebench::Meta) -> bool,
) -> PolicyTotals {
    let mine: Vec<&Cell> = cells
        .iter()
        .filter(|c| c.policy == policy && keep(meta_of(metas, c.kernel)))
        .collect();
    let racy: Vec<&&Cell> = mine.iter().filter(|c| c.label == Label::Racy).collect();
    let found: Vec<&&Cell> = racy.iter().copied().filter(|c| c.found).collect();
    let alarm: Vec<&'static str> = mine
        .iter()
        .filter(|c| !c.false_alarms.is_empty())
        .map(|c| c.kernel)
        .collect();
    let true_cells = mine
        .iter()
        .filter(|c| c.found && c.false_alarms.is_empty())
        .count();
    let reporting = mine
        .iter()
        .filter(|c| c.found || !c.false_alarms.is_empty())
        .count();
    let secs: Vec<f64> = found.iter().filter_map(|c| c.seconds_to_first).collect();
    let scheds: Vec<u64> = found.iter().filter_map(|c| c.schedules_to_first).collect();
    PolicyTotals {
        policy: policy.to_string(),
        racy: racy.len(),
        found: found.len(),
        recall: ratio(found.len(), racy.len()),
        precision: ratio(true_cells, reporting),
        false_alarm_kernels: alarm,
        missed: racy.iter().filter(|c| !c.found).map(|c| c.kernel).collect(),
        found_with_oracle: racy
            .iter()
            .filter(|c| c.found || c.oracle_violations > 0)
            .count(),
        median_seconds_to_detection: median(secs.clone()),
        worst_seconds_to_detection: secs.iter().copied().reduce(f64::max),
        median_schedules_to_detection: median(scheds.clone()),
        worst_schedules_to_detection: scheds.iter().copied().max(),
    }
}

/// Best-policy recall and overall precision (over every kernel and policy cell).
fn overall(
    cells: &[Cell],
    metas: &[racebench::Meta],
    keep: impl Fn(&racebench::Meta) -> bool,
) -> (f64, f64) {
    let kept: Vec<&racebench::Meta> = metas.iter().filter(|m| keep(m)).collect();
    let racy: Vec<&&racebench::Meta> = kept.iter().filter(|m| m.label == Label::Racy).collect();
    let found = racy
        .iter()
        .filter(|m| cells.iter().any(|c| c.kernel == m.name && c.found))
        .count();
    let mine: Vec<&Cell> = cells
        .iter()
        .filter(|c| kept.iter().any(|m| m.name == c.kernel))
        .collect();
    let true_cells = mine
        .iter()
        .filter(|c| c.found && c.false_alarms.is_empty())
        .count();
    let reporting = mine
        .iter()
        .filter(|c| c.found || !c.false_alarms.is_empty())
        .count();
    (ratio(found, racy.len()), ratio(true_cells, reporting))
}
