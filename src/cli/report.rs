//! `fragrace report`: tables of measured EPR, R_h, bytes per pixel and time, and EPR over views.

use anyhow::{Context, Result};
use fragrace::run::{self, RunSpec, SceneSpec};
use fragrace::scene::Camera;

use crate::{within_budget, ReportArgs};

pub(crate) fn cmd_report(a: &ReportArgs, given: &[String]) -> Result<()> {
    fragrace::validate::options_for_exec(&a.exec, given.iter().map(String::as_str))?;
    let algos: Vec<String> = if a.algo.is_empty() {
        fragrace_kernels::names()
            .into_iter()
            .map(String::from)
            .collect()
    } else {
        a.algo.clone()
    };
    let exec = run::exec_config(&a.exec, &a.policy, a.seed, a.threads, 64)?;
    let occupancy = a.occupancy.get(crate::takes_range(&a.algo.join(",")))?;
    if let Some(o) = occupancy {
        o.validate(a.k)?;
    }
    // The occupancy culling of one algorithm's runs, and its row name.
    let culled = |name: &str| {
        let takes = fragrace_kernels::algorithm(name).is_some_and(|x| x.takes_occupancy());
        match occupancy {
            Some(o) if takes => (Some(o), format!("{name}+occ")),
            _ => (None, name.to_string()),
        }
    };
    let scene_spec = |s: &str| {
        if s.contains(".obj") {
            SceneSpec::Obj {
                path: s.into(),
                sha256: None,
            }
        } else {
            SceneSpec::Builtin(s.into())
        }
    };
    if let Some(out) = &a.out {
        fragrace::output::check_writable(out, "the plot (--out)")?;
    }
    if let Some(views) = a.views {
        let scene = a.scenes.first().context("one scene for --views")?;
        let bar = crate::progress(u64::from(views) * (algos.len() as u64 + 1), "views");
        let mut series: Vec<(String, Vec<f64>)> =
            algos.iter().map(|n| (n.clone(), Vec::new())).collect();
        for v in 0..views {
            let mut spec = RunSpec::new(scene_spec(scene), "truth");
            spec.width = a.size;
            spec.height = a.size;
            spec.camera = Camera::new(360.0 * v as f32 / views as f32, 0.0);
            spec.exec = exec.clone();
            spec.params.k = a.k;
            let loaded = run::load(&spec)?;
            report_budget(&spec, &loaded, &algos, a.memory_limit.as_deref())?;
            bar.set_message(format!("view {} of {views}: the truth", v + 1));
            let truth = run::truth(&spec, &loaded)?;
            bar.inc(1);
            for (name, eprs) in &mut series {
                let mut s = spec.clone();
                s.algo = name.clone();
                s.params.occupancy = culled(name).0;
                bar.set_message(format!("view {} of {views}: {name}", v + 1));
                eprs.push(run::check_with(&s, &loaded, &truth)?.metrics.epr);
                bar.inc(1);
            }
        }
        bar.finish_and_clear();
        println!("azimuth,{}", algos.join(","));
        for v in 0..views as usize {
            let row: Vec<String> = series.iter().map(|(_, e)| format!("{:.6}", e[v])).collect();
            println!("{:.1},{}", 360.0 * v as f32 / views as f32, row.join(","));
        }
        if let Some(out) = &a.out {
            fragrace::output::write_plot(out, "EPR over azimuth", &series)?;
        }
        return Ok(());
    }
    println!("| algorithm | scene | EPR | R_h | bytes/pixel | dropped | hazards (lost/race/torn) | time ms |");
    println!("|---|---|---|---|---|---|---|---|");
    let bar = crate::progress(a.scenes.len() as u64 * (algos.len() as u64 + 1), "");
    for scene in &a.scenes {
        let mut spec = RunSpec::new(scene_spec(scene), "truth");
        spec.width = a.size;
        spec.height = a.size;
        spec.exec = exec.clone();
        spec.params.k = a.k;
        let loaded = run::load(&spec)?;
        report_budget(&spec, &loaded, &algos, a.memory_limit.as_deref())?;
        bar.set_message(format!("{scene}: the truth"));
        let truth = run::truth(&spec, &loaded)?;
        bar.inc(1);
        for name in &algos {
            let mut s = spec.clone();
            s.algo = name.clone();
            let (occ, row) = culled(name);
            s.params.occupancy = occ;
            bar.set_message(format!("{scene}: {name}"));
            let c = run::check_with(&s, &loaded, &truth)?;
            bar.inc(1);
            let r = &c.rendered.result;
            let hz = r.report.hazards;
            // Rows as they come (above the progress bar on a terminal).
            bar.suspend(|| {
                println!(
                    "| {} | {} | {:.6} | {:.4} | {:.1} | {} | {}/{}/{} | {:.1} |",
                    row,
                    scene,
                    c.metrics.epr,
                    c.metrics.robustness,
                    r.storage_bytes as f64 / (a.size as f64 * a.size as f64),
                    r.dropped,
                    hz.lost_updates,
                    hz.races,
                    hz.torn,
                    c.rendered.wall_ms
                )
            });
        }
    }
    bar.finish_and_clear();
    Ok(())
}

/// Checks every algorithm of a report against the budget before its scene's truth is
/// computed (each is checked against the truth, one after the other).
fn report_budget(
    spec: &RunSpec,
    loaded: &run::Loaded,
    algos: &[String],
    limit: Option<&str>,
) -> Result<()> {
    for name in algos {
        let mut s = spec.clone();
        s.algo = name.clone();
        s.validate()?;
        within_budget(&s, loaded, true, limit).with_context(|| format!("algorithm {name}"))?;
    }
    Ok(())
}
