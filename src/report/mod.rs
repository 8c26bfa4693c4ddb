//! `fragrace report --paper SECTION --out DIR`: the seeds' tables and figures regenerated
//! from measured runs, written as one directory a researcher can open without a server:
//! `index.html` (the page), one SVG and PNG per figure, CSV and Markdown per table, and
//! `report.json` with every table's rows and every figure's points.
//!
//! Each section is one file: [`depth_fighting`] (Table 1 of "Depth-Fighting Aware Methods
//! for Multifragment Rendering" against its formulas), [`bucket`] (Table 2 and Figure 6 of
//! "Efficient Depth Peeling via Bucket Sort"), [`occupancy`] (the culling of "Improving
//! k-buffer methods via occupancy maps", Figures 4 and 5 analogues), [`merging`] (image
//! error against k with and without merging, "Z-Thickness Blending: Effective Fragment
//! Merging for Multi-Fragment Rendering"), [`hazards`] (the race benchmark) and
//! [`presorted`] (the hook of the depth-presorted lists). Nothing here is a stored result:
//! every number is measured when the report runs.

pub mod bucket;
pub mod depth_fighting;
pub mod hazards;
pub mod machine;
pub mod merging;
pub mod occupancy;
pub mod page;
pub mod presorted;

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::plot::{BoxPlot, LinePlot, PlotError};
use crate::run::RunError;

pub use machine::Machine;

/// One section of the report (`--paper NAME`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Paper {
    DepthFighting,
    Bucket,
    Occupancy,
    Merging,
    Presorted,
    Hazards,
}

impl Paper {
    /// Every section, in the page's order.
    pub const ALL: [Paper; 6] = [
        Paper::DepthFighting,
        Paper::Bucket,
        Paper::Occupancy,
        Paper::Merging,
        Paper::Presorted,
        Paper::Hazards,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Paper::DepthFighting => "depth-fighting",
            Paper::Bucket => "bucket",
            Paper::Occupancy => "occupancy",
            Paper::Merging => "merging",
            Paper::Presorted => "presorted",
            Paper::Hazards => "hazards",
        }
    }

    /// `--paper` values: one section's name, several separated by commas, or `all`.
    pub fn parse_list(s: &str) -> Result<Vec<Paper>, ReportError> {
        if s == "all" {
            return Ok(Paper::ALL.to_vec());
        }
        let mut out = Vec::new();
        for part in s.split(',') {
            let p = Paper::ALL
                .into_iter()
                .find(|p| p.name() == part)
                .ok_or_else(|| ReportError::UnknownPaper(part.to_string()))?;
            if !out.contains(&p) {
                out.push(p);
            }
        }
        Ok(out)
    }
}

/// What to report, and where.
#[derive(Clone, Debug)]
pub struct PaperConfig {
    pub papers: Vec<Paper>,
    pub out: PathBuf,
    /// Built-in and shipped scenes only, small images and few views (minutes on 2 cores).
    pub quick: bool,
    /// A directory of meshes (`*.obj`, `*.obj.gz`) for the full report; the shipped meshes
    /// (assets/) when `None`.
    pub models: Option<PathBuf>,
    /// Threads of each run.
    pub threads: usize,
    /// The llvmpipe peer's script (`oit.py`), run next to the k-buffer's race when given.
    pub peer: Option<PathBuf>,
}

impl PaperConfig {
    /// The command that regenerates one section alone (what every table and figure of it
    /// carries).
    pub fn command(&self, paper: Paper) -> String {
        let mut c = format!(
            "{} report --paper {} --out {}",
            crate::run::CLI,
            paper.name(),
            self.out.display()
        );
        if self.quick {
            c += " --quick";
        }
        if let Some(m) = &self.models {
            c += &format!(" --models {}", m.display());
        }
        if let (Paper::Hazards, Some(p)) = (paper, &self.peer) {
            c += &format!(" --peer {}", p.display());
        }
        c
    }

    /// The meshes of the full report: the `--models` directory's OBJ files by name, or the
    /// shipped ones.
    pub fn meshes(&self) -> Result<Vec<PathBuf>, ReportError> {
        let Some(dir) = &self.models else {
            return Ok(shipped_meshes());
        };
        let entries = std::fs::read_dir(dir).map_err(|source| ReportError::Io {
            path: dir.clone(),
            source,
        })?;
        let mut found: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                let n = p.to_string_lossy();
                n.ends_with(".obj") || n.ends_with(".obj.gz")
            })
            .collect();
        found.sort();
        if found.is_empty() {
            return Err(ReportError::NoModels(dir.clone()));
        }
        Ok(found)
    }
}

/// The meshes shipped in the repository's `assets/` (when run from it).
fn shipped_meshes() -> Vec<PathBuf> {
    [
        "assets/bunny.obj.gz",
        "assets/teapot.obj.gz",
        "assets/dragon_res4.obj.gz",
    ]
    .iter()
    .map(PathBuf::from)
    .filter(|p| p.exists())
    .collect()
}

/// A short name of a mesh path (its file name without `.obj` or `.obj.gz`).
pub fn mesh_name(p: &Path) -> String {
    let n = p
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    n.trim_end_matches(".gz")
        .trim_end_matches(".obj")
        .to_string()
}

/// A table: its rows as text (CSV, Markdown, HTML) and as values (report.json).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Table {
    /// File stem (`ID.csv`, `ID.md`) and anchor.
    pub id: String,
    pub title: String,
    /// What the columns mean, how it was measured.
    pub caption: String,
    pub columns: Vec<String>,
    pub rows: Vec<Vec<serde_json::Value>>,
    pub command: String,
}

/// A figure: a plot and the command that regenerates it. In report.json the plot's fields
/// (title, axis labels, series with their points) sit beside the figure's own.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Figure {
    /// File stem (`ID.svg`, `ID.png`) and anchor.
    pub id: String,
    pub caption: String,
    #[serde(flatten)]
    pub plot: Plot,
    pub command: String,
}

/// What a figure draws: lines over x, or one box per labelled sample.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(untagged)]
pub enum Plot {
    Lines(LinePlot),
    Boxes(BoxPlot),
}

impl Plot {
    pub fn title(&self) -> &str {
        match self {
            Plot::Lines(p) => &p.title,
            Plot::Boxes(p) => &p.title,
        }
    }

    pub fn write(&self, path: &Path) -> Result<(), PlotError> {
        match self {
            Plot::Lines(p) => p.write(path),
            Plot::Boxes(p) => p.write(path),
        }
    }
}

impl From<LinePlot> for Plot {
    fn from(p: LinePlot) -> Plot {
        Plot::Lines(p)
    }
}

impl From<BoxPlot> for Plot {
    fn from(p: BoxPlot) -> Plot {
        Plot::Boxes(p)
    }
}

/// A picture the section wrote itself (an image strip), with its command.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Picture {
    /// File stem (`ID.png`) and anchor.
    pub id: String,
    pub title: String,
    pub caption: String,
    pub command: String,
}

/// One section as measured.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Section {
    pub paper: Paper,
    pub title: String,
    /// Paragraphs before the tables (plain text).
    pub text: Vec<String>,
    pub tables: Vec<Table>,
    pub figures: Vec<Figure>,
    #[serde(default)]
    pub pictures: Vec<Picture>,
    pub seconds: f64,
    /// Where and when this section was measured (sections of one page may come from
    /// different runs: `--paper bucket` redoes one and keeps the others).
    pub machine: Option<Machine>,
    /// Whether it was measured by a `--quick` report.
    #[serde(default)]
    pub quick: bool,
}

impl Section {
    fn new(paper: Paper, title: &str) -> Section {
        Section {
            paper,
            title: title.into(),
            text: Vec::new(),
            tables: Vec::new(),
            figures: Vec::new(),
            pictures: Vec::new(),
            seconds: 0.0,
            machine: None,
            quick: false,
        }
    }
}

/// Why a report could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error("--paper {0}: unknown section; the sections are depth-fighting, bucket, occupancy, merging, presorted, hazards, or all")]
    UnknownPaper(String),
    #[error("--models {0}: no .obj or .obj.gz file in it")]
    NoModels(PathBuf),
    #[error("--threads {0} is out of range: it must be from 1 to {1}")]
    Threads(usize, usize),
    #[error("{context}: {source}")]
    Run {
        context: String,
        #[source]
        source: Box<RunError>,
    },
    #[error(transparent)]
    Plot(#[from] PlotError),
    #[error("drawing a picture: {0}")]
    Render(#[from] crate::render::RenderError),
    #[error(transparent)]
    Bench(#[from] crate::racebench::BenchError),
    #[error("writing {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// Attaches what was being run to a run's error.
pub(crate) fn ctx<T>(
    r: Result<T, RunError>,
    what: impl FnOnce() -> String,
) -> Result<T, ReportError> {
    r.map_err(|source| ReportError::Run {
        context: what(),
        source: Box::new(source),
    })
}

/// What the report tells its caller while it runs: the figure or table being made.
pub trait Progress: Sync {
    fn step(&self, message: &str);
}

impl<F: Fn(&str) + Sync> Progress for F {
    fn step(&self, message: &str) {
        self(message)
    }
}

/// The report as written.
#[derive(Clone, Debug)]
pub struct Written {
    pub index: PathBuf,
    pub files: Vec<PathBuf>,
    pub seconds: f64,
}

/// The sections of an earlier report in `cfg.out` that this run does not redo, when that
/// report was of the same kind (quick or full): regenerating one section keeps the others on
/// the page, each with the machine and date it was measured on. An unreadable or foreign
/// `report.json` keeps nothing.
pub fn kept_sections(cfg: &PaperConfig) -> Vec<Section> {
    #[derive(serde::Deserialize)]
    struct Earlier {
        quick: bool,
        sections: Vec<Section>,
    }
    let Ok(text) = std::fs::read_to_string(cfg.out.join("report.json")) else {
        return Vec::new();
    };
    let Ok(earlier) = serde_json::from_str::<Earlier>(&text) else {
        return Vec::new();
    };
    if earlier.quick != cfg.quick {
        return Vec::new();
    }
    earlier
        .sections
        .into_iter()
        .filter(|s| !cfg.papers.contains(&s.paper) && s.machine.is_some())
        .collect()
}

/// Measures every section of `cfg` and writes the directory, with the sections of an
/// earlier report there that this run does not redo ([`kept_sections`]).
pub fn generate(cfg: &PaperConfig, progress: &dyn Progress) -> Result<Written, ReportError> {
    let max = fragrace_emu::exec::max_threads();
    if !(1..=max).contains(&cfg.threads) {
        return Err(ReportError::Threads(cfg.threads, max));
    }
    let start = Instant::now();
    let machine = Machine::this(cfg.threads);
    std::fs::create_dir_all(&cfg.out).map_err(|source| ReportError::Io {
        path: cfg.out.clone(),
        source,
    })?;
    let mut sections = kept_sections(cfg);
    for &paper in &cfg.papers {
        let t = Instant::now();
        progress.step(paper.name());
        let mut s = match paper {
            Paper::DepthFighting => depth_fighting::section(cfg, progress)?,
            Paper::Bucket => bucket::section(cfg, progress)?,
            Paper::Occupancy => occupancy::section(cfg, progress)?,
            Paper::Merging => merging::section(cfg, progress)?,
            Paper::Presorted => presorted::section(cfg, progress)?,
            Paper::Hazards => hazards::section(cfg, progress)?,
        };
        s.seconds = t.elapsed().as_secs_f64();
        s.machine = Some(machine.clone());
        s.quick = cfg.quick;
        sections.retain(|k| k.paper != paper);
        sections.push(s);
    }
    sections.sort_by_key(|s| Paper::ALL.iter().position(|&p| p == s.paper));
    progress.step("writing the page");
    let seconds = start.elapsed().as_secs_f64();
    let files = page::write(cfg, &machine, &sections, seconds)?;
    Ok(Written {
        index: cfg.out.join("index.html"),
        files,
        seconds,
    })
}
