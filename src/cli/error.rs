//! Why a command failed: [`CliError`], the library's typed errors of every concern a command
//! touches, and [`OptionError`], the command line's own mistakes (options that do not go
//! together, a value out of its range).
//!
//! A wrapped error keeps its own message and sources (`#[error(transparent)]`), so the
//! binary's `error: ...` line reads as the library's error does.

use std::path::PathBuf;

/// Options that do not go together, or a value out of its range: each names the option, the
/// value given and what it must be.
#[derive(Debug, thiserror::Error)]
pub enum OptionError {
    #[error(
        "--place given {given} times for {files} --obj files: give it once per file, in order"
    )]
    PlaceCount { given: usize, files: usize },
    #[error("--obj-step moves the second and later --obj files: give at least two")]
    ObjStepWithoutTwo,
    #[error(
        "unknown algorithm `{name}`; known: {}, and after `fragrace presort`: {}",
        known.join(", "),
        preprocessed.join(", ")
    )]
    UnknownAlgorithm {
        name: String,
        known: Vec<&'static str>,
        preprocessed: Vec<&'static str>,
    },
    #[error(
        "--range and --occupancy-fill configure occupancy culling: add --occupancy D (1 to 64)"
    )]
    OccupancyPartWithoutD,
    #[error("--shade, --color and --opacity change only the picture: add --out PATH")]
    PictureWithoutOut,
    #[error("presort --dedupe-to rewrites an OBJ mesh; `{mesh}` is not an .obj file")]
    DedupeNeedsObj { mesh: String },
    #[error("--turntable 0: the number of views must be at least 1")]
    TurntableZero,
    #[error("--raw-out needs a counting algorithm (count, count-plain), not `{algo}`")]
    RawOutNotCounting { algo: String },
    #[error("--raw-out needs a counting algorithm (count, count-plain)")]
    RawOutWithoutCounts,
    #[error("--floor measures the floor of `count` (its atomic adds alone), not of `{algo}`")]
    FloorNotCount { algo: String },
    #[error("--floor replays the per-pixel counts of `count`; `{algo}` has none")]
    FloorWithoutCounts { algo: String },
    #[error("bad duration `{value}`")]
    Duration {
        value: String,
        #[source]
        source: std::num::ParseFloatError,
    },
    #[error("bad duration unit in `{value}` (use s, m or h)")]
    DurationUnit { value: String },
    #[error(
        "--occupancy: none of {} runs behind occupancy culling; the algorithms that do: {}",
        algos.join(", "),
        takers.join(", ")
    )]
    OccupancyWithoutTaker {
        algos: Vec<String>,
        takers: Vec<&'static str>,
    },
    #[error("give --time or --iterations (a campaign needs a budget)")]
    CampaignWithoutBudget,
    #[error("--time {value}: a campaign needs a positive time")]
    ZeroTime { value: String },
    #[error("--threads 0: at least 1 thread")]
    ZeroThreads,
    #[error("NAME@EXEC in --algo is for --views sweeps only; the table runs every algorithm under --exec {exec}")]
    ExecOverrideWithoutViews { exec: String },
    #[error("one scene for --views")]
    ViewsWithoutScene,
    #[error("--jobs {jobs} is out of range: it must be from 1 to {max}")]
    Jobs { jobs: usize, max: usize },
    #[error("--paper writes a directory: give it with --out DIR")]
    PaperWithoutOut,
}

/// Why a command failed.
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    #[error(transparent)]
    Option(#[from] OptionError),
    /// A value out of its range, or an option the run would ignore.
    #[error(transparent)]
    Spec(#[from] crate::validate::SpecError),
    /// An option given that the chosen executor does not read.
    #[error(transparent)]
    NoEffect(#[from] crate::validate::NoEffect),
    /// An option given that the chosen algorithm does not read.
    #[error(transparent)]
    NoEffectOnAlgo(#[from] crate::validate::NoEffectOnAlgo),
    #[error(transparent)]
    Run(#[from] crate::run::RunError),
    #[error(transparent)]
    Budget(#[from] crate::budget::BudgetError),
    #[error(transparent)]
    Case(#[from] crate::case::CaseError),
    #[error(transparent)]
    Scene(#[from] crate::scene::SceneError),
    #[error(transparent)]
    Render(#[from] crate::render::RenderError),
    #[error(transparent)]
    Output(#[from] crate::output::OutputError),
    #[error(transparent)]
    Plot(#[from] crate::plot::PlotError),
    #[error(transparent)]
    Fuzz(#[from] crate::fuzz::FuzzError),
    #[error(transparent)]
    Shard(#[from] crate::fuzz::ShardError),
    #[error(transparent)]
    Report(#[from] crate::report::ReportError),
    #[error(transparent)]
    Racebench(#[from] crate::racebench::BenchError),
    #[error(transparent)]
    Algo(#[from] fragrace_kernels::AlgoError),
    #[error(transparent)]
    Merge(#[from] fragrace_kernels::merging::MergeParamError),
    #[error(transparent)]
    Presort(#[from] fragrace_kernels::presorted::PresortError),
    #[error(transparent)]
    PresortFile(#[from] fragrace_kernels::presorted::file::FileError),
    /// `presort --partitions P` with no bounding polyhedron of P faces.
    #[error("{0}")]
    Partitions(String),
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    #[error("{}: file not found", path.display())]
    NotFound { path: PathBuf },
    #[error("{}: cannot read", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: cannot write", path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A case file whose run cannot be loaded.
    #[error("{}", path.display())]
    CaseScene {
        path: PathBuf,
        #[source]
        source: crate::run::RunError,
    },
    /// `presort MESH` whose mesh cannot be loaded.
    #[error("loading {mesh}")]
    Mesh {
        mesh: String,
        #[source]
        source: crate::run::RunError,
    },
    /// `report --algo NAME@EXEC` with an executor that is not one.
    #[error("--algo {algo}")]
    AlgoExec {
        algo: String,
        #[source]
        source: crate::validate::SpecError,
    },
    /// One algorithm of a report above the memory budget.
    #[error("algorithm {algo}")]
    AlgoBudget {
        algo: String,
        #[source]
        source: crate::budget::BudgetError,
    },
    #[error("starting the pool of --jobs threads")]
    Pool(#[source] rayon::ThreadPoolBuildError),
    #[error("the floor's replay did not add up")]
    Floor,
}

impl CliError {
    /// A file that could not be read, named.
    pub fn read(path: &std::path::Path) -> impl FnOnce(std::io::Error) -> CliError + '_ {
        move |source| CliError::Read {
            path: path.to_path_buf(),
            source,
        }
    }

    /// A file that could not be written, named.
    pub fn write(path: &std::path::Path) -> impl FnOnce(std::io::Error) -> CliError + '_ {
        move |source| CliError::Write {
            path: path.to_path_buf(),
            source,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The full message as the binary prints it: the error, then each source after `: `.
    fn chain(e: &dyn std::error::Error) -> String {
        let mut s = e.to_string();
        let mut next = e.source();
        while let Some(x) = next {
            s.push_str(&format!(": {x}"));
            next = x.source();
        }
        s
    }

    #[test]
    fn an_option_out_of_range_names_its_value_and_range() {
        let e = CliError::from(OptionError::Jobs { jobs: 0, max: 256 });
        assert_eq!(
            chain(&e),
            "--jobs 0 is out of range: it must be from 1 to 256"
        );
    }

    #[test]
    fn a_file_error_names_the_path_then_the_cause() {
        let io = std::io::Error::new(std::io::ErrorKind::PermissionDenied, "denied");
        let e = CliError::write(std::path::Path::new("out/a.png"))(io);
        assert_eq!(chain(&e), "out/a.png: cannot write: denied");
    }

    #[test]
    fn an_unknown_algorithm_lists_the_known_ones() {
        let e = OptionError::UnknownAlgorithm {
            name: "kb".into(),
            known: vec!["count", "ll"],
            preprocessed: vec!["presorted"],
        };
        assert_eq!(
            e.to_string(),
            "unknown algorithm `kb`; known: count, ll, and after `fragrace presort`: presorted"
        );
    }
}
