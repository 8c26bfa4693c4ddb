//! `fragrace fuzz`: a campaign (or one shard of it) with a progress line, or `--merge`.

use std::path::PathBuf;
use std::time::Instant;

use super::error::{CliError, OptionError};
use super::options::{takes_range, OccupancyOptions};
use crate::fuzz::{CampaignState, Shard};
use crate::run;

/// The options of `fuzz`. Each field is the command line's option of the same name (its doc
/// comment is the option's help), parsed but not yet checked.
#[derive(Clone, Debug, clap::Args)]
pub struct FuzzOptions {
    /// Stop after this long (e.g. 60s, 10m, 1h).
    #[arg(long)]
    pub time: Option<String>,
    #[arg(long)]
    pub iterations: Option<u64>,
    /// Algorithms to fuzz (repeat or comma-separate; default: all but truth).
    #[arg(long, value_delimiter = ',')]
    pub algo: Vec<String>,
    /// Parallel workers, each running one iteration at a time (default: one per available
    /// CPU, fewer if the campaign's memory estimate for them passes --memory-limit). With
    /// several, which run of a signature is shrunk into its case file depends on which
    /// worker gets there first; `--jobs 1` runs the iterations in order, the same every
    /// time.
    #[arg(long)]
    pub jobs: Option<usize>,
    #[arg(long, default_value = "fuzz-out")]
    pub out: PathBuf,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Continue the campaign in --out where it stopped.
    #[arg(long)]
    pub resume: bool,
    /// A directory of OBJ meshes to draw scenes from as well.
    #[arg(long)]
    pub meshes: Option<PathBuf>,
    /// Seconds to shrink each new case.
    #[arg(long, default_value_t = 20)]
    pub shrink_secs: u64,
    /// Largest viewport side.
    #[arg(long, default_value_t = 48)]
    pub max_size: u32,
    /// Schedules run on each generated scene: its scene is loaded and its truth computed
    /// once, then this many executions of its run (other seeds) are checked against it.
    #[arg(long, default_value_t = crate::fuzz::DEFAULT_SCHEDULES)]
    pub schedules: u64,
    /// Only these built-in scenes (comma-separated; default: a random mix).
    #[arg(long, value_delimiter = ',')]
    pub scene: Vec<String>,
    /// Occupancy culling for every fuzzed algorithm that takes it (default: none).
    #[command(flatten)]
    pub occupancy: OccupancyOptions,
    #[arg(long)]
    pub json: bool,
    /// Refuse a campaign whose runs in flight are estimated above this much memory (default:
    /// half of the physical memory).
    #[arg(long, value_name = "SIZE")]
    pub memory_limit: Option<String>,
    /// Run only the I-th of N disjoint slices of the campaign's iterations (I from 1): N
    /// machines each run one slice, `--merge` combines their directories.
    #[arg(long, value_name = "I/N", conflicts_with = "merge")]
    pub shard: Option<String>,
    /// Combine the case directories of a campaign's shards into --out (deduplicated by
    /// signature, the smallest case of each kept) and print the merged summary.
    /// The options of a campaign's runs have no effect on a merge, and are refused with it.
    #[arg(long, value_name = "DIR", num_args = 1.., conflicts_with_all = [
        "time", "iterations", "resume", "algo", "jobs", "seed", "meshes", "shrink_secs",
        "max_size", "scene", "memory_limit", "occupancy", "range", "occupancy_fill",
        "schedules",
    ])]
    pub merge: Vec<PathBuf>,
}

/// `--time`: a number and a unit (s, ms, m or min, h; seconds without one).
pub fn parse_duration(s: &str) -> Result<std::time::Duration, OptionError> {
    let (num, unit) = s.split_at(
        s.find(|c: char| !c.is_ascii_digit() && c != '.')
            .unwrap_or(s.len()),
    );
    let v: f64 = num.parse().map_err(|source| OptionError::Duration {
        value: s.to_string(),
        source,
    })?;
    let secs = match unit {
        "" | "s" => v,
        "ms" => v / 1e3,
        "m" | "min" => v * 60.0,
        "h" => v * 3600.0,
        _ => {
            return Err(OptionError::DurationUnit {
                value: s.to_string(),
            })
        }
    };
    Ok(std::time::Duration::from_secs_f64(secs))
}

/// The occupancy culling a fuzz campaign forces, checked against its algorithms: at
/// least one of them must take it, and `d` must hold the largest k the campaign draws (16).
fn fuzz_occupancy(
    a: &FuzzOptions,
) -> Result<Option<fragrace_kernels::occupancy::Occupancy>, CliError> {
    let Some(occ) = a.occupancy.get(takes_range(&a.algo.join(",")))? else {
        return Ok(None);
    };
    occ.validate(16)?;
    let all = fragrace_kernels::algorithms();
    let takers: Vec<&str> = all
        .iter()
        .filter(|x| x.takes_occupancy())
        .map(|x| x.info().name)
        .collect();
    if !a.algo.is_empty() && !a.algo.iter().any(|n| takers.contains(&n.as_str())) {
        return Err(OptionError::OccupancyWithoutTaker {
            algos: a.algo.clone(),
            takers,
        }
        .into());
    }
    Ok(Some(occ))
}

/// `fuzz`: a campaign (or one shard of it) with a progress line, or with `merge` the
/// shards' directories combined; then the summary. Ctrl-C stops the campaign cleanly (the
/// runs in flight finish, the state is saved).
pub fn cmd_fuzz(a: &FuzzOptions) -> Result<(), CliError> {
    use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
    use std::sync::Arc;
    if !a.merge.is_empty() {
        let state = crate::fuzz::merge(&a.merge, &a.out)?;
        return print_summary(a, &state);
    }
    let shard = match &a.shard {
        Some(s) => s.parse::<Shard>()?,
        None => Shard::WHOLE,
    };
    let cfg = crate::fuzz::FuzzConfig {
        out: a.out.clone(),
        time: a.time.as_deref().map(parse_duration).transpose()?,
        iterations: a.iterations,
        algos: a.algo.clone(),
        // (Set below, once the memory limit is known.)
        jobs: a.jobs.unwrap_or(1),
        seed: a.seed,
        resume: a.resume,
        meshes: a.meshes.clone(),
        shrink_budget: std::time::Duration::from_secs(a.shrink_secs),
        max_size: a.max_size,
        scenes: a.scene.clone(),
        occupancy: fuzz_occupancy(a)?,
        shard,
        schedules: a.schedules,
    };
    if cfg.time.is_none() && cfg.iterations.is_none() {
        return Err(OptionError::CampaignWithoutBudget.into());
    }
    if let Some(n) = cfg.iterations {
        crate::validate::at_least_one("iterations", n)?;
    }
    if cfg.time.is_some_and(|t| t.is_zero()) {
        return Err(OptionError::ZeroTime {
            value: a.time.clone().unwrap_or_default(),
        }
        .into());
    }
    let (limit, source) = crate::budget::limit(a.memory_limit.as_deref())?;
    let cfg = crate::fuzz::FuzzConfig {
        jobs: a.jobs.unwrap_or_else(|| cfg.default_jobs(limit)),
        ..cfg
    };
    cfg.validate()?;
    crate::budget::check_campaign(&cfg.memory_estimate(), limit, &source)?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        // Ctrl-C: finish the runs in flight, save the state, exit cleanly.
        let _ = ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed));
    }
    let progress = crate::fuzz::Progress {
        executions: AtomicU64::new(0),
        cases: AtomicU64::new(0),
        violations: AtomicU64::new(0),
    };
    let bar = indicatif::ProgressBar::new_spinner();
    bar.set_style(
        indicatif::ProgressStyle::with_template("{spinner} {elapsed_precise} {msg}")
            .expect("valid template"),
    );
    let start = Instant::now();
    let state = std::thread::scope(|s| {
        let h = s.spawn(|| crate::fuzz::campaign(&cfg, &stop, &progress));
        while !h.is_finished() {
            let e = progress.executions.load(Ordering::Relaxed);
            bar.set_message(format!(
                "{e} executions ({:.1}/s), {} cases, {} violations",
                e as f64 / start.elapsed().as_secs_f64().max(1e-3),
                progress.cases.load(Ordering::Relaxed),
                progress.violations.load(Ordering::Relaxed)
            ));
            bar.tick();
            std::thread::sleep(std::time::Duration::from_millis(100));
        }
        h.join().expect("campaign thread")
    })?;
    bar.finish_and_clear();
    print_summary(a, &state)
}

/// The campaign's summary: counts, then one line per finding signature with its case.
fn print_summary(a: &FuzzOptions, state: &CampaignState) -> Result<(), CliError> {
    if a.json {
        println!("{}", serde_json::to_string(&state)?);
        return Ok(());
    }
    if let Some(s) = state.shard {
        println!("shard {s} of the campaign of seed {}", state.seed);
    }
    if !state.merged_shards.is_empty() {
        let count = state.merged_shards[0].count;
        let missing: Vec<String> = (1..=count)
            .map(|i| Shard { index: i, count })
            .filter(|s| !state.merged_shards.contains(s))
            .map(|s| s.to_string())
            .collect();
        println!(
            "merged {} of {count} shards of the campaign of seed {}{}",
            state.merged_shards.len(),
            state.seed,
            if missing.is_empty() {
                String::new()
            } else {
                format!(" (missing: {})", missing.join(", "))
            }
        );
    }
    let jobs = match state.jobs {
        0 => String::new(),
        1 => ", 1 job".to_string(),
        j => format!(", {j} jobs"),
    };
    println!(
        "{} executions in {:.1} s ({:.1}/s{jobs}): {} violations, {} expected findings, {} case files in {}",
        state.executions,
        state.elapsed_s,
        state.executions as f64 / state.elapsed_s.max(1e-3),
        state.violations,
        state.expected_findings,
        state.cases.len(),
        a.out.display()
    );
    let total: f64 = state.phases.named().iter().map(|(_, s)| s).sum();
    if total > 0.0 {
        let parts: Vec<String> = state
            .phases
            .named()
            .iter()
            .map(|(name, s)| format!("{name} {s:.1} s ({:.0} %)", 100.0 * s / total))
            .collect();
        println!(
            "  {} schedules per scene; where the workers' time went: {}",
            state.schedules,
            parts.join(", ")
        );
    }
    println!(
        "  violations: runs where an algorithm broke what its class promises (a hazard-free one raced or differed, a fault, a failed invariant): bugs\n  expected findings: hazard-prone algorithms showing the race they are known for: not bugs, the hazards this tool exists to show"
    );
    println!("  runs per finding (algorithm, hazard class, the principal hazard and its buffer), one shrunk case file each:");
    for (sig, n) in &state.signatures {
        println!("  {n:>6}  {sig}");
        if let Some(c) = state.case_of.get(sig) {
            println!("          {} replay {}", run::CLI, a.out.join(c).display());
        }
    }
    let algos = state
        .coverage
        .keys()
        .map(|k| k.split(" x ").next().unwrap_or(""))
        .collect::<std::collections::BTreeSet<_>>()
        .len();
    println!(
        "  coverage: {} algorithm x policy pairs over {algos} algorithms",
        state.coverage.len()
    );
    // Cases of an earlier campaign resumed here, whose signature is not recorded.
    let named: std::collections::BTreeSet<&String> = state.case_of.values().collect();
    for c in state.cases.iter().filter(|c| !named.contains(c)) {
        println!(
            "  case: {}  ({} replay {})",
            c,
            run::CLI,
            a.out.join(c).display()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_take_a_unit_and_refuse_others_by_value() {
        assert_eq!(
            parse_duration("90s").expect("seconds"),
            std::time::Duration::from_secs(90)
        );
        assert_eq!(
            parse_duration("2m").expect("minutes"),
            std::time::Duration::from_secs(120)
        );
        assert_eq!(
            parse_duration("1.5h").expect("hours"),
            std::time::Duration::from_secs(5400)
        );
        let e = parse_duration("3d").expect_err("days are not a unit");
        assert_eq!(e.to_string(), "bad duration unit in `3d` (use s, m or h)");
        let e = parse_duration("x").expect_err("not a number");
        assert_eq!(e.to_string(), "bad duration `x`");
        assert!(
            std::error::Error::source(&e).is_some(),
            "the parse error is its source"
        );
    }
}
