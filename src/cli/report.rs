//! `fragrace report`: tables of measured EPR, R_h, bytes per pixel and time, and EPR over
//! views (in parallel with `--jobs`, one slice of them with `--shard I/N`).

use std::path::PathBuf;

use rayon::prelude::*;

use super::error::{CliError, OptionError};
use super::memory::within_budget;
use super::options::{takes_range, OccupancyOptions};
use super::progress::progress;
use crate::fuzz::Shard;
use crate::run::{self, RunSpec, SceneSpec};
use crate::scene::Camera;

/// The options of `report`. Each field is the command line's option of the same name (its doc
/// comment is the option's help), parsed but not yet checked.
#[derive(Clone, Debug, clap::Args)]
pub struct ReportOptions {
    /// Algorithms (default: all).
    #[arg(long, value_delimiter = ',')]
    pub algo: Vec<String>,
    /// Scenes: built-in names or OBJ paths.
    #[arg(long, value_delimiter = ',', default_value = "hairball,cubes")]
    pub scenes: Vec<String>,
    #[arg(long, default_value_t = 256)]
    pub size: u32,
    /// ordered | parallel | scheduled (scheduled runs use --policy and --seed).
    #[arg(long, default_value = "parallel")]
    pub exec: String,
    #[arg(long, default_value = "random")]
    pub policy: String,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[arg(long)]
    pub threads: Option<usize>,
    #[arg(long, default_value_t = 8)]
    pub k: u32,
    /// Instead of the table: EPR of each algorithm over this many azimuths, as CSV on stdout
    /// and a plot to --out (.svg or .png). In a sweep, `--algo NAME@EXEC` runs one algorithm
    /// under another executor (e.g. `kb-rmw,kb-rmw@scheduled`).
    #[arg(long)]
    pub views: Option<u32>,
    /// Views computed at once (--views): a work-stealing pool of this many threads, each
    /// view's runs using --threads as well. Memory: this many runs at once.
    #[arg(long, default_value_t = 1, requires = "views")]
    pub jobs: usize,
    /// Only the I-th of N disjoint slices of the views (--views; I from 1): view v goes to
    /// slice v % N + 1, so N machines can each compute one; the slices' CSV rows together
    /// are the whole sweep's (sort them by azimuth).
    #[arg(long, value_name = "I/N", requires = "views")]
    pub shard: Option<String>,
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Occupancy culling for the algorithms that take it (their rows are named `NAME+occ`);
    /// the others run as they are.
    #[command(flatten)]
    pub occupancy: OccupancyOptions,
    /// Refuse a report whose largest run is estimated above this much memory (default: half
    /// of the physical memory).
    #[arg(long, value_name = "SIZE")]
    pub memory_limit: Option<String>,
    /// Instead of the table: the seeds' tables and figures, measured, written to --out DIR
    /// (index.html, SVG and PNG per figure, CSV and Markdown per table, report.json).
    /// depth-fighting, bucket, occupancy, merging, presorted, hazards (comma-separated), or
    /// all.
    #[arg(long, value_name = "SECTIONS", conflicts_with_all = [
        "views", "algo", "scenes", "size", "exec", "policy", "seed", "k", "jobs", "shard",
        "memory_limit", "occupancy", "range", "occupancy_fill",
    ])]
    pub paper: Option<String>,
    /// --paper: built-in and shipped scenes only, small images, few views (minutes).
    #[arg(long, requires = "paper")]
    pub quick: bool,
    /// --paper: a directory of meshes (.obj, .obj.gz) for the full report (default: the
    /// shipped meshes of assets/).
    #[arg(long, value_name = "DIR", requires = "paper", conflicts_with = "quick")]
    pub models: Option<PathBuf>,
    /// --paper: the llvmpipe peer's script (oit.py, with Python's moderngl), run by the
    /// hazards section next to the k-buffer's race; without it the page says it is absent.
    #[arg(long, value_name = "FILE", requires = "paper")]
    pub peer: Option<PathBuf>,
}

/// `report`: the table of every algorithm on every scene, or with `views` a sweep of EPR
/// over azimuths, or with `paper` the seeds' tables and figures.
pub fn cmd_report(a: &ReportOptions, given: &[String]) -> Result<(), CliError> {
    if let Some(papers) = &a.paper {
        return cmd_paper(a, papers);
    }
    // `NAME@EXEC` runs one algorithm of a view sweep under another executor than --exec;
    // the scheduled executor's options then apply to it.
    let overridden = a
        .algo
        .iter()
        .filter_map(|n| n.split_once('@').map(|(_, e)| e));
    let execs: Vec<&str> = std::iter::once(a.exec.as_str()).chain(overridden).collect();
    if a.views.is_none() && execs.len() > 1 {
        return Err(OptionError::ExecOverrideWithoutViews {
            exec: a.exec.clone(),
        }
        .into());
    }
    let scheduled = execs.contains(&"scheduled");
    let checked = if scheduled {
        "scheduled"
    } else {
        a.exec.as_str()
    };
    crate::validate::options_for_exec(checked, given.iter().map(String::as_str))?;
    let algos: Vec<String> = if a.algo.is_empty() {
        fragrace_kernels::names()
            .into_iter()
            .map(String::from)
            .collect()
    } else {
        a.algo.clone()
    };
    let exec = run::exec_config(&a.exec, &a.policy, a.seed, a.threads, 64)?;
    // Each algorithm (row or line) with its executor.
    let runs: Vec<(String, fragrace_emu::ExecConfig)> = algos
        .iter()
        .map(|spec| match spec.split_once('@') {
            Some((name, e)) => Ok((
                name.to_string(),
                run::exec_config(e, &a.policy, a.seed, a.threads, 64).map_err(|source| {
                    CliError::AlgoExec {
                        algo: spec.clone(),
                        source,
                    }
                })?,
            )),
            None => Ok((spec.clone(), exec.clone())),
        })
        .collect::<Result<_, CliError>>()?;
    let occupancy = a.occupancy.get(takes_range(&a.algo.join(",")))?;
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
        crate::output::check_writable(out, "the plot (--out)")?;
    }
    if let Some(views) = a.views {
        let scene = a.scenes.first().ok_or(OptionError::ViewsWithoutScene)?;
        crate::validate::at_least_one("views", views.into())?;
        let shard = match &a.shard {
            Some(s) => s.parse::<Shard>()?,
            None => Shard::WHOLE,
        };
        let max_jobs = fragrace_emu::exec::max_threads();
        if !(1..=max_jobs).contains(&a.jobs) {
            return Err(OptionError::Jobs {
                jobs: a.jobs,
                max: max_jobs,
            }
            .into());
        }
        let mine: Vec<u32> = (0..views).filter(|&v| shard.contains(v.into())).collect();
        let azimuth = |v: u32| 360.0 * v as f32 / views as f32;
        let view_spec = |v: u32| {
            let mut spec = RunSpec::new(scene_spec(scene), "truth");
            spec.width = a.size;
            spec.height = a.size;
            spec.camera = Camera::new(azimuth(v), 0.0);
            spec.exec = exec.clone();
            spec.params.k = a.k;
            spec
        };
        // Every view's runs within the budget, `jobs` of them at once, before any runs.
        if let Some(&v) = mine.first() {
            let spec = view_spec(v);
            let loaded = run::load(&spec)?;
            report_budget(&spec, &loaded, &runs, a.memory_limit.as_deref(), a.jobs)?;
        }
        let bar = progress(mine.len() as u64 * (algos.len() as u64 + 1), "views");
        // The views are independent runs: a work-stealing pool (rayon) shares them out.
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(a.jobs)
            .build()
            .map_err(CliError::Pool)?;
        let rows: Vec<Vec<f64>> = pool.install(|| {
            mine.par_iter()
                .map(|&v| -> Result<Vec<f64>, CliError> {
                    let spec = view_spec(v);
                    let loaded = run::load(&spec)?;
                    bar.set_message(format!("view {} of {views}: the truth", v + 1));
                    let truth = run::truth(&spec, &loaded)?;
                    bar.inc(1);
                    runs.iter()
                        .map(|(name, exec)| {
                            let mut s = spec.clone();
                            s.algo = name.clone();
                            s.exec = exec.clone();
                            s.params.occupancy = culled(name).0;
                            bar.set_message(format!("view {} of {views}: {name}", v + 1));
                            let epr = run::check_with(&s, &loaded, &truth)?.metrics.epr;
                            bar.inc(1);
                            Ok(epr)
                        })
                        .collect()
                })
                .collect::<Result<Vec<_>, CliError>>()
        })?;
        bar.finish_and_clear();
        println!("azimuth,{}", algos.join(","));
        for (v, row) in mine.iter().zip(&rows) {
            let row: Vec<String> = row.iter().map(|e| format!("{e:.6}")).collect();
            println!("{:.1},{}", azimuth(*v), row.join(","));
        }
        if let Some(out) = &a.out {
            let series = algos
                .iter()
                .enumerate()
                .map(|(i, n)| crate::plot::Series {
                    name: n.clone(),
                    points: mine
                        .iter()
                        .zip(&rows)
                        .map(|(&v, r)| (azimuth(v) as f64, r[i]))
                        .collect(),
                })
                .collect();
            // A mesh by its file name: the directory it was read from is the machine's, not
            // the figure's.
            let name = std::path::Path::new(scene)
                .file_name()
                .map_or(scene.to_string(), |n| n.to_string_lossy().into_owned());
            let mut plot = crate::plot::LinePlot::new(
                &format!(
                    "Error pixel rate over {views} views of {name} ({0}x{0}, k = {1})",
                    a.size, a.k
                ),
                "azimuth (degrees)",
                "error pixel rate (EPR)",
                series,
            );
            plot.size = (1000, 560);
            plot.write(out)?;
        }
        return Ok(());
    }
    println!("| algorithm | scene | EPR | R_h | bytes/pixel | dropped | hazards (lost/race/torn) | time ms |");
    println!("|---|---|---|---|---|---|---|---|");
    let bar = progress(a.scenes.len() as u64 * (algos.len() as u64 + 1), "");
    for scene in &a.scenes {
        let mut spec = RunSpec::new(scene_spec(scene), "truth");
        spec.width = a.size;
        spec.height = a.size;
        spec.exec = exec.clone();
        spec.params.k = a.k;
        let loaded = run::load(&spec)?;
        report_budget(&spec, &loaded, &runs, a.memory_limit.as_deref(), 1)?;
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
/// computed (each is checked against the truth, one after the other; `jobs` such runs at
/// once).
fn report_budget(
    spec: &RunSpec,
    loaded: &run::Loaded,
    runs: &[(String, fragrace_emu::ExecConfig)],
    limit: Option<&str>,
    jobs: usize,
) -> Result<(), CliError> {
    let (limit_bytes, source) = crate::budget::limit(limit)?;
    for (name, exec) in runs {
        let mut s = spec.clone();
        s.algo = name.clone();
        s.exec = exec.clone();
        s.validate()?;
        if jobs == 1 {
            within_budget(&s, loaded, true, limit).map_err(|source| CliError::AlgoBudget {
                algo: name.clone(),
                source,
            })?;
            continue;
        }
        let one = crate::budget::estimate(&s, loaded, true);
        let all = crate::budget::MemoryEstimate {
            bytes: one.bytes.saturating_mul(jobs as u64),
            fragments: one.fragments,
            parts: vec![(
                format!(
                    "--jobs {jobs} x {} for one view",
                    crate::budget::human(one.bytes)
                ),
                one.bytes.saturating_mul(jobs as u64),
            )],
        };
        crate::budget::check(&all, limit_bytes, &source).map_err(|source| {
            CliError::AlgoBudget {
                algo: name.clone(),
                source,
            }
        })?;
    }
    Ok(())
}

/// `report --paper SECTIONS --out DIR`: the library's report ([`crate::report`]), with a
/// progress bar naming the figure or table being made.
fn cmd_paper(a: &ReportOptions, papers: &str) -> Result<(), CliError> {
    let out = a.out.clone().ok_or(OptionError::PaperWithoutOut)?;
    let cfg = crate::report::PaperConfig {
        papers: crate::report::Paper::parse_list(papers)?,
        out,
        quick: a.quick,
        models: a.models.clone(),
        peer: a.peer.clone(),
        threads: a
            .threads
            .unwrap_or_else(fragrace_emu::exec::default_threads),
    };
    let bar = progress(0, "report");
    let step = |m: &str| bar.set_message(m.to_string());
    let written = crate::report::generate(&cfg, &step)?;
    bar.finish_and_clear();
    println!(
        "{} ({} files, {:.1} s)",
        written.index.display(),
        written.files.len(),
        written.seconds
    );
    Ok(())
}
