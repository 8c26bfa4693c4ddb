//! "Improving k-buffer methods via occupancy maps": the fraction of fragments the occupancy
//! map culls against its words per pixel d and k, and the k-buffer's invocations against k
//! with and without culling (analogues of the paper's Figures 4 and 5), measured on the
//! k+-buffer.

use super::{ctx, mesh_name, Figure, Paper, PaperConfig, Progress, ReportError, Section};
use crate::plot::{LinePlot, Series};
use crate::run::{self, RunSpec, SceneSpec};
use fragrace_kernels::occupancy::Occupancy;

/// The culled algorithm.
pub const ALGO: &str = "kplus";

/// The scenes of the section: hairball (the paper's case: high depth complexity, where
/// culling pays), and in the full report also the dragon of `--models` (or its first mesh),
/// where few pixels hold more than k fragments and little is culled.
fn scenes(cfg: &PaperConfig) -> Result<Vec<(String, SceneSpec)>, ReportError> {
    let mut out = vec![(
        "hairball".to_string(),
        SceneSpec::Builtin("hairball".into()),
    )];
    if cfg.quick {
        return Ok(out);
    }
    let meshes = cfg.meshes()?;
    let p = meshes
        .iter()
        .find(|p| mesh_name(p).contains("dragon"))
        .or(meshes.first())
        .cloned()
        .ok_or_else(|| ReportError::NoModels(cfg.models.clone().unwrap_or_default()))?;
    out.push((
        mesh_name(&p),
        SceneSpec::Obj {
            path: p,
            sha256: None,
        },
    ));
    Ok(out)
}

/// One culled run: (culled fraction, k-buffer invocations with, without).
pub fn culled(
    base: &RunSpec,
    loaded: &run::Loaded,
    k: u32,
    d: u32,
) -> Result<(f64, f64, f64), ReportError> {
    let mut s = base.clone();
    s.params.k = k;
    s.params.occupancy = Some(Occupancy {
        d,
        range: Default::default(),
        fill: Default::default(),
    });
    let what = || format!("{ALGO} with --occupancy {d}, k = {k}");
    let with = ctx(run::render(&s, loaded), what)?;
    let without = ctx(crate::culling::baseline(&s, loaded), what)?;
    let v = crate::culling::summary(&with, None, without.as_ref());
    let f = |x: &serde_json::Value| x.as_f64().unwrap_or(f64::NAN);
    Ok((
        f(&v["culled_fraction"]),
        f(&v["with"]["kbuffer_invocations"]),
        f(&v["without"]["kbuffer_invocations"]),
    ))
}

/// The section.
pub fn section(cfg: &PaperConfig, progress: &dyn Progress) -> Result<Section, ReportError> {
    let mut s = Section::new(Paper::Occupancy, "Occupancy maps: culling against d and k");
    for (i, (name, scene)) in scenes(cfg)?.into_iter().enumerate() {
        // The first scene keeps the figures' plain ids; the others get their name.
        let suffix = if i == 0 {
            String::new()
        } else {
            format!("-{name}")
        };
        scene_figures(cfg, progress, &mut s, &name, scene, &suffix)?;
    }
    Ok(s)
}

/// Figures 4 and 5 on one scene.
fn scene_figures(
    cfg: &PaperConfig,
    progress: &dyn Progress,
    s: &mut Section,
    name: &str,
    scene: SceneSpec,
    suffix: &str,
) -> Result<(), ReportError> {
    let size = if cfg.quick { 96 } else { 512 };
    let mut base = RunSpec::new(scene, ALGO);
    base.width = size;
    base.height = size;
    base.exec.mode = fragrace_emu::ExecMode::Parallel;
    base.exec.threads = cfg.threads;
    let loaded = ctx(run::load(&base), || name.to_string())?;
    s.text.push(format!(
        "{ALGO} on {name} ({size}x{size}) with occupancy culling (--occupancy d: 32 d depth \
         sub-intervals per pixel, the exact depth range, atomic fill). Culled fraction: \
         fragments the peel pass's early test rejects over the fragments it rasterizes. \
         Invocations: k-buffer (fragment shader) invocations of the capture passes, with \
         culling and without (the same run with --occupancy left out)."
    ));
    let ds = [1u32, 2, 4, 8];
    let ks = [4u32, 8, 16, 32];
    let mut fig4 = Vec::new();
    for &k in &ks[..3] {
        let mut points = Vec::new();
        for &d in &ds {
            progress.step(&format!("occupancy: Figure 4, {name}, k = {k}, d = {d}"));
            points.push((f64::from(d), culled(&base, &loaded, k, d)?.0));
        }
        fig4.push(Series {
            name: format!("k = {k}"),
            points,
        });
    }
    s.figures.push(Figure {
        id: format!("figure4-culled-fraction{suffix}"),
        caption: format!("Fraction of the rasterized fragments culled by the occupancy map against d, one line per k ({name})."),
        plot: LinePlot::new(
            &format!("Culled fraction against d ({ALGO}, {name}, {size}x{size})"),
            "d (map words per pixel; 32 d sub-intervals)",
            "culled fraction (culled / rasterized fragments)",
            fig4,
        ).into(),
        command: cfg.command(Paper::Occupancy),
    });
    let mut without = Series {
        name: "without culling".into(),
        points: Vec::new(),
    };
    let mut with: Vec<Series> = [1u32, 4]
        .iter()
        .map(|d| Series {
            name: format!("with culling, d = {d}"),
            points: Vec::new(),
        })
        .collect();
    for &k in &ks {
        for (line, d) in with.iter_mut().zip([1u32, 4]) {
            progress.step(&format!("occupancy: Figure 5, {name}, k = {k}, d = {d}"));
            let (_, w, wo) = culled(&base, &loaded, k, d)?;
            line.points.push((f64::from(k), w));
            if d == 1 {
                without.points.push((f64::from(k), wo));
            }
        }
    }
    let mut series = vec![without];
    series.extend(with);
    s.figures.push(Figure {
        id: format!("figure5-invocations{suffix}"),
        caption: format!("k-buffer invocations against k, without culling and with it ({name})."),
        plot: LinePlot::new(
            &format!("k-buffer invocations against k ({ALGO}, {name}, {size}x{size})"),
            "k (fragments kept per pixel)",
            "k-buffer invocations (fragments shaded)",
            series,
        )
        .into(),
        command: cfg.command(Paper::Occupancy),
    });
    Ok(())
}
