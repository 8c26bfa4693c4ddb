//! Depth-presorted triangle lists ("Depth-Presorted Triangle Lists", Chen, Sander, Nehab,
//! Yang and Hu): an off-line preprocessing turns a static mesh into an extended list of
//! triangle instances, each annotated with test planes, such that for every viewpoint
//! outside a bounding polyhedron the instances that pass their tests are the mesh's
//! triangles, each exactly once, in back-to-front order. At run time no sorting is left:
//! the CPU picks the viewpoint's segment, the GPU selects instances by one dot product and
//! blends in API order.
//!
//! Preprocessing (sections 3-4), one concept per file:
//! - [`geom`]: half-spaces, convex regions of viewpoint space, occlusion regions;
//! - [`separate`]: separability of two regions (the distance of their hulls);
//! - [`partition`]: the bounding polyhedron (4, 6, 16 or 64 faces) and its partitions;
//! - [`graph`]: the occlusion graph of a partition (back-facing duplicates included);
//! - [`order`]: the preliminary order (depth sort and feedback-arc heuristic);
//! - [`scan`]: the back-edge scan with duplication and cutting planes (section 4.1);
//! - [`scc`], [`cells`]: the default in place of the scan: cyclic components resolved by
//!   subdividing viewpoint space with the same cutting planes;
//! - [`input`]: what meshes are accepted; [`split`]: intersecting triangles split apart;
//!   [`file`]: the stored result; [`checkpoint`]: finished partitions kept for a rerun;
//!   [`carry`]: a round after cutting cycles reuses the previous round's components;
//!   `pipeline`: one partition's work, from its checkpoints to its segment.
//!
//! Run time (section 5): [`runtime`] (`presorted`, `presorted-vs`, `presorted-ssbo`,
//! `presorted-ssbo-interlock`).

pub mod carry;
pub mod cells;
pub mod checkpoint;
pub mod file;
pub mod geom;
pub mod graph;
pub mod input;
pub mod order;
pub mod partition;
mod pipeline;
pub mod runtime;
pub mod scan;
pub mod scc;
pub mod separate;
pub mod split;

use std::sync::Arc;
use std::time::{Duration, Instant};

use fragrace_emu::Mesh;
use glam::DVec3;

use pipeline::{partition_with, Part, Previous, Store};

pub use input::InputError;
pub use partition::{Frame3, ViewpointError};
pub use runtime::algorithms;

/// How to preprocess.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PresortConfig {
    /// Faces of the bounding polyhedron = partitions of viewpoint space: 4, 6, 16 or 64.
    pub partitions: u32,
    /// Worker threads: several partitions at once when their graphs fit in
    /// `memory_limit` together, and each graph's rows on every thread.
    pub threads: usize,
    /// How cycles of the occlusion graph are broken.
    pub method: Method,
    /// Bytes the occlusion graphs built at once may hold (`None`: unbounded). Checked up
    /// front from a sample of each graph's rows, which sets how many partitions run at once
    /// (down to one; [`PresortError::Memory`] when the largest graph alone would not fit),
    /// and while the graphs grow ([`graph::GraphError`]).
    pub memory_limit: Option<u64>,
}

impl Default for PresortConfig {
    fn default() -> Self {
        PresortConfig {
            partitions: 6,
            threads: 2,
            method: Method::default(),
            memory_limit: None,
        }
    }
}

/// How cycles of the occlusion graph are broken (both place copies with test planes).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Method {
    /// Strongly connected components, each cyclic one resolved by cutting viewpoint space
    /// into cells ([`cells`]).
    #[default]
    Cells,
    /// The paper's back-edge scan over a preliminary order ([`scan`], section 4.1): its
    /// copies multiply on the teapot (see `cells`).
    Scan,
}

/// One triangle instance of a segment, in draw order.
#[derive(Clone, Debug, PartialEq)]
pub struct Instance {
    /// The piece it draws ([`Presorted::pieces`]; piece `i` is input triangle `i` when no
    /// triangle had to be split).
    pub piece: u32,
    /// The back-facing duplicate: rendered only from behind the triangle's plane.
    pub back: bool,
    /// The last instance of its triangle and facing in the segment: the paper leaves its
    /// test planes to a LESS depth test (section 4.1: it is drawn iff no earlier copy was).
    /// Stored, but the run time here tests every copy's planes ([`runtime`] says why).
    pub last: bool,
    /// Test planes `p` (world space), all of which must pass: `dot(p, [v, -1]) > 0`.
    /// The last instance keeps them too (its exact region).
    pub planes: Vec<[f32; 4]>,
}

/// The instances of one partition, in draw order (back to front).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Segment {
    pub instances: Vec<Instance>,
}

/// What preprocessing one partition did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PartitionStats {
    /// Triangle instances rendered from some viewpoint of the partition, before the scan.
    pub initial_nodes: usize,
    pub edges: usize,
    /// Back-edges of the preliminary order.
    pub back_edges: usize,
    pub scan: scan::ScanStats,
    /// What the cell subdivision did ([`Method::Cells`]).
    pub cells: cells::CellStats,
    pub graph_time: Duration,
    pub scan_time: Duration,
    /// Read from a checkpoint of an earlier run ([`checkpoint`]; its times are that run's).
    pub resumed: bool,
}

/// A piece of an input triangle: the whole triangle, or a part of one that crossed another
/// ([`split`]). It is drawn as its input triangle, keeping the fragments inside its clips.
#[derive(Clone, Debug, PartialEq)]
pub struct Piece {
    /// The input triangle.
    pub tri: u32,
    /// Half-spaces (world space, `[n, w]`): a fragment at `p` on the input triangle is the
    /// piece's iff `(dot(n, p) - w >= 0) == nonneg` for each.
    pub clips: Vec<WorldClip>,
}

/// One clip of a [`Piece`] in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldClip {
    pub plane: [f32; 4],
    pub nonneg: bool,
}

/// The preprocessing's result: one segment per partition.
#[derive(Clone, Debug, PartialEq)]
pub struct Presorted {
    pub mesh_hash: u64,
    pub triangles: u32,
    /// What is drawn: the input triangles, or pieces of them where triangles crossed.
    pub pieces: Vec<Piece>,
    pub frame: Frame3,
    pub dirs: Vec<DVec3>,
    pub segments: Vec<Segment>,
    /// Per partition (empty for a result read from a file).
    pub stats: Vec<PartitionStats>,
    /// What splitting crossing triangles did (zero for a result read from a file).
    pub split: split::SplitStats,
}

impl Presorted {
    /// Instances in all segments.
    pub fn total_instances(&self) -> usize {
        self.segments.iter().map(|s| s.instances.len()).sum()
    }
    /// Whether some input triangle was split (pieces are then not the input triangles).
    pub fn is_split(&self) -> bool {
        self.pieces.len() != self.triangles as usize
    }
    /// Memory ratio of the paper's figure 5: all instances over the input triangles.
    pub fn duplication_ratio(&self) -> f64 {
        self.total_instances() as f64 / self.triangles.max(1) as f64
    }
    /// Average draw-call size over the input triangles (figure 5).
    pub fn avg_segment_ratio(&self) -> f64 {
        self.total_instances() as f64
            / self.segments.len().max(1) as f64
            / self.triangles.max(1) as f64
    }
    /// The segment of a world-space viewpoint.
    pub fn locate(&self, eye: DVec3) -> Result<usize, ViewpointError> {
        partition::locate(&self.frame, &self.dirs, eye)
    }
}

/// Why preprocessing failed.
#[derive(Debug, thiserror::Error)]
pub enum PresortError {
    #[error(transparent)]
    Input(#[from] InputError),
    #[error(transparent)]
    Split(#[from] split::SplitError),
    #[error("{0}")]
    Config(String),
    /// (The scan's error is part of this message, not a `source`: error chains would
    /// print it twice.)
    #[error("partition {partition}: {error}")]
    Scan {
        partition: usize,
        error: scan::ScanError,
    },
    #[error("partition {partition}: {error}")]
    Cells {
        partition: usize,
        error: cells::CellError,
    },
    #[error(
        "saving a partition's checkpoint (its graph's components or its result) for a rerun: {0}"
    )]
    Checkpoint(file::FileError),
    #[error("partition {partition}: {error}")]
    Graph {
        partition: usize,
        error: graph::GraphError,
    },
    #[error(
        "the largest occlusion graph would need about {} (per partition, estimated from \
         {rows} rows of each: {}), over the memory limit of {}: use fewer partitions, a \
         simpler mesh, or a higher --memory-limit if the machine has the memory",
        graph::gib(*estimate),
        per_partition.iter().map(|b| graph::gib(*b)).collect::<Vec<_>>().join(", "),
        graph::gib(*limit)
    )]
    Memory {
        estimate: u64,
        limit: u64,
        rows: usize,
        per_partition: Vec<u64>,
    },
}

/// Progress of preprocessing: `(partition, phase, done, total)`, phase `"graph"` or
/// `"scan"`. Called from the worker threads.
pub trait Progress: Sync {
    fn update(&self, partition: usize, phase: &'static str, done: u64, total: u64);

    /// Partition `partition` failed with `error` (the other partitions go on, and the
    /// finished ones are kept when checkpoints are on; [`presort`] returns the first error,
    /// or starts a round that cuts cycles seen whole, once all have run). Called as it
    /// happens, so that a long run shows it hours before its end. Nothing by default.
    fn failed(&self, partition: usize, error: &PresortError) {
        let _ = (partition, error);
    }
}

/// No progress reporting.
pub struct Silent;

impl Progress for Silent {
    fn update(&self, _: usize, _: &'static str, _: u64, _: u64) {}
}

/// Rounds of cutting pieces of cycles seen whole from a viewpoint before preprocessing
/// gives up ([`split::break_cycle`]).
pub const MAX_CYCLE_ROUNDS: u32 = 8;

/// What [`presort`] and [`estimate_graph`] start from: the partitions' directions, the
/// mesh's local frame, its triangles in that frame, and the pool of `cfg.threads` threads
/// (the configuration and the mesh checked first).
struct Prepared {
    dirs: Vec<DVec3>,
    frame: Frame3,
    input: Vec<[DVec3; 3]>,
    pool: rayon::ThreadPool,
}

fn prepare(mesh: &Mesh, cfg: &PresortConfig) -> Result<Prepared, PresortError> {
    if cfg.threads == 0 {
        return Err(PresortError::Config(
            "threads 0: preprocessing needs at least 1 thread".into(),
        ));
    }
    let dirs = partition::directions(cfg.partitions).map_err(PresortError::Config)?;
    input::check(mesh)?;
    let frame = Frame3::of(&mesh.positions);
    let input = mesh
        .indices
        .iter()
        .map(|t| t.map(|i| frame.to_local(mesh.positions[i as usize].as_dvec3())))
        .collect();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(cfg.threads)
        .build()
        .map_err(|e| PresortError::Config(format!("thread pool: {e}")))?;
    Ok(Prepared {
        dirs,
        frame,
        input,
        pool,
    })
}

/// Preprocesses `mesh` (sections 3-4.2): as many partitions at once as their graphs fit the
/// memory limit (at most `cfg.threads`), each graph's rows on every thread.
pub fn presort(
    mesh: &Mesh,
    cfg: &PresortConfig,
    progress: &dyn Progress,
) -> Result<Presorted, PresortError> {
    presort_with(mesh, cfg, None, progress)
}

/// [`presort`], each partition that finishes saved to `checkpoints`, and each partition
/// whose valid checkpoint is there read instead of computed ([`checkpoint`]: an
/// interrupted run resumes). A checkpoint that is there but not valid is reported to
/// `progress` (phase `"checkpoint ignored"`) and its partition computed again; a resumed
/// one is reported as phase `"resumed"`.
pub fn presort_with(
    mesh: &Mesh,
    cfg: &PresortConfig,
    checkpoints: Option<&checkpoint::Checkpoints>,
    progress: &dyn Progress,
) -> Result<Presorted, PresortError> {
    let Prepared {
        dirs,
        frame,
        input,
        pool,
    } = prepare(mesh, cfg)?;
    let (mut split_pieces, mut split_stats) = split::split_crossing(&input)?;
    let tris: Arc<[[DVec3; 3]]> = split_pieces.iter().map(|p| p.pos).collect();
    let at_once = check_memory(&tris, &dirs, cfg, &pool, progress)?;
    let budget = graph::MemoryBudget::new(cfg.memory_limit);
    // Rounds: a cycle seen whole from some viewpoint is broken by cutting one of its pieces
    // by another's plane, and every partition runs again on the new pieces.
    let mut round = 0;
    // The previous round's pieces and how this round's came from them ([`carry`]).
    let mut previous: Option<Previous> = None;
    let results: Vec<(Segment, PartitionStats)> = loop {
        let tris: Arc<[[DVec3; 3]]> = split_pieces.iter().map(|p| p.pos).collect();
        // `at_once` partitions at a time (each graph's rows also run on every thread).
        let all: Vec<Result<(Segment, PartitionStats), PresortError>> = pool.install(|| {
            use rayon::prelude::*;
            let ks: Vec<usize> = (0..dirs.len()).collect();
            ks.chunks(at_once)
                .flat_map(|group| {
                    group
                        .par_iter()
                        .map(|&k| {
                            let part = Part {
                                tris: &tris,
                                dirs: &dirs,
                                k,
                                frame: &frame,
                            };
                            let store = Store {
                                checkpoints,
                                previous: previous.as_ref(),
                            };
                            partition_with(&part, cfg.method, &budget, store, progress)
                        })
                        .collect::<Vec<_>>()
                })
                .collect()
        });
        if all.iter().all(Result::is_ok) {
            break all.into_iter().map(|r| r.expect("checked")).collect();
        }
        round += 1;
        let before = split_pieces.len();
        let (mut cut, mut parts): (Vec<usize>, Vec<usize>) = (Vec::new(), Vec::new());
        let mut first_err: Option<PresortError> = None;
        for r in all {
            let Err(e) = r else { continue };
            if let PresortError::Cells {
                error: cells::CellError::Visible { cycles, .. },
                ..
            } = &e
            {
                if round <= MAX_CYCLE_ROUNDS {
                    for c in cycles {
                        let n = split_pieces.len();
                        if let Some(a) = split::break_cycle(&mut split_pieces, c) {
                            cut.push(a);
                            parts.extend(std::iter::repeat_n(a, split_pieces.len() - n));
                        }
                    }
                }
            }
            first_err.get_or_insert(e);
        }
        if cut.is_empty() {
            return Err(first_err.expect("some partition failed"));
        }
        split_stats.cycle_cuts += cut.len() as u64;
        previous = Some(Previous {
            tris,
            lineage: carry::Lineage::new(before, &cut, &parts),
        });
        split_stats.extra_pieces = (split_pieces.len() - input.len()) as u64;
    };
    let pieces = world_pieces(&frame, &split_pieces);
    let (segments, stats): (Vec<Segment>, Vec<PartitionStats>) = results.into_iter().unzip();
    Ok(Presorted {
        mesh_hash: input::mesh_hash(mesh),
        triangles: mesh.indices.len() as u32,
        pieces,
        frame,
        dirs,
        segments,
        stats,
        split: split_stats,
    })
}

/// The measured cost of one partition's occlusion graph, from a sample of its rows
/// ([`estimate_graph`]).
#[derive(Clone, Debug, PartialEq)]
pub struct GraphEstimate {
    /// Nodes of the partition's graph (its rows).
    pub nodes: usize,
    /// Rows built (evenly spaced over the nodes).
    pub rows: usize,
    /// Edges leaving the rows built.
    pub edges: usize,
    /// How the rows' pairs were decided.
    pub pairs: graph::RowStats,
    /// Time the rows took.
    pub seconds: f64,
    /// The whole graph's edges at the sample's rate (edges per row).
    pub graph_edges: u64,
    /// The whole graph's bytes ([`graph::Graph::bytes_for`]: nodes, and `graph_edges`
    /// edges with the in-edges if the method needs them).
    pub graph_bytes: u64,
}

impl GraphEstimate {
    /// Rows per second.
    pub fn rows_per_second(&self) -> f64 {
        self.rows as f64 / self.seconds.max(1e-9)
    }
    /// The whole graph's time at the sample's rate.
    pub fn graph_seconds(&self) -> f64 {
        self.nodes as f64 / self.rows_per_second()
    }
}

/// Measures what the occlusion graphs of `mesh` would cost without building them: in every
/// partition (in parallel on `cfg.threads`, as [`presort`] runs them), the out-edges of
/// `rows` nodes evenly spaced over the graph's nodes. The pieces are those of the first
/// round (crossing triangles split; a later round's cycle cuts add a few pieces).
pub fn estimate_graph(
    mesh: &Mesh,
    cfg: &PresortConfig,
    rows: usize,
    progress: &dyn Progress,
) -> Result<Vec<GraphEstimate>, PresortError> {
    if rows == 0 {
        return Err(PresortError::Config(
            "rows 0: the estimate needs at least 1 row of each graph".into(),
        ));
    }
    let Prepared {
        dirs, input, pool, ..
    } = prepare(mesh, cfg)?;
    let (pieces, _) = split::split_crossing(&input)?;
    let tris: Arc<[[DVec3; 3]]> = pieces.iter().map(|p| p.pos).collect();
    sample_graphs(&tris, &dirs, cfg, rows, &pool, progress)
}

/// The out-edges of `rows` nodes evenly spaced over each partition's graph, measured
/// (in parallel on `pool`).
fn sample_graphs(
    tris: &Arc<[[DVec3; 3]]>,
    dirs: &[DVec3],
    cfg: &PresortConfig,
    rows: usize,
    pool: &rayon::ThreadPool,
    progress: &dyn Progress,
) -> Result<Vec<GraphEstimate>, PresortError> {
    let in_edges = cfg.method == Method::Scan;
    pool.install(|| {
        use rayon::prelude::*;
        (0..dirs.len())
            .into_par_iter()
            .map(|k| {
                let region = partition::partition_region(dirs, k);
                let mut g = graph::Graph::nodes_of(tris.clone(), &region);
                let n = g.nodes.len();
                let take = rows.min(n);
                let t = Instant::now();
                // (A sample holds a fraction of the graph: it is not bounded.)
                let unbounded = graph::MemoryBudget::new(None);
                let pairs = g
                    .add_rows(
                        (0..take).map(|r| r * n / take),
                        graph::RowWork::Sequential,
                        &unbounded,
                        &|d, t| progress.update(k, "graph", d, t),
                    )
                    .map_err(|error| PresortError::Graph {
                        partition: k,
                        error,
                    })?;
                let edges = g.edge_count();
                let graph_edges = (edges as f64 * n as f64 / take.max(1) as f64).round() as u64;
                Ok(GraphEstimate {
                    nodes: n,
                    rows: take,
                    edges,
                    pairs,
                    seconds: t.elapsed().as_secs_f64(),
                    graph_edges,
                    graph_bytes: g.bytes_for(graph_edges, in_edges),
                })
            })
            .collect()
    })
}

/// Rows of each partition's graph [`check_memory`] samples when the worst case (every
/// ordered pair of nodes an edge) does not fit.
pub const MEMORY_SAMPLE_ROWS: usize = 64;

/// The largest `k` of `bytes`, summed: what `k` graphs built at once hold at most.
fn largest_sum(bytes: &[u64], k: usize) -> u64 {
    let mut b = bytes.to_vec();
    b.sort_unstable_by(|x, y| y.cmp(x));
    b.iter().take(k).sum()
}

/// How many partitions' graphs may be built at once within `cfg.memory_limit` (at most
/// `cfg.threads`; each graph's rows run on every thread anyway, [`graph::RowWork`]), and
/// refuses, before any graph is built, a mesh whose largest graph alone would not fit: each
/// graph at its worst case (n (n - 1) edges) or, when that does not fit, estimated from
/// [`MEMORY_SAMPLE_ROWS`] rows.
fn check_memory(
    tris: &Arc<[[DVec3; 3]]>,
    dirs: &[DVec3],
    cfg: &PresortConfig,
    pool: &rayon::ThreadPool,
    progress: &dyn Progress,
) -> Result<usize, PresortError> {
    let most = cfg.threads.min(dirs.len()).max(1);
    let Some(limit) = cfg.memory_limit else {
        return Ok(most);
    };
    let in_edges = cfg.method == Method::Scan;
    let worst: Vec<u64> = (0..dirs.len())
        .map(|k| {
            let g = graph::Graph::nodes_of(tris.clone(), &partition::partition_region(dirs, k));
            let n = g.nodes.len() as u64;
            g.bytes_for(n * n.saturating_sub(1), in_edges)
        })
        .collect();
    if largest_sum(&worst, most) <= limit {
        return Ok(most);
    }
    let est = sample_graphs(tris, dirs, cfg, MEMORY_SAMPLE_ROWS, pool, progress)?;
    if let Some(k) = est.iter().position(|e| e.graph_edges > graph::MAX_IDS) {
        return Err(PresortError::Graph {
            partition: k,
            error: graph::GraphError::TooManyEdges,
        });
    }
    let per_partition: Vec<u64> = est.iter().map(|e| e.graph_bytes).collect();
    match (1..=most)
        .rev()
        .find(|&k| largest_sum(&per_partition, k) <= limit)
    {
        Some(k) => Ok(k),
        None => Err(PresortError::Memory {
            estimate: largest_sum(&per_partition, 1),
            limit,
            rows: MEMORY_SAMPLE_ROWS,
            per_partition,
        }),
    }
}

/// The pieces with their clips in world space.
fn world_pieces(frame: &Frame3, pieces: &[split::Piece]) -> Vec<Piece> {
    pieces
        .iter()
        .map(|p| Piece {
            tri: p.tri,
            clips: p
                .clips
                .iter()
                .map(|c| WorldClip {
                    plane: frame.world_plane(&c.plane).map(|x| x as f32),
                    nonneg: c.nonneg,
                })
                .collect(),
        })
        .collect()
}

/// The tests' fixed random numbers in [-1, 1): a 64-bit LCG from a fixed seed.
#[cfg(test)]
fn test_lcg() -> impl FnMut() -> f64 {
    test_lcg_from(TEST_LCG_SEED)
}

/// [`test_lcg`]'s seed.
#[cfg(test)]
const TEST_LCG_SEED: u64 = 0x2545_f491_4f6c_dd1d;

/// [`test_lcg`] from `seed`.
#[cfg(test)]
fn test_lcg_from(mut seed: u64) -> impl FnMut() -> f64 {
    move || {
        seed = seed
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}
