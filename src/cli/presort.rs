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
    #[arg(long)]
    pub out: PathBuf,
    /// Worker threads (partitions run one per task; default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// How cycles of the occlusion graph are broken: `cells` (strongly connected components,
    /// each cyclic one cut into cells of viewpoint space) or `scan` (the paper's back-edge
    /// scan of section 4.1, whose copies can multiply without bound on curved meshes).
    #[arg(long, default_value = "cells", value_parser = super::parse::parse_method)]
    pub method: fragrace_kernels::presorted::Method,
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
    fn update(&self, partition: usize, phase: &'static str, done: u64, total: u64) {
        let frac = if total == 0 {
            1.0
        } else {
            done as f64 / total as f64
        };
        let v = match phase {
            "graph" => (frac * 500.0) as u64,
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
                if done == total {
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
    let scene = if a.mesh.contains(".obj") {
        crate::run::SceneSpec::Obj {
            path: a.mesh.clone().into(),
            sha256: None,
        }
    } else {
        crate::run::SceneSpec::Builtin(a.mesh.clone())
    };
    let mesh = scene
        .load()
        .map_err(|source| CliError::Mesh {
            mesh: a.mesh.clone(),
            source,
        })?
        .mesh;
    let bar = Bar {
        bar: progress(
            u64::from(a.partitions) * 1000,
            &format!("presorting {} triangles", mesh.indices.len()),
        ),
        parts: Mutex::new(vec![0; a.partitions as usize]),
        logged: Mutex::new(vec![0.0; a.partitions as usize]),
        start: Instant::now(),
    };
    let t = Instant::now();
    let lists = presorted::presort(
        &mesh,
        &PresortConfig {
            partitions: a.partitions,
            threads,
            method: a.method,
        },
        &bar,
    )?;
    let secs = t.elapsed().as_secs_f64();
    bar.bar.finish_and_clear();
    file::save(&lists, &a.out)?;
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
            })
        })
        .collect();
    let summary = serde_json::json!({
        "mesh": a.mesh,
        "triangles": lists.triangles,
        "non_manifold_edges": presorted::input::non_manifold_edges(&mesh),
        "partitions": a.partitions,
        "threads": threads,
        "seconds": secs,
        "instances": lists.total_instances(),
        "duplication_ratio": lists.duplication_ratio(),
        "avg_segment_ratio": lists.avg_segment_ratio(),
        "out": a.out,
        "per_partition": per,
    });
    if a.json {
        println!("{summary}");
    } else {
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
            a.out.display()
        );
    }
    Ok(())
}
