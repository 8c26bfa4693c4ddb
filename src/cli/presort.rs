//! `fragrace presort MESH --partitions P --out FILE`: the off-line preprocessing of
//! depth-presorted triangle lists, stored for `render --algo presorted --presorted FILE`.

use std::path::PathBuf;
use std::sync::Mutex;
use std::time::Instant;

use fragrace_kernels::presorted::{self, file, PresortConfig, Progress};

use super::error::{CliError, OptionError};
use super::progress::progress;

/// The options of `presort`.
#[derive(Clone, Debug, clap::Args)]
pub struct PresortOptions {
    /// The mesh: an OBJ file (plain or .gz), or a built-in scene's name.
    pub mesh: String,
    /// Faces of the bounding polyhedron (= viewpoint partitions = segments): 4, 6, 16 or 64.
    #[arg(long, default_value_t = 6)]
    pub partitions: u32,
    /// Where to write the lists (written to a temporary file and renamed when complete).
    /// Each partition that finishes is kept in the directory `OUT.partitions` until the
    /// lists are written: the same command run again after an interruption resumes with
    /// the partitions kept there (each checked against the mesh, the partition count and
    /// the method: a checkpoint of anything else is not used).
    #[arg(long, required_unless_present = "estimate_graph")]
    pub out: Option<PathBuf>,
    /// Worker threads (default: all cores): each partition's occlusion graph is built on all
    /// of them, and several partitions run at once when their graphs fit `--memory-limit`.
    #[arg(long)]
    pub threads: Option<usize>,
    /// How cycles of the occlusion graph are broken: `cells` (strongly connected components,
    /// each cyclic one cut into cells of viewpoint space) or `scan` (the paper's back-edge
    /// scan of section 4.1, whose copies can multiply without bound on curved meshes).
    #[arg(long, default_value = "cells", value_parser = super::parse::parse_method)]
    pub method: fragrace_kernels::presorted::Method,
    /// Remove duplicate triangles (the same three points, in either winding; the first in
    /// file order is kept) and write the mesh without them to this OBJ file (gzip if it ends
    /// in `.gz`): the lists are made for that mesh, so render it (`render --obj PATH
    /// --presorted OUT`); the original mesh is refused by the lists' mesh hash. Without
    /// it, a mesh with duplicate triangles is refused, naming them. OBJ meshes only.
    #[arg(long, value_name = "PATH")]
    pub dedupe_to: Option<PathBuf>,
    /// Instead of presorting, measure the occlusion graphs on ROWS rows of each partition's
    /// graph (evenly spaced) and print the rows per second and the estimated graph time of
    /// every partition (the graphs are most of the preprocessing of a large mesh).
    #[arg(long, value_name = "ROWS")]
    pub estimate_graph: Option<usize>,
    /// Memory the occlusion graphs may hold: as many partitions run at once (up to
    /// `--threads`) as their estimated graphs fit; a graph estimated above it alone is
    /// refused, and building stops if the graphs grow past it (default: half of the physical
    /// memory). E.g. `20G`, `512MiB`.
    #[arg(long, value_name = "SIZE")]
    pub memory_limit: Option<String>,
    /// Print one JSON object on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Progress over every partition: each partition's graph phase is its first half, the scan
/// its second, shown as one bar of `partitions x 1000` steps.
struct Bar {
    bar: indicatif::ProgressBar,
    parts: Mutex<Vec<u64>>,
    /// When each partition last printed a line (seconds since start).
    logged: Mutex<Vec<f64>>,
    start: Instant,
}

impl Progress for Bar {
    fn failed(&self, partition: usize, error: &presorted::PresortError) {
        let now = self.start.elapsed().as_secs_f64();
        self.bar.suspend(|| {
            eprintln!("partition {partition}: failed at {now:.1} s: {error}");
        });
    }

    fn update(&self, partition: usize, phase: &'static str, done: u64, total: u64) {
        let frac = if total == 0 {
            1.0
        } else {
            done as f64 / total as f64
        };
        let v = match phase {
            "graph" | "graph resumed" | "graph carried" => (frac * 500.0) as u64,
            _ => 500 + (frac * 500.0) as u64,
        };
        let now = self.start.elapsed().as_secs_f64();
        // One line per finished phase and one a minute per partition, for logs (the bar is
        // hidden off a terminal).
        let due = self.logged.lock().is_ok_and(|mut l| {
            let slot = l.get_mut(partition);
            match slot {
                Some(t) if done == total || now - *t >= 60.0 => {
                    *t = now;
                    true
                }
                _ => false,
            }
        });
        if due {
            self.bar.suspend(|| {
                if !matches!(phase, "graph" | "scan") {
                    eprintln!("partition {partition}: {phase} at {now:.1} s");
                } else if done == total {
                    eprintln!("partition {partition}: {phase} done at {now:.1} s");
                } else {
                    eprintln!("partition {partition}: {phase} {done} of {total} at {now:.1} s");
                }
            });
        }
        if let Ok(mut p) = self.parts.lock() {
            if let Some(slot) = p.get_mut(partition) {
                *slot = (*slot).max(v);
            }
            self.bar.set_position(p.iter().sum());
        }
    }
}

/// `presort`: the lists preprocessed, saved to `out`, and their statistics printed.
pub fn cmd_presort(a: &PresortOptions) -> Result<(), CliError> {
    if a.threads == Some(0) {
        return Err(OptionError::ZeroThreads.into());
    }
    let threads = a
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    presorted::partition::directions(a.partitions).map_err(CliError::Partitions)?;
    let mesh_error = |source| CliError::Mesh {
        mesh: a.mesh.clone(),
        source,
    };
    let (scene, removed) = match &a.dedupe_to {
        Some(to) => {
            if !a.mesh.contains(".obj") {
                return Err(OptionError::DedupeNeedsObj {
                    mesh: a.mesh.clone(),
                }
                .into());
            }
            let raw = crate::scene::obj::load_obj(&a.mesh)
                .map_err(|e| mesh_error(crate::run::RunError::from(Box::new(e))))?;
            let d = presorted::input::dedupe(&raw);
            write_obj(&d.mesh, to).map_err(CliError::write(to))?;
            let spec = crate::run::SceneSpec::Obj {
                path: to.clone(),
                sha256: None,
            };
            (spec, Some(d.removed.len()))
        }
        None if a.mesh.contains(".obj") => (
            crate::run::SceneSpec::Obj {
                path: a.mesh.clone().into(),
                sha256: None,
            },
            None,
        ),
        None => (crate::run::SceneSpec::Builtin(a.mesh.clone()), None),
    };
    // With --dedupe-to, the written file read back the way `render` reads it: the lists are
    // made from exactly the mesh that is rendered and that the truth is computed from.
    let mesh = scene.load().map_err(mesh_error)?.mesh;
    let bar = Bar {
        bar: progress(
            u64::from(a.partitions) * 1000,
            &format!("presorting {} triangles", mesh.indices.len()),
        ),
        parts: Mutex::new(vec![0; a.partitions as usize]),
        logged: Mutex::new(vec![0.0; a.partitions as usize]),
        start: Instant::now(),
    };
    let (memory_limit, limit_source) = crate::budget::limit(a.memory_limit.as_deref())?;
    if !a.json {
        eprintln!(
            "memory limit of the occlusion graphs: {} ({limit_source})",
            crate::budget::human(memory_limit)
        );
    }
    let cfg = PresortConfig {
        partitions: a.partitions,
        threads,
        method: a.method,
        memory_limit: Some(memory_limit),
    };
    let out = match (a.estimate_graph, &a.out) {
        (Some(rows), _) => return estimate(a, &mesh, &cfg, rows, bar),
        (None, Some(out)) => out,
        // (clap requires one of the two.)
        (None, None) => {
            return Err(presorted::PresortError::Config(
                "presort needs --out FILE, or --estimate-graph ROWS to measure the graphs".into(),
            )
            .into())
        }
    };
    let mut dir = out.clone().into_os_string();
    dir.push(".partitions");
    let checkpoints = presorted::checkpoint::Checkpoints::new(dir);
    if !a.json && checkpoints.dir().exists() {
        eprintln!(
            "resuming: partitions finished by an earlier run are read from {}",
            checkpoints.dir().display()
        );
    }
    let t = Instant::now();
    let lists = presorted::presort_with(&mesh, &cfg, Some(&checkpoints), &bar)?;
    let secs = t.elapsed().as_secs_f64();
    bar.bar.finish_and_clear();
    file::save(&lists, out)?;
    checkpoints.remove()?;
    let per: Vec<serde_json::Value> = lists
        .stats
        .iter()
        .zip(&lists.segments)
        .map(|(s, seg)| {
            serde_json::json!({
                "instances": seg.instances.len(),
                "initial_instances": s.initial_nodes,
                "edges": s.edges,
                "back_edges": s.back_edges,
                "moves": s.scan.moves,
                "splits": s.scan.splits,
                "pairwise_splits": s.scan.pairwise,
                "b_f_duplications": s.scan.bf_dups,
                "whole_moves": s.scan.whole_moves,
                "lp_calls": s.scan.lp_calls,
                "touching_tests": s.scan.touching_tests,
                "touching_planes": s.scan.touching_planes,
                "cyclic_components": s.cells.cyclic_components,
                "largest_component": s.cells.largest_component,
                "cell_cuts": s.cells.cuts,
                "prefix_cuts": s.cells.prefix_cuts,
                "max_cell_depth": s.cells.max_depth,
                "graph_s": s.graph_time.as_secs_f64(),
                "scan_s": s.scan_time.as_secs_f64(),
                "resumed": s.resumed,
            })
        })
        .collect();
    let summary = serde_json::json!({
        "mesh": a.mesh,
        "triangles": lists.triangles,
        "non_manifold_edges": presorted::input::non_manifold_edges(&mesh),
        "duplicates_removed": removed,
        "mesh_written": a.dedupe_to,
        "partitions": a.partitions,
        "threads": threads,
        "seconds": secs,
        "instances": lists.total_instances(),
        "duplication_ratio": lists.duplication_ratio(),
        "avg_segment_ratio": lists.avg_segment_ratio(),
        "out": out,
        "per_partition": per,
    });
    if a.json {
        println!("{summary}");
    } else {
        if let (Some(n), Some(to)) = (removed, &a.dedupe_to) {
            println!(
                "{}: {n} duplicate triangles removed; the mesh presorted (render this one) \
                 written to {}",
                a.mesh,
                to.display()
            );
        }
        println!(
            "{} ({} triangles): {} partitions in {:.1} s on {} threads; {} instances, \
             duplication ratio {:.3}, average segment {:.3} of the input; written to {}",
            a.mesh,
            lists.triangles,
            a.partitions,
            secs,
            threads,
            lists.total_instances(),
            lists.duplication_ratio(),
            lists.avg_segment_ratio(),
            out.display()
        );
    }
    Ok(())
}

/// `presort --estimate-graph ROWS`: the graphs measured on a sample of rows.
fn estimate(
    a: &PresortOptions,
    mesh: &fragrace_emu::Mesh,
    cfg: &PresortConfig,
    rows: usize,
    bar: Bar,
) -> Result<(), CliError> {
    let t = Instant::now();
    let est = presorted::estimate_graph(mesh, cfg, rows, &bar)?;
    let secs = t.elapsed().as_secs_f64();
    bar.bar.finish_and_clear();
    let total: f64 = est.iter().map(|e| e.graph_seconds()).sum();
    let wall = total / cfg.threads.min(est.len()).max(1) as f64;
    // What the `threads` largest graphs hold, built at once.
    let mut bytes: Vec<u64> = est.iter().map(|e| e.graph_bytes).collect();
    bytes.sort_unstable_by(|x, y| y.cmp(x));
    let at_once: u64 = bytes.iter().take(cfg.threads).sum();
    if a.json {
        let per: Vec<serde_json::Value> = est
            .iter()
            .map(|e| {
                serde_json::json!({
                    "nodes": e.nodes,
                    "rows": e.rows,
                    "edges": e.edges,
                    "exact_pairs": e.pairs.pairs,
                    "witnessed_edges": e.pairs.witnessed,
                    "clipped_edges": e.pairs.clipped,
                    "seconds": e.seconds,
                    "rows_per_second": e.rows_per_second(),
                    "graph_seconds": e.graph_seconds(),
                    "graph_edges": e.graph_edges,
                    "graph_bytes": e.graph_bytes,
                })
            })
            .collect();
        let summary = serde_json::json!({
            "mesh": a.mesh,
            "triangles": mesh.indices.len(),
            "partitions": cfg.partitions,
            "threads": cfg.threads,
            "memory_limit": cfg.memory_limit,
            "graph_bytes_at_once": at_once,
            "seconds": secs,
            "graph_seconds_sum": total,
            "graph_wall_seconds": wall,
            "per_partition": per,
        });
        println!("{summary}");
    } else {
        for (k, e) in est.iter().enumerate() {
            println!(
                "partition {k}: {} rows of {} in {:.1} s ({:.1} rows/s, {} edges of {} pairs \
                 past the cheap tests, {} by a witness): graph about {:.0} s, {} edges, {}",
                e.rows,
                e.nodes,
                e.seconds,
                e.rows_per_second(),
                e.edges,
                e.pairs.pairs,
                e.pairs.witnessed,
                e.graph_seconds(),
                e.graph_edges,
                crate::budget::human(e.graph_bytes)
            );
        }
        println!(
            "{} ({} triangles, {} partitions): graphs about {:.0} s in all, {:.0} s wall on {} \
             threads; the largest {} at once hold about {} (limit {})",
            a.mesh,
            mesh.indices.len(),
            cfg.partitions,
            total,
            wall,
            cfg.threads,
            cfg.threads.min(est.len()),
            crate::budget::human(at_once),
            cfg.memory_limit.map_or("none".into(), crate::budget::human)
        );
    }
    Ok(())
}

/// Writes `mesh` as OBJ ([`crate::scene::obj::obj_text`]), gzip if `path` ends in `.gz`.
fn write_obj(mesh: &fragrace_emu::Mesh, path: &std::path::Path) -> std::io::Result<()> {
    use std::io::Write as _;
    let text = format!(
        "# written by fragrace presort --dedupe-to\n{}",
        crate::scene::obj::obj_text(mesh)
    );
    let bytes = if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gz"))
    {
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
        gz.write_all(text.as_bytes())?;
        gz.finish()?
    } else {
        text.into_bytes()
    };
    std::fs::write(path, bytes)
}
