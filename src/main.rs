//! The `fragrace` command line: it only parses. Its options (clap's derive structs, with
//! their help text and defaults) convert into the library's plain options, and the commands
//! themselves are [`fragrace::cli`]'s; an error is printed as `error: ...` with exit
//! status 2.

#![forbid(unsafe_code)]

use std::path::PathBuf;

use anyhow::Result;
use clap::parser::ValueSource;
use clap::{ArgMatches, Args, CommandFactory, FromArgMatches, Parser, Subcommand};
use fragrace::cli;

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
    Racebench(RacebenchArgs),
    /// Preprocess a static mesh into depth-presorted triangle lists (`--algo presorted`).
    Presort(PresortArgs),
}

#[derive(Args)]
struct RacebenchArgs {
    /// Schedules per kernel and policy (runs, for `parallel`).
    #[arg(long, default_value_t = 200)]
    schedules: u64,
    /// Comma-separated policies (scheduled policy names, or `parallel`).
    #[arg(long, default_value = "random,pct:2,pct:3,warp:32,far-first,parallel")]
    policies: String,
    /// Comma-separated kernel names (default: all).
    #[arg(long)]
    kernels: Option<String>,
    /// Worker threads of the sweep (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Run every schedule even after a racy kernel's race was found (a precision run: every
    /// report is seen). By default a racy kernel stops at its first true report.
    #[arg(long)]
    all_schedules: bool,
    /// The full result as JSON.
    #[arg(long)]
    json: bool,
}

/// Options of `presort`.
#[derive(Args)]
struct PresortArgs {
    /// The mesh: an OBJ file (plain or .gz), or a built-in scene's name.
    mesh: String,
    /// Faces of the bounding polyhedron (= viewpoint partitions = segments): 4, 6, 16 or 64.
    #[arg(long, default_value_t = 6)]
    partitions: u32,
    /// Where to write the lists (written to a temporary file and renamed when complete).
    #[arg(long)]
    out: PathBuf,
    /// Worker threads (partitions run one per task; default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Print one JSON object on stdout.
    #[arg(long)]
    json: bool,
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
    #[arg(long, default_value_t = cli::RunOptions::default().scene, conflicts_with_all = ["obj", "scene_file"])]
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
    #[arg(long, default_value_t = cli::RunOptions::default().algo)]
    algo: String,
    #[arg(long, default_value_t = cli::RunOptions::default().width)]
    width: u32,
    #[arg(long, default_value_t = cli::RunOptions::default().height)]
    height: u32,
    /// Degrees about +Y (0: eye on +Z, 90: on +X).
    #[arg(long, default_value_t = cli::RunOptions::default().azimuth, allow_negative_numbers = true)]
    azimuth: f32,
    #[arg(long, default_value_t = cli::RunOptions::default().elevation, allow_negative_numbers = true)]
    elevation: f32,
    /// Vertical field of view, degrees.
    #[arg(long, default_value_t = cli::RunOptions::default().fov)]
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
    #[arg(long, default_value_t = cli::RunOptions::default().sigma)]
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
    #[arg(long, default_value_t = cli::RunOptions::default().exec)]
    exec: String,
    /// Scheduling policy: random, pct:D, warp:N, reverse, fifo, far-first, bytes:HEX.
    #[arg(long, default_value_t = cli::RunOptions::default().policy)]
    policy: String,
    #[arg(long, default_value_t = cli::RunOptions::default().seed)]
    seed: u64,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Invocations in flight under the scheduled executor.
    #[arg(long, default_value_t = cli::RunOptions::default().window)]
    window: usize,
    /// Scheduled: pixels per side of the blocks fragments are admitted by.
    #[arg(long, default_value_t = cli::RunOptions::default().block)]
    block: u32,
    /// Scheduled: interleave only invocations about to touch the same address or pixel.
    #[arg(long)]
    reduce: bool,
    /// Per-mille probability that a weak compare-exchange fails spuriously.
    #[arg(long, default_value_t = cli::RunOptions::default().spurious_cas)]
    spurious_cas: u32,
    /// Parallel: lanes per warp (fragments shaded together by one thread).
    #[arg(long, default_value_t = cli::RunOptions::default().lanes)]
    lanes: usize,
    /// Parallel: lanes run one after the other instead of in SIMT lockstep (one memory
    /// access each per turn). Faster; races then come only from other threads.
    #[arg(long)]
    no_lockstep: bool,
    /// Parallel: most triangles of one tile per unit of work; smaller units put more
    /// threads on one tile at once (when the pass's fixed-function results commute).
    #[arg(long, default_value_t = cli::RunOptions::default().segment)]
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
    #[arg(long, default_value_t = cli::RunOptions::default().simt)]
    simt: u32,
    /// kb-spinlock: lock attempts before a fragment gives up (4294967295: never).
    #[arg(long, default_value_t = cli::RunOptions::default().spin_cap)]
    spin_cap: u32,
    /// k of the k-buffers.
    #[arg(long, default_value_t = cli::RunOptions::default().k)]
    k: u32,
    /// Opacity of every fragment in the OIT composite.
    #[arg(long, default_value_t = cli::RunOptions::default().alpha)]
    alpha: f32,
    #[command(flatten)]
    occupancy: OccupancyArgs,
    /// Merging algorithms: the z-thickness of every fragment, `NxP` (N times the z-resolution
    /// P(z) of a 24-bit depth buffer, equation 9; `NxP:BITS` for other precisions) or a
    /// fixed view depth (e.g. 0.01).
    #[arg(long, default_value = "2xP", value_parser = parse_thickness)]
    thickness: fragrace_kernels::merging::Thickness,
    /// Merging algorithms: beta of equation 4 (SFM: 0 exact optics, 1 linear), in [0, 1].
    #[arg(long, default_value_t = cli::RunOptions::default().beta)]
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

// The options, parsed, into the library's (`fragrace::cli`): every field named on both
// sides, so an option added to one side only does not compile.

impl From<RunArgs> for cli::RunOptions {
    fn from(a: RunArgs) -> cli::RunOptions {
        let RunArgs {
            scene,
            scene_file,
            obj,
            obj_step,
            place,
            geometry_culling,
            algo,
            width,
            height,
            azimuth,
            elevation,
            fov,
            distance,
            look_at,
            orthographic,
            shade,
            sigma,
            color,
            opacity,
            turntable,
            exec,
            policy,
            seed,
            threads,
            window,
            block,
            reduce,
            spurious_cas,
            lanes,
            no_lockstep,
            segment,
            binning,
            simt,
            spin_cap,
            k,
            alpha,
            occupancy,
            thickness,
            beta,
            presorted,
            out,
            raw_out,
            heatmap,
            json,
            memory_limit,
        } = a;
        cli::RunOptions {
            scene,
            scene_file,
            obj,
            obj_step,
            place,
            geometry_culling,
            algo,
            width,
            height,
            azimuth,
            elevation,
            fov,
            distance,
            look_at,
            orthographic,
            shade,
            sigma,
            color,
            opacity,
            turntable,
            exec,
            policy,
            seed,
            threads,
            window,
            block,
            reduce,
            spurious_cas,
            lanes,
            no_lockstep,
            segment,
            binning,
            simt,
            spin_cap,
            k,
            alpha,
            occupancy: occupancy.into(),
            thickness,
            beta,
            presorted,
            out,
            raw_out,
            heatmap,
            json,
            memory_limit,
        }
    }
}

impl From<CheckArgs> for cli::run::CheckOptions {
    fn from(a: CheckArgs) -> cli::run::CheckOptions {
        let CheckArgs { run, schedules } = a;
        cli::run::CheckOptions {
            run: run.into(),
            schedules,
        }
    }
}

impl From<BenchArgs> for cli::bench::BenchOptions {
    fn from(a: BenchArgs) -> cli::bench::BenchOptions {
        let BenchArgs {
            run,
            frames,
            warmup,
            floor,
        } = a;
        cli::bench::BenchOptions {
            run: run.into(),
            frames,
            warmup,
            floor,
        }
    }
}

impl From<FuzzArgs> for cli::fuzz::FuzzOptions {
    fn from(a: FuzzArgs) -> cli::fuzz::FuzzOptions {
        let FuzzArgs {
            time,
            iterations,
            algo,
            jobs,
            out,
            seed,
            resume,
            meshes,
            shrink_secs,
            max_size,
            schedules,
            scene,
            occupancy,
            json,
            memory_limit,
            shard,
            merge,
        } = a;
        cli::fuzz::FuzzOptions {
            time,
            iterations,
            algo,
            jobs,
            out,
            seed,
            resume,
            meshes,
            shrink_secs,
            max_size,
            schedules,
            scene,
            occupancy: occupancy.into(),
            json,
            memory_limit,
            shard,
            merge,
        }
    }
}

impl From<ReportArgs> for cli::report::ReportOptions {
    fn from(a: ReportArgs) -> cli::report::ReportOptions {
        let ReportArgs {
            algo,
            scenes,
            size,
            exec,
            policy,
            seed,
            threads,
            k,
            views,
            jobs,
            shard,
            out,
            occupancy,
            memory_limit,
            paper,
            quick,
            models,
            peer,
        } = a;
        cli::report::ReportOptions {
            algo,
            scenes,
            size,
            exec,
            policy,
            seed,
            threads,
            k,
            views,
            jobs,
            shard,
            out,
            occupancy: occupancy.into(),
            memory_limit,
            paper,
            quick,
            models,
            peer,
        }
    }
}

impl From<RacebenchArgs> for cli::racebench::RacebenchOptions {
    fn from(a: RacebenchArgs) -> cli::racebench::RacebenchOptions {
        let RacebenchArgs {
            schedules,
            policies,
            kernels,
            threads,
            all_schedules,
            json,
        } = a;
        cli::racebench::RacebenchOptions {
            schedules,
            policies,
            kernels,
            threads,
            all_schedules,
            json,
        }
    }
}

impl From<PresortArgs> for cli::presort::PresortOptions {
    fn from(a: PresortArgs) -> cli::presort::PresortOptions {
        let PresortArgs {
            mesh,
            partitions,
            out,
            threads,
            json,
        } = a;
        cli::presort::PresortOptions {
            mesh,
            partitions,
            out,
            threads,
            json,
        }
    }
}

impl From<OccupancyArgs> for cli::OccupancyOptions {
    fn from(a: OccupancyArgs) -> cli::OccupancyOptions {
        let OccupancyArgs {
            occupancy,
            range,
            occupancy_fill,
        } = a;
        cli::OccupancyOptions {
            occupancy,
            range,
            occupancy_fill,
        }
    }
}

fn main() {
    if let Err(e) = real_main() {
        eprintln!("error: {e:#}");
        std::process::exit(2);
    }
}

fn real_main() -> Result<()> {
    let matches = Cli::command().get_matches();
    let parsed = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    let given = matches
        .subcommand()
        .map(|(_, m)| given(m))
        .unwrap_or_default();
    // A kernel panic is a reported fault, not a crash: keep the default hook's noise out.
    std::panic::set_hook(Box::new(|_| {}));
    match parsed.command {
        Command::Render(a) => cli::run::cmd_render(&a.into(), &given)?,
        Command::Check(a) => cli::run::cmd_check(&a.into(), &given)?,
        Command::List { json } => cli::list::cmd_list(json),
        Command::Bench(a) => cli::bench::cmd_bench(&a.into(), &given)?,
        Command::Fuzz(a) => cli::fuzz::cmd_fuzz(&a.into())?,
        Command::Replay {
            case,
            json,
            memory_limit,
        } => {
            let holds = cli::run::cmd_replay(&cli::run::ReplayOptions {
                case,
                json,
                memory_limit,
            })?;
            if !holds {
                std::process::exit(1);
            }
        }
        Command::Report(a) => cli::report::cmd_report(&a.into(), &given)?,
        Command::Racebench(a) => cli::racebench::cmd_racebench(&a.into())?,
        Command::Presort(a) => cli::presort::cmd_presort(&a.into())?,
    }
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
