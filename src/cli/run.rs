//! `fragrace render`, `check` and `replay`: one run (or a few schedules of it) against the
//! truth, its summary printed and its pictures written.

use std::path::PathBuf;

use fragrace_emu::HazardKind;

use super::error::CliError;
use super::memory::{merge, within_budget};
use super::options::RunOptions;
use super::outputs::{check_outputs, list_written, write_outputs};
use super::progress::progress;
use crate::run::{self, RunSpec, SceneSpec};

/// The options of `check`: a run, over `schedules` seeds.
#[derive(Clone, Debug, clap::Args)]
pub struct CheckOptions {
    #[command(flatten)]
    pub run: RunOptions,
    /// Schedules (seeds seed, seed+1, ...) to run under the scheduled executor.
    #[arg(long, default_value_t = 1)]
    pub schedules: u64,
}

/// The options of `replay`.
#[derive(Clone, Debug, clap::Args)]
pub struct ReplayOptions {
    /// The case file.
    pub case: PathBuf,
    #[arg(long)]
    pub json: bool,
    /// Refuse a case whose estimated peak memory is above this (default: half of the
    /// physical memory).
    #[arg(long, value_name = "SIZE")]
    pub memory_limit: Option<String>,
}

/// `render`: one run, its summary printed and its pictures written.
pub fn cmd_render(a: &RunOptions, given: &[String]) -> Result<(), CliError> {
    let spec = a.spec(given)?;
    check_outputs(a, &spec.algo)?;
    let loaded = run::load(&spec)?;
    super::outputs::warn_scene(&loaded);
    let memory = within_budget(&spec, &loaded, false, a.memory_limit.as_deref())?;
    let bar = progress(0, "rendering");
    let rendered = run::render(&spec, &loaded)?;
    bar.finish_and_clear();
    let written = write_outputs(a, &spec, &loaded, &rendered, None)?;
    let mut summary = run::summary_json(&spec, &loaded, None, &rendered);
    summary["shade"] = serde_json::json!(written.shade);
    summary["picture_ms"] = serde_json::json!(written.picture_ms);
    let written = written.files;
    if let Some(base) = crate::culling::baseline(&spec, &loaded)? {
        summary["occupancy"] = crate::culling::summary(&rendered, None, Some(&base));
    }
    merge(&mut summary, &memory);
    summary["peak_rss_bytes"] = serde_json::json!(crate::budget::peak_rss());
    if a.json {
        println!("{summary}");
    } else {
        print_summary(&summary);
    }
    list_written(&written, a.json);
    Ok(())
}

fn print_summary(v: &serde_json::Value) {
    println!(
        "{} on {} ({} triangles) at {}x{}, {} executor{}",
        v["algo"].as_str().unwrap_or("?"),
        v["scene"].as_str().unwrap_or("?"),
        v["triangles"],
        v["width"],
        v["height"],
        v["exec"].as_str().unwrap_or("?"),
        match v["policy"].as_str() {
            Some(p) => format!(" (policy {p}, seed {})", v["seed"]),
            None => format!(" ({} threads)", v["threads"]),
        }
    );
    println!(
        "  fragments {}   covered pixels {}   max depth complexity {}",
        v["fragments"], v["covered_pixels"], v["max_depth_complexity"]
    );
    println!(
        "  hazards: lost updates {}, races {}, torn {}   faults {}   dropped {}",
        v["hazards"]["lost_updates"],
        v["hazards"]["races"],
        v["hazards"]["torn"],
        v["faults"],
        v["dropped"]
    );
    if !v["epr"].is_null() {
        println!(
            "  EPR {:.6} ({} error pixels): error pixel rate, covered pixels whose result differs from the truth",
            v["epr"].as_f64().unwrap_or(0.0),
            v["error_pixels"],
        );
        println!(
            "  R_h {:.6}: robustness, fragments kept over fragments the algorithm should keep",
            v["robustness"].as_f64().unwrap_or(0.0),
        );
        println!(
            "  C_p {:.4}: coplanarity, covered pixels with two fragments at exactly the same depth",
            v["coplanarity"].as_f64().unwrap_or(0.0)
        );
    }
    let im = &v["image"];
    if !im.is_null() {
        println!(
            "  image vs the truth's composite: image EPR {:.6}  PSNR {:.2} dB  max channel difference {:.6}",
            im["image_epr"].as_f64().unwrap_or(0.0),
            im["psnr"].as_f64().unwrap_or(f64::INFINITY),
            im["max_diff"].as_f64().unwrap_or(0.0)
        );
    }
    println!(
        "  storage {:.1} bytes/pixel   {:.1} ms",
        v["bytes_per_pixel"].as_f64().unwrap_or(0.0),
        v["wall_ms"].as_f64().unwrap_or(0.0)
    );
    let o = &v["occupancy"];
    if !o.is_null() {
        println!(
            "  occupancy culling (d = {}, range {}, fill {}): culled {} of {} fragments ({:.1} %){}",
            o["d"],
            o["range"].as_str().unwrap_or("?"),
            o["fill"].as_str().unwrap_or("?"),
            o["culled_fragments"],
            o["peel_fragments"],
            100.0 * o["culled_fraction"].as_f64().unwrap_or(0.0),
            match o["saved"]["invocation_ratio"].as_f64() {
                Some(r) => format!(
                    "; k-buffer invocations {:.1} % of the unculled run's, {} memory accesses saved",
                    100.0 * r,
                    o["saved"]["memory_ops"]
                ),
                None => String::new(),
            }
        );
    }
    if let Some(checks) = v["checks"].as_array().filter(|c| !c.is_empty()) {
        println!("  the algorithm's own invariants:");
        for c in checks {
            let ok = c["passed"].as_bool().unwrap_or(false);
            println!(
                "    [{}] {}: {}",
                if ok { "ok" } else { "FAIL" },
                c["name"].as_str().unwrap_or(""),
                c["detail"].as_str().unwrap_or("")
            );
        }
    }
}

/// `check`: the run over `schedules` seeds against the truth; the worst one's summary
/// printed and its pictures written.
pub fn cmd_check(a: &CheckOptions, given: &[String]) -> Result<(), CliError> {
    let spec = a.run.spec(given)?;
    crate::validate::at_least_one("schedules", a.schedules)?;
    check_outputs(&a.run, &spec.algo)?;
    let loaded = run::load(&spec)?;
    super::outputs::warn_scene(&loaded);
    let memory = within_budget(&spec, &loaded, true, a.run.memory_limit.as_deref())?;
    // More than one schedule only under the scheduled executor (`spec_of` refuses
    // --schedules elsewhere).
    let n = a.schedules;
    let bar = progress(n + 1, "computing the truth");
    let truth = run::truth(&spec, &loaded)?;
    bar.inc(1);
    let base_seed = spec.schedule().map(|s| s.seed).unwrap_or(0);
    let mut worst: Option<(RunSpec, run::Checked)> = None;
    let mut totals = fragrace_emu::HazardCounts::default();
    let mut anomalous_runs = 0u64;
    let mut eprs = Vec::new();
    for i in 0..n {
        bar.set_message(if n > 1 {
            format!("running schedule {} of {n}", i + 1)
        } else {
            "running the algorithm".to_string()
        });
        let s = spec.with_seed(base_seed + i);
        let c = run::check_with(&s, &loaded, &truth)?;
        bar.inc(1);
        totals.add(&c.hazards());
        eprs.push(c.metrics.epr);
        if c.anomalous() {
            anomalous_runs += 1;
        }
        let score = |c: &run::Checked| (c.metrics.error_pixels, c.hazards().total());
        if worst.as_ref().is_none_or(|(_, w)| score(&c) > score(w)) {
            worst = Some((s, c));
        }
    }
    bar.finish_and_clear();
    let (wspec, w) = worst.expect("at least one run");
    let written = write_outputs(&a.run, &wspec, &loaded, &w.rendered, Some((&w, &truth)))?;
    let mut summary = run::summary_json(&wspec, &loaded, Some(&w), &w.rendered);
    summary["shade"] = serde_json::json!(written.shade);
    if let Some(base) = crate::culling::baseline(&wspec, &loaded)? {
        summary["occupancy"] = crate::culling::summary(&w.rendered, Some(&w.metrics), Some(&base));
    }
    merge(&mut summary, &memory);
    summary["peak_rss_bytes"] = serde_json::json!(crate::budget::peak_rss());
    let verdict = crate::verdict::verdict(&w, &totals);
    summary["verdict"] = serde_json::json!(verdict);
    summary["schedules"] = serde_json::json!(n);
    summary["anomalous_runs"] = serde_json::json!(anomalous_runs);
    summary["hazards_total"] = serde_json::json!({"lost_updates": totals.lost_updates, "races": totals.races, "torn": totals.torn});
    summary["epr_max"] = serde_json::json!(eprs.iter().cloned().fold(0.0, f64::max));
    summary["epr_mean"] = serde_json::json!(eprs.iter().sum::<f64>() / eprs.len() as f64);
    summary["hazard_list"] = serde_json::json!(w
        .rendered
        .result
        .report
        .hazard_list
        .iter()
        .take(8)
        .collect::<Vec<_>>());
    summary["faults_list"] = serde_json::json!(w
        .rendered
        .result
        .report
        .faults
        .iter()
        .take(8)
        .collect::<Vec<_>>());
    let replay = wspec.command("check");
    summary["replay"] = serde_json::json!(replay);
    // Threads race for real under `parallel`: a rerun gives other numbers. The scheduled
    // executor reproduces a run bit for bit.
    let reproducible =
        spec.schedule().is_some() || spec.exec.mode == fragrace_emu::ExecMode::Ordered;
    summary["reproducible"] = serde_json::json!(reproducible);
    let scheduled = (!reproducible).then(|| {
        let mut s = wspec.clone();
        s.exec.mode = fragrace_emu::ExecMode::Scheduled(fragrace_emu::ScheduleConfig::default());
        format!("{} --schedules 8", s.command("check"))
    });
    summary["reproduce_with"] = serde_json::json!(scheduled.as_ref().unwrap_or(&replay));
    let picture = a.run.out.as_deref().filter(|_| a.run.turntable.is_none());
    // The picture too is reproduced bit for bit by its replay.
    let replay_picture = match (picture, written.shade) {
        (Some(p), Some(shade)) => format!("{replay} --shade {shade} --out {}", p.display()),
        _ => replay.clone(),
    };
    let plain = crate::verdict::plain_words(&w, &verdict, &replay_picture, picture);
    summary["plain_words"] = serde_json::json!(plain);
    if a.run.json {
        println!("{summary}");
    } else {
        println!("{}", verdict.text);
        for line in &plain {
            println!("  {line}");
        }
        print_summary(&summary);
        if n > 1 {
            println!(
                "  over {n} schedules: {anomalous_runs} anomalous, EPR max {:.6} mean {:.6}, hazards {} lost updates, {} races, {} torn",
                summary["epr_max"].as_f64().unwrap_or(0.0),
                summary["epr_mean"].as_f64().unwrap_or(0.0),
                totals.lost_updates,
                totals.races,
                totals.torn
            );
        }
        // The first hazard of each kind (races are usually the most numerous).
        let list = &w.rendered.result.report.hazard_list;
        for kind in [HazardKind::LostUpdate, HazardKind::Torn, HazardKind::Race] {
            if let Some(h) = list.iter().find(|h| h.kind == kind) {
                println!(
                    "  {} on {}[{}] at step {}: pixel ({}, {}) primitive {} vs primitive {}",
                    h.kind.name(),
                    h.buffer,
                    h.index,
                    h.step,
                    h.victim.x,
                    h.victim.y,
                    h.victim.primitive,
                    h.other.primitive
                );
            }
        }
        for f in w.rendered.result.report.faults.iter().take(3) {
            println!(
                "  fault at pixel ({}, {}) primitive {}: {}",
                f.invocation.x, f.invocation.y, f.invocation.primitive, f.kind
            );
        }
        if let Some(sched) = &scheduled {
            println!(
                "  parallel runs are not reproducible (threads race for real; a rerun gives other numbers).\n  To reproduce hazards exactly, run the scheduled executor (same seed, same bits):\n    {sched}"
            );
        } else if w.anomalous() {
            println!("  worst case replays with:\n    {replay}");
        }
    }
    list_written(&written.files, a.run.json);
    Ok(())
}

/// `replay`: reruns a case file and says whether its observation still holds. `Ok(false)`
/// when it no longer does (the binary then exits with status 1).
pub fn cmd_replay(a: &ReplayOptions) -> Result<bool, CliError> {
    let (path, json) = (a.case.as_path(), a.json);
    let case = crate::case::read(path)?;
    let loaded = run::load(&case.spec).map_err(|source| CliError::CaseScene {
        path: path.to_path_buf(),
        source,
    })?;
    within_budget(&case.spec, &loaded, true, a.memory_limit.as_deref())?;
    drop(loaded);
    let r = crate::case::replay(&case)?;
    if json {
        println!(
            "{}",
            serde_json::json!({"exact": r.exact, "holds": r.holds, "recorded": case.observed, "observed": r.observed})
        );
    } else {
        println!("{}: {}", path.display(), case.verdict);
        match &case.spec.scene {
            // Its triangles are in the case file only.
            SceneSpec::Inline { .. } => {
                println!("  rerun with: {} replay {}", run::CLI, path.display())
            }
            _ => println!("  rerun with: {}", case.spec.command("check")),
        }
        if let (Some(b), Some(a)) = (&case.original_size, &case.shrunk_size) {
            println!(
                "  shrunk from {} triangles, {} pixels, window {} to {} triangles, {} pixels, window {}, {} schedule steps",
                b.triangles, b.pixels, b.window, a.triangles, a.pixels, a.window, a.schedule_steps
            );
        }
        println!("  recorded: {:?}", case.observed.signature());
        println!(
            "  observed: {:?}   {}",
            r.observed.signature(),
            r.observed.first_hazard.clone().unwrap_or_default()
        );
        println!(
            "  {}",
            if r.exact {
                "reproduced exactly (bit-identical result)"
            } else if r.holds {
                "the observation holds, but the result is not bit-identical"
            } else {
                "the observation no longer holds"
            }
        );
    }
    Ok(r.holds)
}
