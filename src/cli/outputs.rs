//! Files a run writes: checked before the computation, named when written.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use fragrace::run::{self, RunSpec};

use crate::RunArgs;

/// Checks that the outputs asked for can be written, before any computation.
pub(crate) fn check_outputs(a: &RunArgs, algo: &str) -> Result<()> {
    use fragrace::output::{check_dir, check_writable};
    if let Some(p) = &a.out {
        check_writable(p, "the image (--out)")?;
    }
    if let Some(p) = &a.raw_out {
        if !matches!(algo, "count" | "count-plain") {
            bail!("--raw-out needs a counting algorithm (count, count-plain), not `{algo}`");
        }
        check_writable(p, "the counts (--raw-out)")?;
    }
    if let Some(d) = &a.heatmap {
        check_dir(d, "heatmaps (--heatmap)")?;
    }
    Ok(())
}

/// Writes the outputs asked for; returns the files written.
pub(crate) fn write_outputs(
    a: &RunArgs,
    spec: &RunSpec,
    r: &run::Rendered,
    checked: Option<&run::Checked>,
) -> Result<Vec<PathBuf>> {
    let res = &r.result;
    let mut written = Vec::new();
    let named = |p: &Path| format!("{}: cannot write", p.display());
    if let Some(path) = &a.out {
        if let Some(img) = &res.image {
            fragrace::output::write_rgba(path, spec.width, spec.height, img)
                .with_context(|| named(path))?;
        } else if let Some(c) = &res.counts {
            fragrace::output::write_heatmap(path, spec.width, spec.height, c)
                .with_context(|| named(path))?;
        } else {
            bail!("algorithm `{}` produces no image", spec.algo);
        }
        written.push(path.clone());
    }
    if let Some(path) = &a.raw_out {
        let Some(c) = &res.counts else {
            bail!("--raw-out needs a counting algorithm (count, count-plain)")
        };
        let bytes: Vec<u8> = c.iter().flat_map(|v| v.to_le_bytes()).collect();
        fragrace::output::write_atomic(path, &bytes).with_context(|| named(path))?;
        written.push(path.clone());
    }
    if let Some(dir) = &a.heatmap {
        std::fs::create_dir_all(dir).with_context(|| named(dir))?;
        let mut heat = |name: &str, values: &[u32]| -> Result<()> {
            let p = dir.join(name);
            fragrace::output::write_heatmap(&p, spec.width, spec.height, values)
                .with_context(|| named(&p))?;
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
    Ok(written)
}

/// Lists the files written (on stderr under --json, to keep stdout one JSON object).
pub(crate) fn list_written(written: &[PathBuf], json: bool) {
    for p in written {
        if json {
            eprintln!("wrote {}", p.display());
        } else {
            println!("  wrote {}", p.display());
        }
    }
}
