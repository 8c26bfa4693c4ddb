//! "Depth-Presorted Triangle Lists", measured with the library's preprocessing
//! ([`fragrace_kernels::presorted::presort`], the same as `fragrace presort`): the Figure 5
//! analogue (duplication ratio and average segment size against the number of viewpoint
//! partitions) and the Figure 6 analogue (preprocessing time against the triangle count).
//! A preprocessing that fails (a scan that cannot make progress) is a measured outcome: its
//! cell says so, and the report goes on.

use std::time::Instant;

use fragrace_kernels::presorted::{self, PresortConfig, Presorted, Silent};
use serde_json::json;

use super::{mesh_name, Figure, Paper, PaperConfig, Progress, ReportError, Section, Table};
use crate::plot::{LinePlot, Series};
use crate::run::SceneSpec;
use crate::scene::builtin::torus;
use fragrace_emu::geometry::Mesh;

/// Faces of the bounding polyhedron (= viewpoint partitions) the paper's Figure 5 sweeps.
pub const PARTITIONS: [u32; 4] = [4, 6, 16, 64];

/// The partition count of the time-against-triangles figure (the paper's default cube).
pub const TIME_PARTITIONS: u32 = 6;

/// Meshes above this many triangles are left out of the report's time figure (and named):
/// the preprocessing's occlusion graph and scan grow faster than the triangles; on the
/// shipped teapot (992 triangles) the scan does not finish yet (docs/algorithms.md), so
/// only what finishes is timed here.
pub const MAX_TRIANGLES: usize = 600;

/// One preprocessing, timed.
struct Measured {
    triangles: usize,
    result: Result<Presorted, String>,
    seconds: f64,
}

fn measure(mesh: &Mesh, partitions: u32, threads: usize) -> Measured {
    let t = Instant::now();
    let result = presorted::presort(
        mesh,
        &PresortConfig {
            partitions,
            threads,
            ..Default::default()
        },
        &Silent,
    )
    .map_err(|e| e.to_string());
    Measured {
        triangles: mesh.indices.len(),
        result,
        seconds: t.elapsed().as_secs_f64(),
    }
}

/// Tori of growing size ([`torus`]): closed, non-convex, with occlusion cycles across
/// viewpoints, small enough that every partition count finishes.
pub const TORI: [(u32, u32); 4] = [(8, 4), (12, 6), (16, 8), (24, 12)];

/// The meshes of the time figure: the tori (quick: the two smallest), then in the full
/// report the meshes of `--models` up to [`MAX_TRIANGLES`] (named when left out).
fn meshes(cfg: &PaperConfig, s: &mut Section) -> Result<Vec<(String, Mesh)>, ReportError> {
    let tori = if cfg.quick { &TORI[..2] } else { &TORI[..] };
    let mut out: Vec<(String, Mesh)> = tori
        .iter()
        .map(|&(n, m)| (format!("torus {n}x{m}"), torus(n, m)))
        .collect();
    if cfg.quick {
        return Ok(out);
    }
    for p in cfg.meshes()? {
        let name = mesh_name(&p);
        let scene = SceneSpec::Obj {
            path: p,
            sha256: None,
        };
        let mesh = scene
            .load()
            .map_err(|source| ReportError::Run {
                context: name.clone(),
                source: Box::new(source),
            })?
            .mesh;
        if mesh.indices.len() > MAX_TRIANGLES {
            s.text.push(format!(
                "{name} ({} triangles) is left out of the time figure: above {MAX_TRIANGLES} \
                 triangles the scan does not finish yet (the teapot's 992 ran past 15 \
                 minutes; docs/algorithms.md, presorted lists).",
                mesh.indices.len()
            ));
            continue;
        }
        out.push((name, mesh));
    }
    out.sort_by_key(|(_, m)| m.indices.len());
    Ok(out)
}

fn round(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

/// The section.
pub fn section(cfg: &PaperConfig, progress: &dyn Progress) -> Result<Section, ReportError> {
    let mut s = Section::new(Paper::Presorted, "Depth-presorted triangle lists");
    let sized = meshes(cfg, &mut s)?;
    s.text.push(format!(
        "Preprocessing (sections 3-4 of the paper: back-facing duplicates, the occlusion \
         graph, the preliminary order and the scan that duplicates at back-edges), one \
         partition per task on {} threads. Duplication ratio: all instances over the input \
         triangles (the paper's memory ratio); average segment: instances per segment over \
         the input triangles (the draw call's size).",
        cfg.threads
    ));
    // Figure 5: the smallest mesh against the partition count.
    let mut rows = Vec::new();
    let mut ratio = Vec::new();
    let mut segment = Vec::new();
    // The torus of the paper's size class (the second: 144 triangles).
    if let Some((name, mesh)) = sized.get(1).or(sized.first()) {
        for p in PARTITIONS {
            progress.step(&format!("presorted: {name}, {p} partitions"));
            let m = measure(mesh, p, cfg.threads);
            match &m.result {
                Ok(r) => {
                    ratio.push((f64::from(p), r.duplication_ratio()));
                    segment.push((f64::from(p), r.avg_segment_ratio()));
                    rows.push(vec![
                        json!(name),
                        json!(m.triangles),
                        json!(p),
                        json!(r.total_instances()),
                        json!(round(r.duplication_ratio())),
                        json!(round(r.avg_segment_ratio())),
                        json!(round(m.seconds)),
                        json!(""),
                    ]);
                }
                Err(e) => rows.push(vec![
                    json!(name),
                    json!(m.triangles),
                    json!(p),
                    json!(null),
                    json!(null),
                    json!(null),
                    json!(round(m.seconds)),
                    json!(format!("failed: {e}")),
                ]),
            }
        }
        s.tables.push(Table {
            id: "presorted-figure5".into(),
            title: format!(
                "Figure 5 analogue: duplication and segment size against partitions ({name})"
            ),
            caption: format!(
                "{name}, partitions 4, 6, 16 and 64 (faces of the bounding polyhedron), \
                 {} threads; seconds of preprocessing.",
                cfg.threads
            ),
            columns: [
                "mesh",
                "triangles",
                "partitions",
                "instances",
                "duplication ratio",
                "average segment",
                "seconds",
                "outcome",
            ]
            .iter()
            .map(|c| c.to_string())
            .collect(),
            rows,
            command: cfg.command(Paper::Presorted),
        });
        if !ratio.is_empty() {
            s.figures.push(Figure {
                id: "presorted-figure5".into(),
                caption: format!(
                    "Duplication ratio and average segment size of {name} against the number \
                     of partitions (the paper's Figure 5)."
                ),
                plot: LinePlot::new(
                    &format!("Duplication and segment size against partitions ({name})"),
                    "viewpoint partitions (faces of the bounding polyhedron)",
                    "ratio to the input triangles",
                    vec![
                        Series {
                            name: "duplication ratio".into(),
                            points: ratio,
                        },
                        Series {
                            name: "average segment".into(),
                            points: segment,
                        },
                    ],
                )
                .into(),
                command: cfg.command(Paper::Presorted),
            });
        }
    }
    // Figure 6: time against triangles at the default partitions.
    let mut rows = Vec::new();
    let mut time = Vec::new();
    for (name, mesh) in &sized {
        progress.step(&format!(
            "presorted: {name}, {TIME_PARTITIONS} partitions, timed"
        ));
        let m = measure(mesh, TIME_PARTITIONS, cfg.threads);
        let outcome = match &m.result {
            Ok(r) => {
                time.push((m.triangles as f64, m.seconds));
                format!(
                    "{} instances, duplication ratio {:.3}",
                    r.total_instances(),
                    r.duplication_ratio()
                )
            }
            Err(e) => format!("failed: {e}"),
        };
        rows.push(vec![
            json!(name),
            json!(m.triangles),
            json!(cfg.threads),
            json!(round(m.seconds)),
            json!(outcome),
        ]);
    }
    s.tables.push(Table {
        id: "presorted-figure6".into(),
        title: "Figure 6 analogue: preprocessing time against triangles".into(),
        caption: format!(
            "{TIME_PARTITIONS} partitions, {} threads (one partition per task).",
            cfg.threads
        ),
        columns: ["mesh", "triangles", "threads", "seconds", "outcome"]
            .iter()
            .map(|c| c.to_string())
            .collect(),
        rows,
        command: cfg.command(Paper::Presorted),
    });
    if !time.is_empty() {
        s.figures.push(Figure {
            id: "presorted-figure6".into(),
            caption: format!(
                "Preprocessing time against the input triangles, {TIME_PARTITIONS} partitions, \
                 {} threads (the paper's Figure 6).",
                cfg.threads
            ),
            plot: LinePlot::new(
                "Preprocessing time against triangles",
                "input triangles",
                "preprocessing time (s)",
                vec![Series {
                    name: format!("{TIME_PARTITIONS} partitions"),
                    points: time,
                }],
            )
            .into(),
            command: cfg.command(Paper::Presorted),
        });
    }
    Ok(s)
}
