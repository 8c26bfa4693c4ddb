//! `fragrace fuzz`: a campaign (or one shard of it) with a progress line, or `--merge`.

use std::time::Instant;

use anyhow::{bail, Context, Result};
use fragrace::fuzz::{CampaignState, Shard};
use fragrace::run;

use crate::FuzzArgs;

fn parse_duration(s: &str) -> Result<std::time::Duration> {
    let (num, unit) = s.split_at(
        s.find(|c: char| !c.is_ascii_digit() && c != '.')
            .unwrap_or(s.len()),
    );
    let v: f64 = num.parse().with_context(|| format!("bad duration `{s}`"))?;
    let secs = match unit {
        "" | "s" => v,
        "ms" => v / 1e3,
        "m" | "min" => v * 60.0,
        "h" => v * 3600.0,
        _ => bail!("bad duration unit in `{s}` (use s, m or h)"),
    };
    Ok(std::time::Duration::from_secs_f64(secs))
}

/// The occupancy culling a fuzz campaign forces, checked against its algorithms: at
/// least one of them must take it, and `d` must hold the largest k the campaign draws (16).
fn fuzz_occupancy(a: &FuzzArgs) -> Result<Option<fragrace_kernels::occupancy::Occupancy>> {
    let Some(occ) = a.occupancy.get(crate::takes_range(&a.algo.join(",")))? else {
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
        bail!(
            "--occupancy: none of {} runs behind occupancy culling; the algorithms that do: {}",
            a.algo.join(", "),
            takers.join(", ")
        );
    }
    Ok(Some(occ))
}

pub(crate) fn cmd_fuzz(a: &FuzzArgs) -> Result<()> {
    use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
    use std::sync::Arc;
    if !a.merge.is_empty() {
        let state = fragrace::fuzz::merge(&a.merge, &a.out)?;
        return print_summary(a, &state);
    }
    let shard = match &a.shard {
        Some(s) => s.parse::<Shard>()?,
        None => Shard::WHOLE,
    };
    let cfg = fragrace::fuzz::FuzzConfig {
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
        bail!("give --time or --iterations (a campaign needs a budget)");
    }
    if let Some(n) = cfg.iterations {
        fragrace::validate::at_least_one("iterations", n)?;
    }
    if cfg.time.is_some_and(|t| t.is_zero()) {
        bail!(
            "--time {}: a campaign needs a positive time",
            a.time.as_deref().unwrap_or("")
        );
    }
    cfg.validate()?;
    let (limit, source) = fragrace::budget::limit(a.memory_limit.as_deref())?;
    fragrace::budget::check_campaign(&cfg.memory_estimate(), limit, &source)?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        // Ctrl-C: finish the runs in flight, save the state, exit cleanly.
        let _ = ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed));
    }
    let progress = fragrace::fuzz::Progress {
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
        let h = s.spawn(|| fragrace::fuzz::campaign(&cfg, &stop, &progress));
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
fn print_summary(a: &FuzzArgs, state: &CampaignState) -> Result<()> {
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
