//! `fragrace fuzz`: a campaign (or one shard of it) with a progress line, or `--merge`.

use std::path::PathBuf;
use std::time::Instant;

use super::error::{CliError, OptionError};
use super::options::{takes_range, OccupancyOptions};
use crate::fuzz::{CampaignState, Shard};
use crate::run;

/// The options of `fuzz`. Each field is the command line's option of the same name
/// (`fragrace fuzz --help` says what each means), parsed but not yet checked.
#[derive(Clone, Debug)]
pub struct FuzzOptions {
    pub time: Option<String>,
    pub iterations: Option<u64>,
    pub algo: Vec<String>,
    pub jobs: usize,
    pub out: PathBuf,
    pub seed: u64,
    pub resume: bool,
    pub meshes: Option<PathBuf>,
    pub shrink_secs: u64,
    pub max_size: u32,
    pub schedules: u64,
    pub scene: Vec<String>,
    pub occupancy: OccupancyOptions,
    pub json: bool,
    pub memory_limit: Option<String>,
    pub shard: Option<String>,
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
        jobs: a.jobs,
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
    cfg.validate()?;
    let (limit, source) = crate::budget::limit(a.memory_limit.as_deref())?;
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
    println!(
        "{} executions in {:.1} s ({:.1}/s): {} violations, {} expected findings, {} case files in {}",
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
