//! The `fragrace` command line.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::parser::ValueSource;
use clap::{ArgMatches, Args, CommandFactory, FromArgMatches, Parser, Subcommand};
use fragrace::run::{self, RunSpec, SceneSpec};
use fragrace::scene::Camera;
use fragrace_kernels::Params;

mod cli;
use cli::bench::cmd_bench;
use cli::fuzz::cmd_fuzz;
use cli::report::cmd_report;
use cli::run::{cmd_check, cmd_render, cmd_replay};

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
        /// Refuse a case whose estimated peak memory is above this (default: half of the
        /// physical memory).
        #[arg(long, value_name = "SIZE")]
        memory_limit: Option<String>,
    },
    /// Tables of measured EPR, R_h, bytes per pixel and time (markdown), and EPR over views.
    Report(ReportArgs),
    /// The hazard detector measured on labelled racy and race-free kernels, per policy.
    Racebench(cli::racebench::RacebenchArgs),
    /// Preprocess a static mesh into depth-presorted triangle lists (`--algo presorted`).
    Presort(cli::presort::PresortArgs),
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
    /// Schedules run on each generated scene: its scene is loaded and its truth computed
    /// once, then this many executions of its run (other seeds) are checked against it.
    #[arg(long, default_value_t = fragrace::fuzz::DEFAULT_SCHEDULES)]
    schedules: u64,
    /// Only these built-in scenes (comma-separated; default: a random mix).
    #[arg(long, value_delimiter = ',')]
    scene: Vec<String>,
    /// Occupancy culling for every fuzzed algorithm that takes it (default: none).
    #[command(flatten)]
    occupancy: OccupancyArgs,
    #[arg(long)]
    json: bool,
    /// Refuse a campaign whose runs in flight are estimated above this much memory (default:
    /// half of the physical memory).
    #[arg(long, value_name = "SIZE")]
    memory_limit: Option<String>,
    /// Run only the I-th of N disjoint slices of the campaign's iterations (I from 1): N
    /// machines each run one slice, `--merge` combines their directories.
    #[arg(long, value_name = "I/N", conflicts_with = "merge")]
    shard: Option<String>,
    /// Combine the case directories of a campaign's shards into --out (deduplicated by
    /// signature, the smallest case of each kept) and print the merged summary.
    /// The options of a campaign's runs have no effect on a merge, and are refused with it.
    #[arg(long, value_name = "DIR", num_args = 1.., conflicts_with_all = [
        "time", "iterations", "resume", "algo", "jobs", "seed", "meshes", "shrink_secs",
        "max_size", "scene", "memory_limit", "occupancy", "range", "occupancy_fill",
        "schedules",
    ])]
    merge: Vec<PathBuf>,
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
    /// Instead of the table: EPR of each algorithm over this many azimuths, as CSV on stdout
    /// and a plot to --out (.svg or .png). In a sweep, `--algo NAME@EXEC` runs one algorithm
    /// under another executor (e.g. `kb-rmw,kb-rmw@scheduled`).
    #[arg(long)]
    views: Option<u32>,
    /// Views computed at once (--views): a work-stealing pool of this many threads, each
    /// view's runs using --threads as well. Memory: this many runs at once.
    #[arg(long, default_value_t = 1, requires = "views")]
    jobs: usize,
    /// Only the I-th of N disjoint slices of the views (--views; I from 1): view v goes to
    /// slice v % N + 1, so N machines can each compute one; the slices' CSV rows together
    /// are the whole sweep's (sort them by azimuth).
    #[arg(long, value_name = "I/N", requires = "views")]
    shard: Option<String>,
    #[arg(long)]
    out: Option<PathBuf>,
    /// Occupancy culling for the algorithms that take it (their rows are named `NAME+occ`);
    /// the others run as they are.
    #[command(flatten)]
    occupancy: OccupancyArgs,
    /// Refuse a report whose largest run is estimated above this much memory (default: half
    /// of the physical memory).
    #[arg(long, value_name = "SIZE")]
    memory_limit: Option<String>,
    /// Instead of the table: the seeds' tables and figures, measured, written to --out DIR
    /// (index.html, SVG and PNG per figure, CSV and Markdown per table, report.json).
    /// depth-fighting, bucket, occupancy, merging, presorted, hazards (comma-separated), or
    /// all.
    #[arg(long, value_name = "SECTIONS", conflicts_with_all = [
        "views", "algo", "scenes", "size", "exec", "policy", "seed", "k", "jobs", "shard",
        "memory_limit", "occupancy", "range", "occupancy_fill",
    ])]
    paper: Option<String>,
    /// --paper: built-in and shipped scenes only, small images, few views (minutes).
    #[arg(long, requires = "paper")]
    quick: bool,
    /// --paper: a directory of meshes (.obj, .obj.gz) for the full report (default: the
    /// shipped meshes of assets/).
    #[arg(long, value_name = "DIR", requires = "paper", conflicts_with = "quick")]
    models: Option<PathBuf>,
    /// --paper: the llvmpipe peer's script (oit.py, with Python's moderngl), run by the
    /// hazards section next to the k-buffer's race; without it the page says it is absent.
    #[arg(long, value_name = "FILE", requires = "paper")]
    peer: Option<PathBuf>,
}

#[derive(Args, Clone)]
struct RunArgs {
    /// A built-in scene (see `fragrace list`).
    #[arg(long, default_value = "cubes", conflicts_with_all = ["obj", "scene_file"])]
    scene: String,
    /// A scene file (JSON: OBJ objects with placements, colours and opacities, and a
    /// camera; README "Scene files").
    #[arg(long, value_name = "PATH", conflicts_with = "obj")]
    scene_file: Option<PathBuf>,
    /// An OBJ file (plain or .gz) instead of a built-in scene; repeated, a scene of several
    /// objects (one per file; see --geometry-culling).
    #[arg(long)]
    obj: Vec<PathBuf>,
    /// With several --obj: file i is moved by i times this vector (X,Y,Z, in the files'
    /// units), e.g. the same file three times in a row.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_step, requires = "obj")]
    obj_step: Option<[f32; 3]>,
    /// Where each --obj file goes: repeated once per file, in order (X,Y,Z in the files'
    /// units, added to --obj-step's move); --scene-file also rotates and scales.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_step, allow_negative_numbers = true, requires = "obj")]
    place: Vec<[f32; 3]>,
    /// Multi-pass peelers (front-to-back and dual): per iteration an occlusion query of each
    /// object's bounding box against what is left to peel, and conditional rendering of the
    /// objects (completely peeled ones are culled; depth-fighting paper, section 3.3).
    #[arg(long)]
    geometry_culling: bool,
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
    /// Vertical field of view, degrees.
    #[arg(long, default_value_t = 60.0)]
    fov: f32,
    /// Distance from the eye to the point looked at (default: the bounding sphere fills
    /// 80 % of the view), in units of the normalised scene (largest extent 1).
    #[arg(long)]
    distance: Option<f32>,
    /// The point looked at (default the scene's centre, the origin).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_step, allow_negative_numbers = true)]
    look_at: Option<[f32; 3]>,
    /// Parallel projection instead of perspective.
    #[arg(long)]
    orthographic: bool,
    /// How --out shades kept fragments: lit (headlight, Lambert and Blinn-Phong, materials'
    /// colour and opacity), translucent (Beer-Lambert absorption through the layers),
    /// fresnel (translucent times Fresnel transmittance), id (the algorithm's own composite in
    /// the peer's hash colours at --alpha). Default: lit for `render` (id for the algorithms
    /// that keep only an image), id for `check`.
    #[arg(long)]
    shade: Option<fragrace::render::Shade>,
    /// Translucent and fresnel shading: absorption per unit of the normalised scene; a
    /// channel absorbs sigma (1 - its colour).
    #[arg(long, default_value_t = fragrace::render::Look::default().sigma)]
    sigma: f32,
    /// Colour R,G,B (each in [0, 1]) of every object, or repeated: of each object in order.
    #[arg(long, value_name = "R,G,B", value_parser = parse_step)]
    color: Vec<[f32; 3]>,
    /// Opacity in [0, 1] of every object, or repeated: of each object in order (lit shading).
    #[arg(long, allow_negative_numbers = true)]
    opacity: Vec<f32>,
    /// Render N views around the scene (azimuth + 360 i / N) to --out: an animated GIF
    /// when it ends in .gif, else numbered PNGs (NAME-000.png, ...).
    #[arg(long, value_name = "N", requires = "out")]
    turntable: Option<u32>,
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
    #[command(flatten)]
    occupancy: OccupancyArgs,
    /// Merging algorithms: the z-thickness of every fragment, `NxP` (N times the z-resolution
    /// P(z) of a 24-bit depth buffer, equation 9; `NxP:BITS` for other precisions) or a
    /// fixed view depth (e.g. 0.01).
    #[arg(long, default_value = "2xP", value_parser = parse_thickness)]
    thickness: fragrace_kernels::merging::Thickness,
    /// Merging algorithms: beta of equation 4 (SFM: 0 exact optics, 1 linear), in [0, 1].
    #[arg(long, default_value_t = 0.0)]
    beta: f32,
    /// The presorted algorithms: lists written by `fragrace presort` for this mesh (without
    /// it, the mesh is preprocessed first, with 6 partitions).
    #[arg(long, value_name = "FILE")]
    presorted: Option<PathBuf>,
    /// Output PNG.
    #[arg(long)]
    out: Option<PathBuf>,
    /// For `count`: per-pixel counts as little-endian u32, row-major, top row first.
    #[arg(long)]
    raw_out: Option<PathBuf>,
    /// Directory for heatmaps (depth complexity, errors, hazards, image difference, culled,
    /// bucket collisions).
    #[arg(long)]
    heatmap: Option<PathBuf>,
    /// Print one JSON object on stdout.
    #[arg(long)]
    json: bool,
    /// Refuse runs whose estimated peak memory is above this (e.g. 8G, 512M; default: half
    /// of the physical memory).
    #[arg(long, value_name = "SIZE")]
    memory_limit: Option<String>,
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

/// The options given on the command line (not defaulted), named as typed without `--`.
fn given(m: &ArgMatches) -> Vec<String> {
    m.ids()
        .filter(|id| m.value_source(id.as_str()) == Some(ValueSource::CommandLine))
        .map(|id| id.as_str().replace('_', "-"))
        .collect()
}

/// The run the options describe, every value checked ([`RunSpec::validate`]) and every
/// option that the executor would ignore refused, before anything is loaded.
fn spec_of(a: &RunArgs, given: &[String]) -> Result<RunSpec> {
    fragrace::validate::options_for_exec(&a.exec, given.iter().map(String::as_str))?;
    let mut files = Vec::with_capacity(a.obj.len());
    for p in &a.obj {
        if !p.exists() {
            bail!("{}: file not found", p.display());
        }
        let bytes = std::fs::read(p).with_context(|| format!("{}: cannot read", p.display()))?;
        files.push(run::ObjFile {
            path: p.clone(),
            sha256: Some(fragrace::scene::obj::content_hash(&bytes)),
        });
    }
    if !a.place.is_empty() && a.place.len() != files.len() {
        bail!(
            "--place given {} times for {} --obj files: give it once per file, in order",
            a.place.len(),
            files.len()
        );
    }
    if a.obj_step.is_some() && files.len() < 2 {
        bail!("--obj-step moves the second and later --obj files: give at least two");
    }
    let mut camera = Camera {
        fovy: a.fov,
        distance: a.distance,
        look_at: a.look_at,
        projection: if a.orthographic {
            fragrace::scene::Projection::Orthographic
        } else {
            fragrace::scene::Projection::Perspective
        },
        ..Camera::new(a.azimuth, a.elevation)
    };
    if let Some(path) = &a.scene_file {
        // The file's camera, where the command line says nothing.
        let bytes =
            std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
        let file = fragrace::scene::file::SceneFile::parse(&bytes, path)?;
        let from_file = file.camera(camera);
        let set = |name: &str| given.iter().any(|g| g == name);
        camera = Camera {
            azimuth: if set("azimuth") {
                camera.azimuth
            } else {
                from_file.azimuth
            },
            elevation: if set("elevation") {
                camera.elevation
            } else {
                from_file.elevation
            },
            fovy: if set("fov") {
                camera.fovy
            } else {
                from_file.fovy
            },
            distance: camera.distance.or(from_file.distance),
            look_at: camera.look_at.or(from_file.look_at),
            ..from_file
        };
    }
    let scene = match files.len() {
        0 if a.scene_file.is_some() => {
            let path = a.scene_file.clone().expect("checked");
            let bytes = std::fs::read(&path)?;
            SceneSpec::File {
                sha256: Some(fragrace::scene::obj::content_hash(&bytes)),
                path,
            }
        }
        0 => SceneSpec::Builtin(a.scene.clone()),
        1 if a.place.is_empty() => {
            let f = files.remove(0);
            SceneSpec::Obj {
                path: f.path,
                sha256: f.sha256,
            }
        }
        _ => SceneSpec::Objs {
            files,
            step: a.obj_step.unwrap_or_default(),
            places: a.place.clone(),
        },
    };
    let mut exec = run::exec_config(&a.exec, &a.policy, a.seed, a.threads, a.window)?;
    // The scheduled executor's own settings (refused above under the other executors).
    if let fragrace::emu::ExecMode::Scheduled(s) = &mut exec.mode {
        s.block = a.block;
        s.reduce = a.reduce;
        s.simt = a.simt;
    }
    exec.spurious_cas_per_mille = a.spurious_cas;
    exec.batch = a.lanes;
    exec.lockstep = !a.no_lockstep;
    exec.segment = a.segment;
    exec.binning = a.binning;
    if fragrace_kernels::algorithm(&a.algo).is_none() {
        bail!(
            "unknown algorithm `{}`; known: {}, and after `fragrace presort`: {}",
            a.algo,
            fragrace_kernels::names().join(", "),
            fragrace_kernels::registry::preprocessed()
                .iter()
                .map(|x| x.info().name)
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let spec = RunSpec {
        scene,
        camera,
        width: a.width,
        height: a.height,
        algo: a.algo.clone(),
        params: Params {
            k: a.k,
            alpha: a.alpha,
            spin_cap: a.spin_cap,
            occupancy: a.occupancy.get(takes_range(&a.algo))?,
            range: a.occupancy.range.unwrap_or_default(),
            geometry_culling: if a.geometry_culling {
                fragrace_kernels::peeling::GeometryCulling::Queries
            } else {
                fragrace_kernels::peeling::GeometryCulling::Off
            },
            merge: {
                let merge = fragrace_kernels::merging::MergeParams {
                    thickness: a.thickness,
                    beta: a.beta,
                };
                merge.validate()?;
                merge
            },
            presorted: a.presorted.clone(),
            ..Params::default()
        },
        exec,
    };
    spec.validate()?;
    // After the ranges: `--k 0` is out of range whatever the algorithm.
    fragrace::validate::options_for_algo(&a.algo, given.iter().map(String::as_str))?;
    Ok(spec)
}

/// The occupancy-culling options of `render`, `check`, `bench`, `fuzz` and `report`.
#[derive(Args, Clone)]
struct OccupancyArgs {
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
}

impl OccupancyArgs {
    /// The stage's parameters; `--range` and `--occupancy-fill` mean nothing without
    /// `--occupancy` and are refused alone (`--range` alone is the depth range of the
    /// algorithms that take one, the bucket schemes: `takes_range`).
    fn get(&self, takes_range: bool) -> Result<Option<fragrace_kernels::occupancy::Occupancy>> {
        match self.occupancy {
            Some(d) => Ok(Some(fragrace_kernels::occupancy::Occupancy {
                d,
                range: self.range.unwrap_or_default(),
                fill: self.occupancy_fill.unwrap_or_default(),
            })),
            None if (self.range.is_some() && !takes_range) || self.occupancy_fill.is_some() => {
                bail!("--range and --occupancy-fill configure occupancy culling: add --occupancy D (1 to 64)")
            }
            None => Ok(None),
        }
    }
}

/// Whether any of `algos` (comma-separated) takes a depth range of its own (`--range`
/// without `--occupancy`).
fn takes_range(algos: &str) -> bool {
    algos
        .split(',')
        // `NAME@EXEC` (report's view sweeps) names the algorithm before the `@`.
        .map(|n| n.split('@').next().unwrap_or(n))
        .any(|n| fragrace_kernels::algorithm(n).is_some_and(|x| x.takes_range()))
}

fn main() {
    if let Err(e) = real_main() {
        eprintln!("error: {e:#}");
        std::process::exit(2);
    }
}

fn real_main() -> Result<()> {
    let matches = Cli::command().get_matches();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    let given = matches
        .subcommand()
        .map(|(_, m)| given(m))
        .unwrap_or_default();
    // A kernel panic is a reported fault, not a crash: keep the default hook's noise out.
    std::panic::set_hook(Box::new(|_| {}));
    match cli.command {
        Command::Render(a) => cmd_render(&a, &given),
        Command::Check(a) => cmd_check(&a, &given),
        Command::List { json } => cmd_list(json),
        Command::Bench(a) => cmd_bench(&a, &given),
        Command::Fuzz(a) => cmd_fuzz(&a),
        Command::Replay {
            case,
            json,
            memory_limit,
        } => cmd_replay(&case, json, memory_limit.as_deref()),
        Command::Report(a) => cmd_report(&a, &given),
        Command::Racebench(a) => cli::racebench::cmd_racebench(&a),
        Command::Presort(a) => cli::presort::cmd_presort(&a),
    }
}

/// The estimated peak memory of a run, refused when above the budget (`--memory-limit`);
/// as JSON fields for the summary.
fn within_budget(
    spec: &RunSpec,
    loaded: &run::Loaded,
    with_truth: bool,
    limit: Option<&str>,
) -> Result<serde_json::Value> {
    let (limit, source) = fragrace::budget::limit(limit)?;
    let est = fragrace::budget::estimate(spec, loaded, with_truth);
    fragrace::budget::check(&est, limit, &source)?;
    Ok(serde_json::json!({
        "memory_estimate_bytes": est.bytes,
        "memory_estimate_parts": est.parts,
        "memory_limit_bytes": limit,
        "fragments_estimate": est.fragments,
    }))
}

/// A progress bar of `len` steps (a spinner when 0) with the elapsed time, on stderr when it
/// is a terminal; nothing otherwise, so that piped output stays clean.
pub(crate) fn progress(len: u64, msg: &str) -> indicatif::ProgressBar {
    let (bar, template) = if len == 0 {
        (
            indicatif::ProgressBar::new_spinner(),
            "{spinner} {elapsed} {msg}",
        )
    } else {
        (
            indicatif::ProgressBar::new(len),
            "{spinner} {elapsed} [{bar:30}] {pos}/{len} {msg}",
        )
    };
    bar.set_style(indicatif::ProgressStyle::with_template(template).expect("valid template"));
    bar.set_message(msg.to_string());
    bar.enable_steady_tick(std::time::Duration::from_millis(100));
    bar
}

/// Adds the fields of `extra` (an object) to `v`.
fn merge(v: &mut serde_json::Value, extra: &serde_json::Value) {
    if let (Some(v), Some(e)) = (v.as_object_mut(), extra.as_object()) {
        v.extend(e.iter().map(|(k, x)| (k.clone(), x.clone())));
    }
}

fn cmd_list(json: bool) -> Result<()> {
    let mut algos = fragrace_kernels::algorithms();
    algos.extend(fragrace_kernels::registry::preprocessed());
    let infos: Vec<_> = algos
        .iter()
        .map(|a| {
            let mut v = serde_json::to_value(a.info()).expect("AlgoInfo serializes");
            v["occupancy"] = serde_json::json!(a.takes_occupancy());
            // The shared options it reads (`--k`, `--spin-cap`); the others are refused.
            v["reads"] = [fragrace_kernels::Param::K, fragrace_kernels::Param::SpinCap]
                .into_iter()
                .filter(|&p| a.reads(p))
                .map(|p| p.option())
                .collect();
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

fn parse_thickness(s: &str) -> Result<fragrace_kernels::merging::Thickness, String> {
    s.parse()
        .map_err(|e: fragrace_kernels::merging::MergeParamError| e.to_string())
}

/// `--obj-step X,Y,Z`: three finite numbers.
fn parse_step(s: &str) -> Result<[f32; 3], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("`{s}`: expected X,Y,Z (three numbers)"))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([x, y, z]),
        _ => Err(format!("`{s}`: expected X,Y,Z (three finite numbers)")),
    }
}

fn parse_binning(s: &str) -> Result<fragrace::emu::Binning, String> {
    fragrace::emu::Binning::from_name(s)
        .ok_or_else(|| format!("`{s}`: expected `auto` or `always`"))
}
