//! Files a run writes: checked before the computation, named when written.

use std::path::{Path, PathBuf};

use fragrace_kernels::AlgoResult;

use super::error::{CliError, OptionError};
use super::options::RunOptions;
use crate::render::{self, Look, Overrides, RenderError, Shade};
use crate::run::{self, RunSpec};

/// The renderer's settings of the command line; `default` when `--shade` is not given.
pub fn look_of(a: &RunOptions, default: Shade) -> Result<Look, RenderError> {
    let look = Look {
        shade: a.shade.unwrap_or(default),
        sigma: a.sigma,
        ..Look::default()
    };
    look.validate()?;
    Ok(look)
}

/// `--color` and `--opacity`.
pub fn overrides_of(a: &RunOptions) -> Overrides {
    Overrides {
        colors: a.color.clone(),
        opacities: a.opacity.clone(),
    }
}

/// Prints what loading the scene left out (unusable normals, missing or malformed MTL files).
pub fn warn_scene(loaded: &run::Loaded) {
    if let Some(s) = &loaded.scene.surface {
        for w in &s.warnings {
            eprintln!("warning: {w}");
        }
    }
}

/// What `--out` wrote, for the summary: the shading and the time it took to make the
/// picture (shading, compositing, legends; not writing the file) in milliseconds.
#[derive(Clone, Debug, Default)]
pub struct Written {
    pub files: Vec<PathBuf>,
    pub shade: Option<&'static str>,
    pub picture_ms: Option<f64>,
}

/// `--out` of `render` (`truth: None`) or of `check` (the three panels): the picture of this
/// run, or with `--turntable N` of N views around the scene (each view run again).
fn write_picture(
    a: &RunOptions,
    spec: &RunSpec,
    loaded: &run::Loaded,
    r: &run::Rendered,
    checked: Option<(&run::Checked, &AlgoResult)>,
    path: &Path,
    out: &mut Written,
) -> Result<(), CliError> {
    let default = match checked {
        Some(_) => Shade::Id,
        None => render::run::default_shade(r.info.capacity),
    };
    let look = look_of(a, default)?;
    out.shade = Some(look.shade.name());
    let surface = render::run::surface(loaded, &overrides_of(a))?;
    let picture = |spec: &RunSpec,
                   loaded: &run::Loaded,
                   r: &AlgoResult,
                   checked: Option<(&run::Checked, &AlgoResult)>|
     -> Result<render::picture::Canvas, CliError> {
        let view = render::run::view(spec, loaded, &surface);
        Ok(match checked {
            Some((c, truth)) => render::run::compare(spec, &view, c, truth, &look)?,
            None => {
                let (canvas, stats) = render::run::picture(spec, &view, r, &look)?;
                if stats.without_primitive > 0 {
                    eprintln!(
                        "note: {} of {} fragments have no primitive id ({} keeps depths only): shaded with the first material, facing the eye",
                        stats.without_primitive, stats.fragments, spec.algo
                    );
                }
                canvas
            }
        })
    };
    let Some(n) = a.turntable else {
        let t = std::time::Instant::now();
        let canvas = picture(spec, loaded, &r.result, checked)?;
        out.picture_ms = Some(t.elapsed().as_secs_f64() * 1e3);
        canvas.write_png(path).map_err(CliError::write(path))?;
        out.files.push(path.to_path_buf());
        return Ok(());
    };
    let mut frames = Vec::with_capacity(n as usize);
    let mut view_loaded = run::Loaded {
        scene: loaded.scene.clone(),
        view_proj: loaded.view_proj,
    };
    for az in render::turntable::azimuths(spec.camera.azimuth, n) {
        let mut s = spec.clone();
        s.camera.azimuth = az;
        view_loaded.view_proj = view_loaded.scene.view_proj(&s.camera, s.width, s.height);
        let frame = match checked {
            Some(_) => {
                let truth = run::truth(&s, &view_loaded)?;
                let c = run::check_with(&s, &view_loaded, &truth)?;
                picture(&s, &view_loaded, &c.rendered.result, Some((&c, &truth)))?
            }
            None => {
                let r = run::render(&s, &view_loaded)?;
                picture(&s, &view_loaded, &r.result, None)?
            }
        };
        frames.push(frame);
    }
    out.files
        .extend(render::turntable::write(path, &frames, 100)?);
    Ok(())
}

/// Checks that the outputs asked for can be written, before any computation.
pub fn check_outputs(a: &RunOptions, algo: &str) -> Result<(), CliError> {
    use crate::output::{check_dir, check_writable};
    if let Some(p) = &a.out {
        check_writable(p, "the image (--out)")?;
    }
    if a.out.is_none() && (a.shade.is_some() || !a.color.is_empty() || !a.opacity.is_empty()) {
        return Err(OptionError::PictureWithoutOut.into());
    }
    // The renderer's settings, before any computation (the shading mode's default does not
    // matter here).
    look_of(a, Shade::Lit)?;
    overrides_of(a).validate()?;
    if a.turntable == Some(0) {
        return Err(OptionError::TurntableZero.into());
    }
    if let Some(p) = &a.raw_out {
        if !matches!(algo, "count" | "count-plain") {
            return Err(OptionError::RawOutNotCounting {
                algo: algo.to_string(),
            }
            .into());
        }
        check_writable(p, "the counts (--raw-out)")?;
    }
    if let Some(d) = &a.heatmap {
        check_dir(d, "heatmaps (--heatmap)")?;
    }
    Ok(())
}

/// Writes the outputs asked for; returns the files written.
pub fn write_outputs(
    a: &RunOptions,
    spec: &RunSpec,
    loaded: &run::Loaded,
    r: &run::Rendered,
    checked: Option<(&run::Checked, &AlgoResult)>,
) -> Result<Written, CliError> {
    let res = &r.result;
    let mut out = Written::default();
    if let Some(path) = &a.out {
        write_picture(a, spec, loaded, r, checked, path, &mut out)?;
    }
    let mut written = std::mem::take(&mut out.files);
    let checked = checked.map(|(c, _)| c);
    if let Some(path) = &a.raw_out {
        let Some(c) = &res.counts else {
            return Err(OptionError::RawOutWithoutCounts.into());
        };
        let bytes: Vec<u8> = c.iter().flat_map(|v| v.to_le_bytes()).collect();
        crate::output::write_atomic(path, &bytes).map_err(CliError::write(path))?;
        written.push(path.clone());
    }
    if let Some(dir) = &a.heatmap {
        std::fs::create_dir_all(dir).map_err(CliError::write(dir))?;
        let mut heat = |name: &str, values: &[u32]| -> Result<(), CliError> {
            let p = dir.join(name);
            crate::output::write_heatmap(&p, spec.width, spec.height, values)
                .map_err(CliError::write(&p))?;
            written.push(p);
            Ok(())
        };
        if let Some(c) = &res.counts {
            heat("depth-complexity.png", c)?;
        }
        if let Some(c) = &res.collisions {
            // Bucket schemes: fragments that lost their bucket, per pixel.
            heat("collisions.png", c)?;
        }
        if !res.report.hazard_heat.is_empty() {
            heat("hazards.png", &res.report.hazard_heat)?;
        }
        if let Some(c) = checked {
            let errs: Vec<u32> = c.metrics.error_mask.iter().map(|&e| e as u32).collect();
            heat("errors.png", &errs)?;
            if !c.metrics.culled_heat.is_empty() {
                heat("culled.png", &c.metrics.culled_heat)?;
            }
            // The image against the truth's composite, in 8-bit steps of the largest
            // channel difference (the heatmap scales to its maximum).
            if let Some(im) = &c.metrics.image {
                let steps: Vec<u32> = im
                    .diff
                    .iter()
                    .map(|&d| (d.min(1.0) * 255.0).round() as u32)
                    .collect();
                heat("image-diff.png", &steps)?;
            }
        }
        if !written.iter().any(|p| p.starts_with(dir)) {
            eprintln!(
                "note: --heatmap {}: no heatmap written. Depth complexity comes from counting algorithms (count, count-plain), hazards from the scheduled executor, errors from `check`; `{}` under `{}` with `{}` has none of them.",
                dir.display(),
                spec.algo,
                spec.exec.mode.name(),
                if checked.is_some() { "check" } else { "render" }
            );
        }
    }
    out.files = written;
    Ok(out)
}

/// Lists the files written (on stderr under --json, to keep stdout one JSON object).
pub fn list_written(written: &[PathBuf], json: bool) {
    for p in written {
        if json {
            eprintln!("wrote {}", p.display());
        } else {
            println!("  wrote {}", p.display());
        }
    }
}
