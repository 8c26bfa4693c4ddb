//! What no paper could show. The race benchmark's recall and precision per schedule policy
//! (`fragrace racebench`, kernels/src/racebench: kernels labelled racy or race-free, each run
//! under every policy, the detector's reports against the labels); then, for every
//! hazard-prone algorithm × policy × in-flight window, the rate of runs with a hazard, the
//! distribution of their EPR and the time to the first hazard; and next to them the same
//! k-buffer on llvmpipe, which cannot race (each pixel's fragments in submission order).

use std::path::Path;
use std::time::Instant;

use serde_json::json;

use super::{ctx, Figure, Paper, PaperConfig, Progress, ReportError, Section, Table};
use crate::plot::{BoxPlot, LinePlot, Sample, Series};
use crate::racebench::{self, BenchConfig, BenchPolicy};
use crate::run::{self, RunSpec, SceneSpec};
use fragrace_kernels::HazardClass;

/// In-flight windows of the grid (`--window`: invocations in flight at once, what stands for
/// a GPU's occupancy).
pub const WINDOWS: [usize; 6] = [1, 2, 4, 8, 16, 64];

/// The scheduled policies of the grid; `parallel` (real threads) is added to each window-free
/// row set.
pub const POLICIES: [&str; 5] = ["random", "pct:2", "pct:3", "warp:32", "far-first"];

/// The windows whose EPR distributions are drawn as box plots.
pub const BOX_WINDOWS: [usize; 2] = [4, 64];

/// One cell of the grid: an algorithm under one policy and window, over `seeds` runs.
#[derive(Clone, Debug, PartialEq)]
pub struct Cell {
    pub algo: String,
    /// A scheduled policy, or `parallel`.
    pub policy: String,
    /// `None` under `parallel` (real threads have no window).
    pub window: Option<usize>,
    /// Per run, in seed order: whether the detector saw a hazard, and the EPR.
    pub hazard: Vec<bool>,
    pub epr: Vec<f64>,
    /// Runs up to and including the first with a hazard, and their wall time in seconds;
    /// `None` when no run had one.
    pub first_hazard: Option<(usize, f64)>,
}

impl Cell {
    pub fn rate(&self) -> f64 {
        self.hazard.iter().filter(|&&h| h).count() as f64 / self.hazard.len().max(1) as f64
    }
}

/// Every hazard-prone algorithm under every policy and window, `seeds` runs each, on
/// `cubes` at 32x32.
pub fn grid(seeds: u64, threads: usize, progress: &dyn Progress) -> Result<Vec<Cell>, ReportError> {
    let mut base = RunSpec::new(SceneSpec::Builtin("cubes".into()), "truth");
    base.width = 32;
    base.height = 32;
    let loaded = ctx(run::load(&base), || "cubes".into())?;
    let truth = ctx(run::truth(&base, &loaded), || "cubes: the truth".into())?;
    let mut cells = Vec::new();
    for algo in fragrace_kernels::algorithms() {
        let info = algo.info();
        if info.hazard != HazardClass::HazardProne {
            continue;
        }
        let mut settings: Vec<(&str, Option<usize>)> = Vec::new();
        for p in POLICIES {
            settings.extend(WINDOWS.iter().map(|&w| (p, Some(w))));
        }
        settings.push(("parallel", None));
        for (policy, window) in settings {
            progress.step(&format!(
                "hazards: {} under {policy}{}",
                info.name,
                window.map(|w| format!(", window {w}")).unwrap_or_default()
            ));
            let mut cell = Cell {
                algo: info.name.into(),
                policy: policy.into(),
                window,
                hazard: Vec::new(),
                epr: Vec::new(),
                first_hazard: None,
            };
            let mut spent = 0.0;
            for seed in 0..seeds {
                let mut s = base.clone();
                s.algo = info.name.into();
                let (exec, p) = match window {
                    Some(_) => ("scheduled", policy),
                    None => ("parallel", "random"),
                };
                s.exec = ctx(
                    run::exec_config(exec, p, seed, Some(threads), window.unwrap_or(64))
                        .map_err(run::RunError::from),
                    || format!("{policy}, window {window:?}"),
                )?;
                let t = Instant::now();
                let c = ctx(run::check_with(&s, &loaded, &truth), || {
                    format!("{} under {policy}, seed {seed}", info.name)
                })?;
                spent += t.elapsed().as_secs_f64();
                let hit = c.hazards().total() > 0;
                if hit && cell.first_hazard.is_none() {
                    cell.first_hazard = Some((seed as usize + 1, spent));
                }
                cell.hazard.push(hit);
                cell.epr.push(c.metrics.epr);
            }
            cells.push(cell);
        }
    }
    Ok(cells)
}

/// The hazard rate against the window, one line per algorithm, under one policy.
pub fn rate_lines(cells: &[Cell], policy: &str) -> Vec<Series> {
    let mut out: Vec<Series> = Vec::new();
    for c in cells.iter().filter(|c| c.policy == policy) {
        let Some(w) = c.window else { continue };
        let point = ((w as f64).log2(), c.rate());
        match out.iter_mut().find(|s| s.name == c.algo) {
            Some(s) => s.points.push(point),
            None => out.push(Series {
                name: c.algo.clone(),
                points: vec![point],
            }),
        }
    }
    out
}

/// The median, over algorithms, of the runs up to the first hazard, per policy and window
/// (cells with no hazard at all are left out of the median; the table lists them).
pub fn first_hazard_lines(cells: &[Cell]) -> Vec<Series> {
    POLICIES
        .iter()
        .map(|&p| {
            let points = WINDOWS
                .iter()
                .filter_map(|&w| {
                    let mut runs: Vec<f64> = cells
                        .iter()
                        .filter(|c| c.policy == p && c.window == Some(w))
                        .filter_map(|c| c.first_hazard.map(|(n, _)| n as f64))
                        .collect();
                    runs.sort_by(f64::total_cmp);
                    (!runs.is_empty()).then(|| ((w as f64).log2(), runs[runs.len() / 2]))
                })
                .collect();
            Series {
                name: p.to_string(),
                points,
            }
        })
        .filter(|s| !s.points.is_empty())
        .collect()
}

/// What the llvmpipe peer measured for its `kbuf-rmw` (the same k-buffer in GLSL), or why
/// there is nothing.
pub enum Peer {
    Measured {
        frames: usize,
        /// EPR of each frame against the peer's own exact capture.
        epr_per_frame: Vec<f64>,
        /// Whether every frame left the same k-buffer, bit for bit.
        identical: bool,
    },
    Absent(String),
}

/// Runs the peer (`python3 PEER MESH --algo kbuf-rmw`) for `frames` frames.
pub fn peer(script: Option<&Path>, mesh: &Path, size: u32, frames: usize) -> Peer {
    let Some(script) = script else {
        return Peer::Absent(
            "no llvmpipe peer given (`--peer PATH/oit.py`, which needs Python with moderngl \
             and Mesa's EGL): nothing measured"
                .into(),
        );
    };
    let out = std::process::Command::new("python3")
        .arg(script)
        .arg(mesh)
        .args(["--algo", "kbuf-rmw", "--k", "8", "--width"])
        .arg(size.to_string())
        .arg("--height")
        .arg(size.to_string())
        .args(["--frames", &frames.to_string(), "--warmup", "0"])
        .env("LP_NUM_THREADS", "2")
        .output();
    let out = match out {
        Ok(o) if o.status.success() => o,
        Ok(o) => {
            let err = String::from_utf8_lossy(&o.stderr);
            return Peer::Absent(format!(
                "the llvmpipe peer {} failed ({}): {}",
                script.display(),
                o.status,
                err.lines().last().unwrap_or("")
            ));
        }
        Err(e) => {
            return Peer::Absent(format!(
                "the llvmpipe peer {} could not run: {e}",
                script.display()
            ))
        }
    };
    let text = String::from_utf8_lossy(&out.stdout);
    let parsed = text
        .lines()
        .last()
        .and_then(|l| serde_json::from_str::<serde_json::Value>(l).ok());
    let Some(v) = parsed else {
        return Peer::Absent(format!(
            "the llvmpipe peer {} printed no JSON line",
            script.display()
        ));
    };
    let epr_per_frame: Vec<f64> = v["epr_per_frame"]
        .as_array()
        .map(|a| a.iter().filter_map(|x| x.as_f64()).collect())
        .unwrap_or_default();
    let identical = text.contains("identical kbuf contents across frames: True");
    Peer::Measured {
        frames: epr_per_frame.len(),
        epr_per_frame,
        identical,
    }
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
    let mut s = Section::new(Paper::Hazards, "Hazards: the race benchmark and the grid");
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
    grid_section(cfg, progress, &mut s)?;
    peer_section(cfg, progress, &mut s)?;
    Ok(s)
}

/// The algorithm × policy × window grid: its table, the rate against the window, the EPR
/// distributions and the runs to the first hazard.
fn grid_section(
    cfg: &PaperConfig,
    progress: &dyn Progress,
    s: &mut Section,
) -> Result<(), ReportError> {
    let seeds = if cfg.quick { 4 } else { 40 };
    let t = Instant::now();
    let cells = grid(seeds, cfg.threads, progress)?;
    let what = format!("{seeds} seeds per cell, cubes 32x32");
    let algos = cells
        .iter()
        .map(|c| c.algo.as_str())
        .fold(Vec::<&str>::new(), |mut v, a| {
            if !v.contains(&a) {
                v.push(a);
            }
            v
        });
    s.text.push(format!(
        "The grid: {} hazard-prone algorithms × {} scheduled policies × {} windows, and \
         parallel (real threads), {seeds} runs each ({} runs, {:.1} s). A run has a hazard \
         when the detector reported one; its EPR is the fraction of covered pixels that differ \
         from the exact result. The time to the first hazard is the number of runs, and their \
         wall time, until one had a hazard.",
        algos.len(),
        POLICIES.len(),
        WINDOWS.len(),
        cells.len() * seeds as usize,
        t.elapsed().as_secs_f64()
    ));
    let round = |x: f64| (x * 1e4).round() / 1e4;
    let rows = cells
        .iter()
        .map(|c| {
            let q = crate::plot::Quartiles::of(&c.epr);
            vec![
                json!(c.algo),
                json!(c.policy),
                json!(c.window.map_or("threads".to_string(), |w| w.to_string())),
                json!(round(c.rate())),
                json!(q.map(|q| round(q.median))),
                json!(q.map(|q| round(q.max))),
                json!(c.first_hazard.map(|(n, _)| n)),
                json!(c.first_hazard.map(|(_, t)| (t * 1e4).round() / 10.0)),
            ]
        })
        .collect();
    s.tables.push(Table {
        id: "hazards-grid".into(),
        title: "Hazard rate, EPR and time to the first hazard per algorithm, policy and window"
            .into(),
        caption: format!(
            "{what}. Empty first-hazard cells: no run of the cell had a hazard. Times in \
             milliseconds, the test or release build the report ran in."
        ),
        columns: [
            "algorithm",
            "policy",
            "window",
            "runs with a hazard (fraction)",
            "median EPR",
            "max EPR",
            "runs to the first hazard",
            "ms to the first hazard",
        ]
        .iter()
        .map(|c| c.to_string())
        .collect(),
        rows,
        command: cfg.command(Paper::Hazards),
    });
    for policy in ["random", "pct:3"] {
        s.figures.push(Figure {
            id: format!("hazards-rate-window-{}", policy.replace(':', "")),
            caption: format!(
                "Fraction of runs in which the detector saw a hazard, against the in-flight \
                 window, for every hazard-prone algorithm, policy {policy} ({what})."
            ),
            plot: LinePlot::new(
                &format!("Runs with a hazard against the in-flight window ({policy})"),
                "log2 of the in-flight window (--window: invocations at once; 6 = 64)",
                "runs with a hazard (fraction)",
                rate_lines(&cells, policy),
            )
            .into(),
            command: cfg.command(Paper::Hazards),
        });
    }
    for w in BOX_WINDOWS {
        let boxes = cells
            .iter()
            .filter(|c| c.window == Some(w) || c.window.is_none())
            .map(|c| Sample {
                name: c.algo.clone(),
                group: c.policy.clone(),
                values: c.epr.clone(),
            })
            .collect();
        s.figures.push(Figure {
            id: format!("hazards-epr-box-window{w}"),
            caption: format!(
                "Distribution of the EPR of the runs of each algorithm under each policy, \
                 window {w} (parallel: real threads, no window). Box: first to third quartile; \
                 bar: median; whiskers: smallest and largest run ({what})."
            ),
            plot: BoxPlot::new(
                &format!("EPR per run, window {w}"),
                "error pixel rate (fraction of covered pixels)",
                boxes,
            )
            .into(),
            command: cfg.command(Paper::Hazards),
        });
    }
    let first = first_hazard_lines(&cells);
    if !first.is_empty() {
        s.figures.push(Figure {
            id: "hazards-first-hazard".into(),
            caption: format!(
                "Runs until the first run with a hazard, the median over the hazard-prone \
                 algorithms, per policy, against the window ({what}; the table has every cell \
                 and its wall time)."
            ),
            plot: LinePlot::new(
                "Runs to the first hazard against the in-flight window",
                "log2 of the in-flight window (--window: invocations at once; 6 = 64)",
                "runs to the first hazard (median over algorithms)",
                first,
            )
            .into(),
            command: cfg.command(Paper::Hazards),
        });
    }
    Ok(())
}

/// kb-rmw next to the peer's `kbuf-rmw` on llvmpipe: same mesh, size and k.
fn peer_section(
    cfg: &PaperConfig,
    progress: &dyn Progress,
    s: &mut Section,
) -> Result<(), ReportError> {
    let (size, frames) = if cfg.quick { (64, 4) } else { (256, 20) };
    let mesh = Path::new("assets/bunny.obj.gz");
    if !mesh.exists() {
        s.text.push(
            "llvmpipe comparison skipped: assets/bunny.obj.gz is not here (run the report \
             from the repository)."
                .into(),
        );
        return Ok(());
    }
    progress.step("hazards: kbuf-rmw on llvmpipe");
    let peer = peer(cfg.peer.as_deref(), mesh, size, frames);
    let mut base = RunSpec::new(
        SceneSpec::Obj {
            path: mesh.into(),
            sha256: None,
        },
        "kb-rmw",
    );
    base.width = size;
    base.height = size;
    base.params.k = 8;
    let loaded = ctx(run::load(&base), || "bunny".into())?;
    let truth = ctx(run::truth(&base, &loaded), || "bunny: the truth".into())?;
    let mut rows = Vec::new();
    match &peer {
        Peer::Measured {
            frames,
            epr_per_frame,
            identical,
        } => rows.push(vec![
            json!("llvmpipe (Mesa), GLSL kbuf-rmw"),
            json!(frames),
            json!(epr_per_frame.iter().filter(|&&e| e > 0.0).count()),
            json!(epr_per_frame.iter().copied().fold(0.0, f64::max)),
            json!(if *identical { "yes" } else { "no" }),
        ]),
        Peer::Absent(why) => s.text.push(format!("llvmpipe: {why}.")),
    }
    for (exec, policy, window) in [
        ("parallel", "random", 64),
        ("scheduled", "random", 4),
        ("scheduled", "random", 64),
    ] {
        progress.step(&format!("hazards: kb-rmw on bunny, {exec}"));
        let (mut wrong, mut worst) = (0, 0.0f64);
        let mut digests = std::collections::HashSet::new();
        for seed in 0..frames as u64 {
            let mut sp = base.clone();
            sp.exec = ctx(
                run::exec_config(exec, policy, seed, Some(cfg.threads), window)
                    .map_err(run::RunError::from),
                || exec.to_string(),
            )?;
            let c = ctx(run::check_with(&sp, &loaded, &truth), || {
                format!("kb-rmw {exec}, seed {seed}")
            })?;
            wrong += usize::from(c.metrics.epr > 0.0);
            worst = worst.max(c.metrics.epr);
            digests.insert(run::digest(&c.rendered.result));
        }
        rows.push(vec![
            json!(match exec {
                "parallel" => format!("fragrace kb-rmw, parallel ({} threads)", cfg.threads),
                _ => format!("fragrace kb-rmw, scheduled {policy}, window {window}"),
            }),
            json!(frames),
            json!(wrong),
            json!((worst * 1e4).round() / 1e4),
            json!(if digests.len() == 1 { "yes" } else { "no" }),
        ]);
    }
    s.tables.push(Table {
        id: "hazards-llvmpipe".into(),
        title: "The k-buffer's read-modify-write race: llvmpipe against fragrace".into(),
        caption: format!(
            "bunny {size}x{size}, k = 8; runs (frames) with a wrong k-buffer against the exact \
             one, the worst EPR, and whether every run left the same result. llvmpipe gives \
             each pixel's fragments to one thread in submission order, so its k-buffer never \
             races: 0 wrong frames is what it can show, whatever the algorithm's hazard."
        ),
        columns: [
            "renderer",
            "runs",
            "runs with a wrong result",
            "worst EPR",
            "every run identical",
        ]
        .iter()
        .map(|c| c.to_string())
        .collect(),
        rows,
        command: cfg.command(Paper::Hazards),
    });
    Ok(())
}
