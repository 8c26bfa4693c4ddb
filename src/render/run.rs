//! Pictures of runs: what `render` and `check` write with `--out` and `--turntable`.

use fragrace_kernels::{AlgoResult, Capacity};

use super::picture::{self, Canvas};
use super::{image, Look, Overrides, RenderError, Shade, ShadeStats, View};
use crate::run::{Checked, Loaded, RunSpec};
use crate::scene::Surface;

/// The shading `render` uses when none is asked for: [`Shade::Lit`] for the algorithms that
/// keep fragments, [`Shade::Id`] (their own composite) for those that keep an image only.
pub fn default_shade(capacity: Capacity) -> Shade {
    match capacity {
        Capacity::Image => Shade::Id,
        _ => Shade::Lit,
    }
}

/// The scene's surface with `--color` / `--opacity` applied.
pub fn surface(loaded: &Loaded, overrides: &Overrides) -> Result<Surface, RenderError> {
    let scene = &loaded.scene;
    let mut s = scene.surface().into_owned();
    overrides.apply(&mut s, &scene.objects, scene.mesh.indices.len() as u32)?;
    Ok(s)
}

/// The view of a loaded run.
pub fn view<'a>(spec: &RunSpec, loaded: &'a Loaded, surface: &'a Surface) -> View<'a> {
    View {
        scene: &loaded.scene,
        surface,
        view_proj: loaded.view_proj,
        width: spec.width,
        height: spec.height,
        alpha: spec.params.alpha,
    }
}

/// The picture of one result: the depth-complexity image with its legend for counting
/// algorithms, the shaded image otherwise.
pub fn picture(
    spec: &RunSpec,
    view: &View<'_>,
    result: &AlgoResult,
    look: &Look,
) -> Result<(Canvas, ShadeStats), RenderError> {
    if let (Some(c), None) = (&result.counts, &result.capture) {
        return Ok((
            picture::depth_complexity(spec.width, spec.height, c),
            ShadeStats::default(),
        ));
    }
    let (img, stats) = image(&spec.algo, result, view, look)?;
    Ok((Canvas::from_rgba(spec.width, spec.height, &img), stats))
}

/// `check`'s three panels for a checked run: the truth's image, the algorithm's (both shaded
/// by `look`) and the difference at the oracle's error pixels, titled.
pub fn compare(
    spec: &RunSpec,
    view: &View<'_>,
    checked: &Checked,
    truth: &AlgoResult,
    look: &Look,
) -> Result<Canvas, RenderError> {
    let result = &checked.rendered.result;
    let (t, a) = match (&result.counts, &result.capture, &truth.counts) {
        // Counting algorithms: the depth complexities, on one colour scale.
        (Some(mine), None, Some(want)) => {
            let max = want.iter().chain(mine.iter()).copied().max().unwrap_or(0);
            let rgba = |c: &[u32]| -> Vec<[f32; 4]> {
                c.iter()
                    .map(|&n| {
                        let [r, g, b] = picture::count_color(n, max).map(|v| f32::from(v) / 255.0);
                        [r, g, b, 1.0]
                    })
                    .collect()
            };
            (rgba(want), rgba(mine))
        }
        _ => (
            image("truth", truth, view, look)?.0,
            image(&spec.algo, result, view, look)?.0,
        ),
    };
    let run = match spec.schedule() {
        Some(s) => format!("{}, {} seed {}", spec.algo, s.policy, s.seed),
        None => format!("{}, {}", spec.algo, spec.exec.mode.name()),
    };
    let errors = checked.metrics.error_pixels;
    let diff = format!(
        "difference: {errors} error pixel{}",
        if errors == 1 { "" } else { "s" }
    );
    Ok(picture::compare(
        spec.width,
        spec.height,
        &t,
        &a,
        &checked.metrics.error_mask,
        ["truth (A-buffer)", &run, &diff],
    ))
}
