//! The `fragrace` command line.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};
use fragrace::run::{self, RunSpec, SceneSpec};
use fragrace::scene::Camera;
use fragrace_emu::HazardKind;
use fragrace_kernels::Params;

#[derive(Parser)]
#[command(
    name = "fragrace",
    version,
    about = "A software GPU that makes the race hazards of multi-fragment rendering visible, reproducible and measurable"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene with one algorithm (an OIT image, or a heatmap for `count`).
    Render(RunArgs),
    /// Run an algorithm (over N schedules) and compare it with the exact ground truth.
    Check(CheckArgs),
    /// List the algorithms (with --json: their declared properties) and built-in scenes.
    List {
        #[arg(long)]
        json: bool,
    },
    /// Measure throughput: fragments and triangles per second, scheduled steps per second.
    Bench(BenchArgs),
    /// Fuzz campaign: random scenes x algorithms x schedules, shrunk case files for findings.
    Fuzz(FuzzArgs),
    /// Rerun a case file and say whether its observation still holds, bit for bit.
    Replay {
        case: PathBuf,
        #[arg(long)]
        json: bool,
    },
    /// Tables of measured EPR, R_h, bytes per pixel and time (markdown), and EPR over views.
    Report(ReportArgs),
}

#[derive(Args)]
struct FuzzArgs {
    /// Stop after this long (e.g. 60s, 10m, 1h).
    #[arg(long)]
    time: Option<String>,
    #[arg(long)]
    iterations: Option<u64>,
    /// Algorithms to fuzz (repeat or comma-separate; default: all but truth).
    #[arg(long, value_delimiter = ',')]
    algo: Vec<String>,
    /// Parallel workers.
    #[arg(long, default_value_t = 1)]
    jobs: usize,
    #[arg(long, default_value = "fuzz-out")]
    out: PathBuf,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Continue the campaign in --out where it stopped.
    #[arg(long)]
    resume: bool,
    /// A directory of OBJ meshes to draw scenes from as well.
    #[arg(long)]
    meshes: Option<PathBuf>,
    /// Seconds to shrink each new case.
    #[arg(long, default_value_t = 20)]
    shrink_secs: u64,
    /// Largest viewport side.
    #[arg(long, default_value_t = 48)]
    max_size: u32,
    /// Only these built-in scenes (comma-separated; default: a random mix).
    #[arg(long, value_delimiter = ',')]
    scene: Vec<String>,
    /// Occupancy culling with D words per pixel for every fuzzed algorithm that takes it
    /// (default: a quarter of their runs culled, with random D and range).
    #[arg(long, value_name = "D")]
    occupancy: Option<u32>,
    /// With --occupancy: exact, bbox or hull.
    #[arg(long)]
    range: Option<fragrace_kernels::occupancy::RangeSource>,
    /// With --occupancy: atomic or plain (racy by design).
    #[arg(long)]
    occupancy_fill: Option<fragrace_kernels::occupancy::FillMode>,
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
struct ReportArgs {
    /// Algorithms (default: all).
    #[arg(long, value_delimiter = ',')]
    algo: Vec<String>,
    /// Scenes: built-in names or OBJ paths.
    #[arg(long, value_delimiter = ',', default_value = "hairball,cubes")]
    scenes: Vec<String>,
    #[arg(long, default_value_t = 256)]
    size: u32,
    /// ordered | parallel | scheduled (scheduled runs use --policy and --seed).
    #[arg(long, default_value = "parallel")]
    exec: String,
    #[arg(long, default_value = "random")]
    policy: String,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[arg(long)]
    threads: Option<usize>,
    #[arg(long, default_value_t = 8)]
    k: u32,
    /// Instead of the table: EPR of each algorithm over this many azimuths (PNG plot to --out).
    #[arg(long)]
    views: Option<u32>,
    #[arg(long)]
    out: Option<PathBuf>,
    /// Occupancy culling with D words per pixel for the algorithms that take it (their
    /// rows are named `NAME+occ`); the others run as they are.
    #[arg(long, value_name = "D")]
    occupancy: Option<u32>,
    /// With --occupancy: exact, bbox or hull.
    #[arg(long)]
    range: Option<fragrace_kernels::occupancy::RangeSource>,
}

#[derive(Args, Clone)]
struct RunArgs {
    /// A built-in scene (see `fragrace list`).
    #[arg(long, default_value = "cubes", conflicts_with = "obj")]
    scene: String,
    /// An OBJ file (plain or .gz) instead of a built-in scene.
    #[arg(long)]
    obj: Option<PathBuf>,
    #[arg(long, default_value = "truth")]
    algo: String,
    #[arg(long, default_value_t = 512)]
    width: u32,
    #[arg(long, default_value_t = 512)]
    height: u32,
    /// Degrees about +Y (0: eye on +Z, 90: on +X).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    azimuth: f32,
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    elevation: f32,
    /// ordered | parallel | scheduled
    #[arg(long, default_value = "parallel")]
    exec: String,
    /// Scheduling policy: random, pct:D, warp:N, reverse, fifo, far-first, bytes:HEX.
    #[arg(long, default_value = "random")]
    policy: String,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Invocations in flight under the scheduled executor.
    #[arg(long, default_value_t = 64)]
    window: usize,
    /// Scheduled: pixels per side of the blocks fragments are admitted by.
    #[arg(long, default_value_t = 4)]
    block: u32,
    /// Scheduled: interleave only invocations about to touch the same address or pixel.
    #[arg(long)]
    reduce: bool,
    /// Per-mille probability that a weak compare-exchange fails spuriously.
    #[arg(long, default_value_t = 0)]
    spurious_cas: u32,
    /// Parallel: lanes per warp (fragments shaded together by one thread).
    #[arg(long, default_value_t = 64)]
    lanes: usize,
    /// Parallel: lanes run one after the other instead of in SIMT lockstep (one memory
    /// access each per turn). Faster; races then come only from other threads.
    #[arg(long)]
    no_lockstep: bool,
    /// Parallel: most triangles of one tile per unit of work; smaller units put more
    /// threads on one tile at once (when the pass's fixed-function results commute).
    #[arg(long, default_value_t = 128)]
    segment: u32,
    /// Parallel: `auto` runs passes that need nothing of the framebuffer (no depth or
    /// stencil test, no colour target: counting, captures) unbinned, chunks of triangles
    /// set up, rasterized and shaded by whichever thread takes them; `always` bins every
    /// pass into tiles.
    #[arg(long, default_value = "auto", value_parser = parse_binning)]
    binning: fragrace::emu::Binning,
    /// Scheduled: lockstep forward progress in warps of N lanes (no independent thread
    /// scheduling, as on pre-Volta GPUs): lanes spinning in a loop hold back their
    /// warp-mates past it, so a spinlock whose holder shares their warp deadlocks.
    /// 0: lanes progress independently.
    #[arg(long, default_value_t = 0)]
    simt: u32,
    /// kb-spinlock: lock attempts before a fragment gives up (4294967295: never).
    #[arg(long, default_value_t = Params::default().spin_cap)]
    spin_cap: u32,
    /// k of the k-buffers.
    #[arg(long, default_value_t = 8)]
    k: u32,
    /// Opacity of every fragment in the OIT composite.
    #[arg(long, default_value_t = 0.3)]
    alpha: f32,
    /// Occupancy-map culling in front of the k-buffer's capture pass, with D words (32 D
    /// depth sub-intervals) per pixel, 1 to 64 and at least k/32 (`fragrace list` says
    /// which algorithms take it).
    #[arg(long, value_name = "D")]
    occupancy: Option<u32>,
    /// Occupancy culling, and the bucket schemes (bdp, bdp2, adp): the per-pixel depth
    /// range from the scene (`exact`), its bounding box (`bbox`) or its convex hull
    /// (`hull`). Default exact.
    #[arg(long)]
    range: Option<fragrace_kernels::occupancy::RangeSource>,
    /// Occupancy culling: set the map's bits with `atomic` OR (default), or with a `plain`
    /// load, OR and store (racy by design: bits are lost).
    #[arg(long)]
    occupancy_fill: Option<fragrace_kernels::occupancy::FillMode>,
    /// Output PNG.
    #[arg(long)]
    out: Option<PathBuf>,
    /// For `count`: per-pixel counts as little-endian u32, row-major, top row first.
    #[arg(long)]
    raw_out: Option<PathBuf>,
    /// Directory for heatmaps (depth complexity, errors, hazards, bucket collisions).
    #[arg(long)]
    heatmap: Option<PathBuf>,
    /// Print one JSON object on stdout.
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
struct CheckArgs {
    #[command(flatten)]
    run: RunArgs,
    /// Schedules (seeds seed, seed+1, ...) to run under the scheduled executor.
    #[arg(long, default_value_t = 1)]
    schedules: u64,
}

#[derive(Args)]
struct BenchArgs {
    #[command(flatten)]
    run: RunArgs,
    /// Frames to time (the median is reported).
    #[arg(long, default_value_t = 10)]
    frames: usize,
    #[arg(long, default_value_t = 2)]
    warmup: usize,
    /// Also measure the machine's floor under the frame (`--algo count` only): its atomic
    /// adds alone on the same threads, and with the allocation of a zeroed buffer.
    #[arg(long)]
    floor: bool,
}

fn spec_of(a: &RunArgs) -> Result<RunSpec> {
    let scene = match &a.obj {
        Some(p) => {
            if !p.exists() {
                bail!("{}: file not found", p.display());
            }
            let bytes =
                std::fs::read(p).with_context(|| format!("{}: cannot read", p.display()))?;
            SceneSpec::Obj {
                path: p.clone(),
                sha256: Some(fragrace::scene::obj::content_hash(&bytes)),
            }
        }
        None => SceneSpec::Builtin(a.scene.clone()),
    };
    let mut exec = run::exec_config(&a.exec, &a.policy, a.seed, a.threads, a.window)
        .map_err(anyhow::Error::msg)?;
    exec.block = a.block.max(1);
    exec.reduce = a.reduce;
    exec.spurious_cas_per_mille = a.spurious_cas.min(1000);
    exec.batch = a.lanes.max(1);
    exec.lockstep = !a.no_lockstep;
    exec.segment = a.segment.max(1);
    exec.binning = a.binning;
    exec.simt = a.simt;
    if fragrace_kernels::algorithm(&a.algo).is_none() {
        bail!(
            "unknown algorithm `{}`; known: {}",
            a.algo,
            fragrace_kernels::names().join(", ")
        );
    }
    Ok(RunSpec {
        scene,
        camera: Camera::new(a.azimuth, a.elevation),
        width: a.width,
        height: a.height,
        algo: a.algo.clone(),
        params: Params {
            k: a.k.max(1),
            alpha: a.alpha,
            spin_cap: a.spin_cap.max(1),
            occupancy: occupancy_of(a)?,
            range: a.range.unwrap_or_default(),
            ..Params::default()
        },
        exec,
    })
}

/// The occupancy-culling parameters of a run; `--range` and `--occupancy-fill` mean
/// nothing without `--occupancy` and are refused alone (`--range` alone is the depth range
/// of the algorithms that take one, the bucket schemes).
fn occupancy_of(a: &RunArgs) -> Result<Option<fragrace_kernels::occupancy::Occupancy>> {
    let takes_range = fragrace_kernels::algorithm(&a.algo).is_some_and(|x| x.takes_range());
    match a.occupancy {
        Some(d) => Ok(Some(fragrace_kernels::occupancy::Occupancy {
            d,
            range: a.range.unwrap_or_default(),
            fill: a.occupancy_fill.unwrap_or_default(),
        })),
        None if (a.range.is_some() && !takes_range) || a.occupancy_fill.is_some() => {
            bail!("--range and --occupancy-fill configure occupancy culling: add --occupancy D (1 to 64)")
        }
        None => Ok(None),
    }
}

/// The occupancy culling a fuzz campaign forces, checked against its algorithms: at
/// least one of them must take it, and `d` must hold the largest k the campaign draws (16).
fn fuzz_occupancy(a: &FuzzArgs) -> Result<Option<fragrace_kernels::occupancy::Occupancy>> {
    let Some(d) = a.occupancy else {
        if a.range.is_some() || a.occupancy_fill.is_some() {
            bail!("--range and --occupancy-fill configure occupancy culling: add --occupancy D (1 to 64)");
        }
        return Ok(None);
    };
    let occ = fragrace_kernels::occupancy::Occupancy {
        d,
        range: a.range.unwrap_or_default(),
        fill: a.occupancy_fill.unwrap_or_default(),
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

fn main() {
    if let Err(e) = real_main() {
        eprintln!("error: {e:#}");
        std::process::exit(2);
    }
}

fn real_main() -> Result<()> {
    let cli = Cli::parse();
    // A kernel panic is a reported fault, not a crash: keep the default hook's noise out.
    std::panic::set_hook(Box::new(|_| {}));
    match cli.command {
        Command::Render(a) => cmd_render(&a),
        Command::Check(a) => cmd_check(&a),
        Command::List { json } => cmd_list(json),
        Command::Bench(a) => cmd_bench(&a),
        Command::Fuzz(a) => cmd_fuzz(&a),
        Command::Replay { case, json } => cmd_replay(&case, json),
        Command::Report(a) => cmd_report(&a),
    }
}

fn cmd_render(a: &RunArgs) -> Result<()> {
    let spec = spec_of(a)?;
    let loaded = run::load(&spec)?;
    let rendered = run::render(&spec, &loaded)?;
    write_outputs(a, &spec, &rendered, None)?;
    let mut summary = run::summary_json(&spec, &loaded, None, &rendered);
    if let Some(base) = fragrace::culling::baseline(&spec, &loaded)? {
        summary["occupancy"] = fragrace::culling::summary(&rendered, None, Some(&base));
    }
    if a.json {
        println!("{summary}");
    } else {
        print_summary(&summary);
    }
    Ok(())
}

fn write_outputs(
    a: &RunArgs,
    spec: &RunSpec,
    r: &run::Rendered,
    checked: Option<&run::Checked>,
) -> Result<()> {
    let res = &r.result;
    if let Some(path) = &a.out {
        if let Some(img) = &res.image {
            fragrace::output::write_rgba(path, spec.width, spec.height, img)?;
        } else if let Some(c) = &res.counts {
            fragrace::output::write_heatmap(path, spec.width, spec.height, c)?;
        } else {
            bail!("algorithm `{}` produces no image", spec.algo);
        }
    }
    if let Some(path) = &a.raw_out {
        let Some(c) = &res.counts else {
            bail!("--raw-out needs a counting algorithm (count, count-plain)")
        };
        let bytes: Vec<u8> = c.iter().flat_map(|v| v.to_le_bytes()).collect();
        fragrace::output::write_atomic(path, &bytes)?;
    }
    if let Some(dir) = &a.heatmap {
        std::fs::create_dir_all(dir)?;
        if let Some(c) = &res.counts {
            fragrace::output::write_heatmap(
                &dir.join("depth-complexity.png"),
                spec.width,
                spec.height,
                c,
            )?;
        }
        if let Some(c) = &res.collisions {
            // Bucket schemes: fragments that lost their bucket, per pixel.
            fragrace::output::write_heatmap(
                &dir.join("collisions.png"),
                spec.width,
                spec.height,
                c,
            )?;
        }
        if !res.report.hazard_heat.is_empty() {
            fragrace::output::write_heatmap(
                &dir.join("hazards.png"),
                spec.width,
                spec.height,
                &res.report.hazard_heat,
            )?;
        }
        if let Some(c) = checked {
            let errs: Vec<u32> = c.metrics.error_mask.iter().map(|&e| e as u32).collect();
            fragrace::output::write_heatmap(
                &dir.join("errors.png"),
                spec.width,
                spec.height,
                &errs,
            )?;
            if !c.metrics.culled_heat.is_empty() {
                fragrace::output::write_heatmap(
                    &dir.join("culled.png"),
                    spec.width,
                    spec.height,
                    &c.metrics.culled_heat,
                )?;
            }
        }
    }
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
            "  EPR {:.6}  ({} error pixels)   R_h {:.6}   C_p {:.4}",
            v["epr"].as_f64().unwrap_or(0.0),
            v["error_pixels"],
            v["robustness"].as_f64().unwrap_or(0.0),
            v["coplanarity"].as_f64().unwrap_or(0.0)
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
    if let Some(checks) = v["checks"].as_array() {
        for c in checks {
            let ok = c["passed"].as_bool().unwrap_or(false);
            println!(
                "  [{}] {}: {}",
                if ok { "ok" } else { "FAIL" },
                c["name"].as_str().unwrap_or(""),
                c["detail"].as_str().unwrap_or("")
            );
        }
    }
}

fn cmd_check(a: &CheckArgs) -> Result<()> {
    let spec = spec_of(&a.run)?;
    let loaded = run::load(&spec)?;
    let truth = run::truth(&spec, &loaded)?;
    let n = if spec.schedule().is_some() {
        a.schedules.max(1)
    } else {
        1
    };
    let base_seed = spec.schedule().map(|s| s.seed).unwrap_or(0);
    let mut worst: Option<(RunSpec, run::Checked)> = None;
    let mut totals = fragrace_emu::HazardCounts::default();
    let mut anomalous_runs = 0u64;
    let mut eprs = Vec::new();
    for i in 0..n {
        let s = spec.with_seed(base_seed + i);
        let c = run::check_with(&s, &loaded, &truth)?;
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
    let (wspec, w) = worst.expect("at least one run");
    write_outputs(&a.run, &wspec, &w.rendered, Some(&w))?;
    let mut summary = run::summary_json(&wspec, &loaded, Some(&w), &w.rendered);
    if let Some(base) = fragrace::culling::baseline(&wspec, &loaded)? {
        summary["occupancy"] =
            fragrace::culling::summary(&w.rendered, Some(&w.metrics), Some(&base));
    }
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
    if a.run.json {
        println!("{summary}");
    } else {
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
        if w.anomalous() {
            println!("  worst case replays with:\n    {replay}");
        }
    }
    Ok(())
}

fn cmd_list(json: bool) -> Result<()> {
    let algos = fragrace_kernels::algorithms();
    let infos: Vec<_> = algos
        .iter()
        .map(|a| {
            let mut v = serde_json::to_value(a.info()).expect("AlgoInfo serializes");
            v["occupancy"] = serde_json::json!(a.takes_occupancy());
            v
        })
        .collect();
    if json {
        println!(
            "{}",
            serde_json::json!({"algorithms": infos, "scenes": fragrace::scene::builtin_names(), "policies": ["random", "pct:D", "warp:N", "reverse", "fifo", "far-first", "bytes:HEX"]})
        );
        return Ok(());
    }
    println!(
        "{:<24} {:<12} {:<16} {:<26} memory per pixel",
        "algorithm", "family", "hazard class", "passes"
    );
    for a in &algos {
        let i = a.info();
        println!(
            "{:<24} {:<12} {:<16} {:<26} {}",
            i.name,
            i.family,
            i.hazard.name(),
            i.passes,
            i.memory
        );
    }
    let takers: Vec<_> = algos
        .iter()
        .filter(|a| a.takes_occupancy())
        .map(|a| a.info().name)
        .collect();
    println!("\noccupancy culling (--occupancy D): {}", takers.join(", "));
    println!("\nscenes: {}", fragrace::scene::builtin_names().join(", "));
    println!("policies: random, pct:D, warp:N, reverse, fifo, far-first, bytes:HEX");
    Ok(())
}

fn cmd_bench(a: &BenchArgs) -> Result<()> {
    let spec = spec_of(&a.run)?;
    // The floor replays `count`'s operation (one atomic add per fragment); other
    // algorithms do other things per fragment.
    if a.floor && spec.algo != "count" {
        bail!(
            "--floor measures the floor of `count` (its atomic adds alone), not of `{}`",
            spec.algo
        );
    }
    let loaded = run::load(&spec)?;
    for _ in 0..a.warmup {
        run::render(&spec, &loaded)?;
    }
    // A frame is what the llvmpipe peer times as one (clears, passes, resolve); the
    // self-checks that read whole buffers back run after it, timed apart (the peer checks
    // untimed). Every frame is checked.
    let mut times = Vec::new();
    let mut pass_times = Vec::new();
    let mut check_times = Vec::new();
    let mut checked_times = Vec::new();
    let mut imbalance_times = Vec::new();
    // Hazard-prone algorithms may fail a check under real races: reported, not fatal.
    let mut failed_checks = 0;
    let mut last = None;
    for _ in 0..a.frames.max(1) {
        // The previous frame's buffers are freed first, so that the allocator hands the
        // same memory to this frame, as a renderer reuses its buffers from frame to frame
        // (and as the llvmpipe peer clears and reuses one storage buffer).
        drop(last.take());
        let r = run::render(&spec, &loaded)?;
        failed_checks += r.result.checks.iter().filter(|c| !c.passed).count();
        times.push(r.wall_ms);
        check_times.push(r.check_ms);
        checked_times.push(r.wall_ms + r.check_ms);
        pass_times.push(r.result.report.wall.as_secs_f64() * 1e3);
        imbalance_times.push(r.result.report.imbalance.as_secs_f64() * 1e3);
        last = Some(r);
    }
    let r = last.expect("one frame");
    let ms = fragrace::floor::median(&mut times);
    let check_ms = fragrace::floor::median(&mut check_times);
    let checked_ms = fragrace::floor::median(&mut checked_times);
    // The passes alone (transform, binning, shading, fixed function), without buffer
    // allocation and clears.
    let pass_ms = fragrace::floor::median(&mut pass_times);
    // Threads waiting for the last one at the end of shading, summed over threads.
    let imbalance_ms = fragrace::floor::median(&mut imbalance_times);
    let stats = &r.result.report.stats;
    let tris = loaded.scene.mesh.triangle_count() as f64 * stats.geometry_passes.max(1) as f64;
    let floor = if a.floor {
        let counts = r.result.counts.as_deref().with_context(|| {
            format!(
                "--floor replays the per-pixel counts of `count`; `{}` has none",
                spec.algo
            )
        })?;
        let cfg = fragrace::floor::FloorConfig {
            counts,
            width: spec.width,
            height: spec.height,
            tile: fragrace::emu::raster::effective_tile_size(
                fragrace::emu::raster::RasterState::default().tile_size,
            ),
            threads: spec.exec.threads,
            frames: a.frames.max(1),
        };
        Some(fragrace::floor::count_floor(&cfg).context("the floor's replay did not add up")?)
    } else {
        None
    };
    let mut v = serde_json::json!({
        "algo": spec.algo,
        "scene": spec.scene.name(),
        "triangles": loaded.scene.mesh.triangle_count(),
        "width": spec.width, "height": spec.height,
        "exec": spec.exec.mode.name(),
        "threads": spec.exec.threads,
        "frames": times.len(),
        "median_ms": ms,
        "passes_median_ms": pass_ms,
        "imbalance_median_ms": imbalance_ms,
        "check_median_ms": check_ms,
        "checked_median_ms": checked_ms,
        "failed_checks": failed_checks,
        "min_ms": times.first(),
        "max_ms": times.last(),
        "fragments": stats.fragments_generated,
        "fragments_per_s": stats.fragments_generated as f64 / (ms / 1e3),
        "triangles_per_s": tris / (ms / 1e3),
        "steps": stats.steps,
        "steps_per_s": stats.steps as f64 / (ms / 1e3),
    });
    if let Some(f) = floor {
        v["floor_atomics_ms"] = f.atomics_ms.into();
        v["floor_frame_ms"] = f.frame_ms.into();
    }
    if a.run.json {
        println!("{v}");
    } else {
        println!(
            "{} on {} ({} triangles) {}x{}, {} with {} threads: median {:.2} ms over {} frames (min {:.2}, max {:.2}); passes alone {:.2} ms; self-checks after it {:.2} ms (frame and checks {:.2} ms)\n  {:.1} M fragments/s, {:.1} M triangles/s, {:.2} M steps/s",
            spec.algo, spec.scene.name(), loaded.scene.mesh.triangle_count(), spec.width, spec.height, spec.exec.mode.name(), spec.exec.threads,
            ms, times.len(), times[0], times[times.len() - 1], pass_ms, check_ms, checked_ms,
            stats.fragments_generated as f64 / (ms / 1e3) / 1e6, tris / (ms / 1e3) / 1e6, stats.steps as f64 / (ms / 1e3) / 1e6
        );
        if spec.exec.threads > 1 {
            println!(
                "  threads idle at the end of shading, waiting for the last one: {imbalance_ms:.3} ms (median, summed over threads)"
            );
        }
        if failed_checks > 0 {
            println!("  {failed_checks} failed checks over the frames (see `fragrace render`)");
        }
        if let Some(f) = floor {
            println!(
                "  floor: the frame's {} atomic adds alone {:.2} ms; with a fresh zeroed buffer {:.2} ms",
                stats.fragments_generated, f.atomics_ms, f.frame_ms
            );
        }
    }
    Ok(())
}

fn parse_binning(s: &str) -> Result<fragrace::emu::Binning, String> {
    fragrace::emu::Binning::from_name(s)
        .ok_or_else(|| format!("`{s}`: expected `auto` or `always`"))
}

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

fn cmd_fuzz(a: &FuzzArgs) -> Result<()> {
    use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
    use std::sync::Arc;
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
    };
    if cfg.time.is_none() && cfg.iterations.is_none() {
        bail!("give --time or --iterations (a campaign needs a budget)");
    }
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
    if a.json {
        println!("{}", serde_json::to_string(&state)?);
        return Ok(());
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
    for (sig, n) in &state.signatures {
        println!("  {n:>6}  {sig}");
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
    for c in &state.cases {
        println!(
            "  case: {}  (fragrace replay {})",
            c,
            a.out.join(c).display()
        );
    }
    Ok(())
}

fn cmd_replay(path: &Path, json: bool) -> Result<()> {
    let case = fragrace::case::read(path)?;
    let r = fragrace::case::replay(&case)?;
    if json {
        println!(
            "{}",
            serde_json::json!({"exact": r.exact, "holds": r.holds, "recorded": case.observed, "observed": r.observed})
        );
    } else {
        println!("{}: {}", path.display(), case.verdict);
        println!("  {}", case.spec.command("check"));
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
    if !r.holds {
        std::process::exit(1);
    }
    Ok(())
}

fn cmd_report(a: &ReportArgs) -> Result<()> {
    let algos: Vec<String> = if a.algo.is_empty() {
        fragrace_kernels::names()
            .into_iter()
            .map(String::from)
            .collect()
    } else {
        a.algo.clone()
    };
    let exec =
        run::exec_config(&a.exec, &a.policy, a.seed, a.threads, 64).map_err(anyhow::Error::msg)?;
    let occupancy = match a.occupancy {
        Some(d) => {
            let o = fragrace_kernels::occupancy::Occupancy {
                d,
                range: a.range.unwrap_or_default(),
                fill: Default::default(),
            };
            o.validate(a.k)?;
            Some(o)
        }
        None if a.range.is_some() => {
            bail!("--range configures occupancy culling: add --occupancy D (1 to 64)")
        }
        None => None,
    };
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
    if let Some(views) = a.views {
        let scene = a.scenes.first().context("one scene for --views")?;
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
            let truth = run::truth(&spec, &loaded)?;
            for (name, eprs) in &mut series {
                let mut s = spec.clone();
                s.algo = name.clone();
                s.params.occupancy = culled(name).0;
                eprs.push(run::check_with(&s, &loaded, &truth)?.metrics.epr);
            }
            eprintln!("view {}/{views}", v + 1);
        }
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
    for scene in &a.scenes {
        let mut spec = RunSpec::new(scene_spec(scene), "truth");
        spec.width = a.size;
        spec.height = a.size;
        spec.exec = exec.clone();
        spec.params.k = a.k;
        let loaded = run::load(&spec)?;
        let truth = run::truth(&spec, &loaded)?;
        for name in &algos {
            let mut s = spec.clone();
            s.algo = name.clone();
            let (occ, row) = culled(name);
            s.params.occupancy = occ;
            let c = run::check_with(&s, &loaded, &truth)?;
            let r = &c.rendered.result;
            let hz = r.report.hazards;
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
            );
        }
    }
    Ok(())
}
