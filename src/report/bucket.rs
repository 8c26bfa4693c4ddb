//! "Efficient Depth Peeling via Bucket Sort": Table 2 (geometry passes per algorithm per
//! mesh) and Figure 6 (the error pixel rate over views of one mesh), measured.

use serde_json::json;

use super::{ctx, mesh_name, Figure, Paper, PaperConfig, Progress, ReportError, Section, Table};
use crate::plot::{LinePlot, Series};
use crate::run::{self, RunSpec, SceneSpec};
use crate::scene::Camera;

/// The multi-pass algorithms whose passes Table 2 counts: the bucket schemes, the peelers
/// and the multipass k-buffer.
pub fn table2_algorithms() -> Vec<&'static str> {
    fragrace_kernels::algorithms()
        .iter()
        .map(|a| a.info())
        .filter(|i| {
            i.family == "bucket depth peeling"
                || i.family == "depth peeling"
                || i.name == "kb-multipass"
        })
        .map(|i| i.name)
        .collect()
}

/// The algorithms of Figure 6: the bucket schemes and the single-pass k-buffer they are
/// compared with.
pub const FIGURE6: [&str; 4] = ["bdp", "bdp2", "adp", "kb-rmw"];

/// The scenes of the section: built-in names (quick) or the meshes' paths.
fn scenes(cfg: &PaperConfig) -> Result<Vec<(String, SceneSpec)>, ReportError> {
    if cfg.quick {
        return Ok(["bunny", "teapot", "hairball"]
            .iter()
            .map(|n| (n.to_string(), SceneSpec::Builtin(n.to_string())))
            .collect());
    }
    Ok(cfg
        .meshes()?
        .into_iter()
        .map(|p| {
            (
                mesh_name(&p),
                SceneSpec::Obj {
                    path: p,
                    sha256: None,
                },
            )
        })
        .collect())
}

fn spec(scene: &SceneSpec, size: u32, k: u32, threads: usize) -> RunSpec {
    let mut s = RunSpec::new(scene.clone(), "truth");
    s.width = size;
    s.height = size;
    s.params.k = k;
    s.exec.mode = fragrace_emu::ExecMode::Parallel;
    s.exec.threads = threads;
    s
}

/// The section.
pub fn section(cfg: &PaperConfig, progress: &dyn Progress) -> Result<Section, ReportError> {
    let (size, views, k) = if cfg.quick { (96, 8, 8) } else { (512, 200, 8) };
    let scenes = scenes(cfg)?;
    let mut s = Section::new(Paper::Bucket, "Bucket depth peeling: Table 2 and Figure 6");
    // Table 2.
    let algos = table2_algorithms();
    let mut columns = vec!["algorithm".to_string()];
    columns.extend(scenes.iter().map(|(n, _)| n.clone()));
    let mut rows: Vec<Vec<serde_json::Value>> = algos.iter().map(|a| vec![json!(a)]).collect();
    for (name, scene) in &scenes {
        let base = spec(scene, size, k, cfg.threads);
        let loaded = ctx(run::load(&base), || name.clone())?;
        for (row, algo) in rows.iter_mut().zip(&algos) {
            progress.step(&format!("bucket: Table 2, {algo} on {name}"));
            let mut sp = base.clone();
            sp.algo = algo.to_string();
            let r = ctx(run::render(&sp, &loaded), || format!("{algo} on {name}"))?;
            row.push(json!(r.result.report.stats.geometry_passes));
        }
    }
    s.text.push(format!(
        "Table 2: geometry passes of one frame ({size}x{size}, k = {k}, the default camera) per \
         multi-pass algorithm and mesh; the peelers' count grows with the depth complexity, \
         the bucket schemes' stays constant (adp: one routing pass per 32 layers)."
    ));
    s.tables.push(Table {
        id: "table2-geometry-passes".into(),
        title: "Table 2: geometry passes per algorithm per mesh".into(),
        caption: format!("{size}x{size}, k = {k}, parallel executor."),
        columns,
        rows,
        command: cfg.command(Paper::Bucket),
    });
    // Figure 6: EPR over views of one mesh (the dragon when given).
    let (name, scene) = scenes
        .iter()
        .find(|(n, _)| n.contains("dragon"))
        .or(scenes.first())
        .cloned()
        .ok_or(ReportError::NoModels(
            cfg.models.clone().unwrap_or_default(),
        ))?;
    let mut series: Vec<Series> = FIGURE6
        .iter()
        .map(|a| Series {
            name: a.to_string(),
            points: Vec::new(),
        })
        .collect();
    // The mesh is read once; each view only changes the camera.
    let mut loaded = ctx(run::load(&spec(&scene, size, k, cfg.threads)), || {
        name.clone()
    })?;
    for v in 0..views {
        let azimuth = 360.0 * v as f32 / views as f32;
        progress.step(&format!("bucket: Figure 6, view {} of {views}", v + 1));
        let mut base = spec(&scene, size, k, cfg.threads);
        base.camera = Camera::new(azimuth, 0.0);
        loaded.view_proj = loaded.scene.view_proj(&base.camera, size, size);
        let truth = ctx(run::truth(&base, &loaded), || format!("{name}: the truth"))?;
        for (line, algo) in series.iter_mut().zip(FIGURE6) {
            let mut sp = base.clone();
            sp.algo = algo.to_string();
            let c = ctx(run::check_with(&sp, &loaded, &truth), || {
                format!("{algo} on {name}, azimuth {azimuth}")
            })?;
            line.points.push((f64::from(azimuth), c.metrics.epr));
        }
    }
    let mut plot = LinePlot::new(
        &format!(
            "Figure 6: error pixel rate over {views} views of {name} ({size}x{size}, k = {k})"
        ),
        "azimuth (degrees)",
        "error pixel rate (EPR, fraction of covered pixels)",
        series,
    );
    plot.size = (1000, 560);
    s.figures.push(Figure {
        id: "figure6-epr-views".into(),
        caption: format!(
            "EPR of the bucket schemes and the k-buffer over {views} azimuths of {name}: a pixel \
             is an error when its k nearest depths differ from the truth's."
        ),
        plot: plot.into(),
        command: cfg.command(Paper::Bucket),
    });
    Ok(s)
}
