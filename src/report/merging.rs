//! "Z-Thickness Blending: Effective Fragment Merging for Multi-Fragment Rendering": the
//! resolved image's error and PSNR against k, with merging (the paper's 2 P(z) thickness)
//! and without it (a thickness too thin to merge anything), measured on the merging
//! k-buffer (`skb-ofm`).

use fragrace_kernels::merging::{MergeParams, Thickness};

use super::{ctx, Figure, Paper, PaperConfig, Picture, Progress, ReportError, Section};
use crate::plot::{LinePlot, Series};
use crate::run::{self, RunSpec, SceneSpec};

/// The merging algorithm.
pub const ALGO: &str = "skb-ofm";
/// The thickness of the runs without merging: far below the gap between any two of the
/// scene's surfaces, so that no two fragments merge.
pub const NO_MERGE: f32 = 1e-7;
/// A thickness wide enough to merge the close surfaces of `hairball`.
pub const WIDE: f32 = 0.02;

/// The section.
pub fn section(cfg: &PaperConfig, progress: &dyn Progress) -> Result<Section, ReportError> {
    let (size, scene) = if cfg.quick {
        (96, "hairball")
    } else {
        (256, "hairball")
    };
    let mut base = RunSpec::new(SceneSpec::Builtin(scene.into()), ALGO);
    base.width = size;
    base.height = size;
    base.exec.mode = fragrace_emu::ExecMode::Ordered;
    let loaded = ctx(run::load(&base), || scene.to_string())?;
    let truth = ctx(run::truth(&base, &loaded), || format!("{scene}: the truth"))?;
    let thick = |thickness| MergeParams {
        thickness,
        beta: 0.0,
    };
    let modes = [
        (
            "without merging (thickness 1e-7)",
            thick(Thickness::Fixed(NO_MERGE)),
        ),
        ("thickness 2 P(z) (the paper's)", MergeParams::default()),
        ("thickness 0.02 (view depth)", thick(Thickness::Fixed(WIDE))),
    ];
    let mut psnr: Vec<Series> = modes
        .iter()
        .map(|(n, _)| Series {
            name: n.to_string(),
            points: Vec::new(),
        })
        .collect();
    let mut error = psnr.clone();
    let mut infinite = Vec::new();
    for k in [2u32, 4, 8, 16] {
        for (i, (name, merge)) in modes.iter().enumerate() {
            progress.step(&format!("merging: k = {k}, {name}"));
            let mut s = base.clone();
            s.params.k = k;
            s.params.merge = *merge;
            let c = ctx(run::check_with(&s, &loaded, &truth), || {
                format!("{ALGO}, k = {k}, {name}")
            })?;
            let Some(im) = &c.metrics.image else { continue };
            error[i].points.push((f64::from(k), im.image_epr));
            if im.psnr.is_finite() {
                psnr[i].points.push((f64::from(k), im.psnr));
            } else {
                infinite.push(format!("k = {k} {name}"));
            }
        }
    }
    let mut s = Section::new(Paper::Merging, "Fragment merging: image error against k");
    s.text.push(format!(
        "{ALGO} on {scene} ({size}x{size}, ordered executor) against the exact front-to-back \
         composite of every fragment: image error (covered pixels off by more than 1/255) \
         and PSNR, without merging and with two thicknesses. Merging aims at robustness under \
         z-fighting, not at the exact composite: a wider thickness merges more fragments, \
         and the image differs more from the exact one."
    ));
    if error[0].points == error[1].points && psnr[0].points == psnr[1].points {
        s.text.push(
            "The paper's 2 P(z) thickness merged nothing here: its lines lie on those without \
             merging."
                .into(),
        );
    }
    if !infinite.is_empty() {
        s.text.push(format!(
            "Identical to the exact composite (infinite PSNR, not drawn): {}.",
            infinite.join(", ")
        ));
    }
    figure3(cfg, progress, &mut s)?;
    s.figures.push(Figure {
        id: "merging-image-error".into(),
        caption: "Image error pixel rate against k, with and without merging.".into(),
        plot: LinePlot::new(
            &format!("Image error against k ({ALGO}, {scene}, {size}x{size})"),
            "k (records per pixel)",
            "image error pixel rate (fraction of covered pixels)",
            error,
        )
        .into(),
        command: cfg.command(Paper::Merging),
    });
    s.figures.push(Figure {
        id: "merging-psnr".into(),
        caption: "PSNR of the resolved image against k, with and without merging.".into(),
        plot: LinePlot::new(
            &format!("PSNR against k ({ALGO}, {scene}, {size}x{size})"),
            "k (records per pixel)",
            "PSNR (dB, peak 1)",
            psnr,
        )
        .into(),
        command: cfg.command(Paper::Merging),
    });
    Ok(s)
}

/// The Figure 3 analogue: z-fighting surfaces (`interpenetrating`: two boxes on the same
/// planes and two spheres of one radius tessellated differently), the exact composite next
/// to the merging k-buffer without merging and with two thicknesses, as one image strip.
fn figure3(cfg: &PaperConfig, progress: &dyn Progress, s: &mut Section) -> Result<(), ReportError> {
    use crate::render::{image, picture, run as pictures, Look, Overrides, Shade};
    progress.step("merging: Figure 3, the z-fighting strip");
    let (size, scene) = (if cfg.quick { 128 } else { 256 }, "interpenetrating");
    let mut base = RunSpec::new(SceneSpec::Builtin(scene.into()), ALGO);
    base.width = size;
    base.height = size;
    base.camera = crate::scene::Camera::new(30.0, 20.0);
    base.exec.mode = fragrace_emu::ExecMode::Ordered;
    let loaded = ctx(run::load(&base), || scene.to_string())?;
    let truth = ctx(run::truth(&base, &loaded), || format!("{scene}: the truth"))?;
    let render_err = ReportError::Render;
    let surface = pictures::surface(&loaded, &Overrides::default()).map_err(render_err)?;
    let view = pictures::view(&base, &loaded, &surface);
    let look = Look {
        shade: Shade::Id,
        ..Look::default()
    };
    let exact = image(&base.algo, &truth, &view, &look)
        .map_err(render_err)?
        .0;
    let mut panels = vec![(
        "the exact composite".to_string(),
        picture::Canvas::from_rgba(size, size, &exact),
    )];
    // Under each image, where it differs from the exact composite by more than 1/255.
    let mut diffs = vec![(
        "below: pixels off the exact composite by more than 1/255".to_string(),
        picture::Canvas::new(size, size, [255, 255, 255]),
    )];
    let thick = |thickness| MergeParams {
        thickness,
        beta: 0.0,
    };
    for (title, merge) in [
        (
            "no merging (thickness 1e-7)",
            thick(Thickness::Fixed(NO_MERGE)),
        ),
        ("thickness 2 P(z)", MergeParams::default()),
        ("thickness 0.02", thick(Thickness::Fixed(WIDE))),
    ] {
        let mut sp = base.clone();
        sp.params.merge = merge;
        let c = ctx(run::check_with(&sp, &loaded, &truth), || {
            format!("{ALGO}, {title}")
        })?;
        let rgba = image(&sp.algo, &c.rendered.result, &view, &look)
            .map_err(render_err)?
            .0;
        let off: Vec<bool> = exact
            .iter()
            .zip(&rgba)
            .map(|(a, b)| (0..3).any(|ch| (a[ch] - b[ch]).abs() > 1.0 / 255.0))
            .collect();
        let epr = c
            .metrics
            .image
            .as_ref()
            .map_or(c.metrics.epr, |i| i.image_epr);
        panels.push((
            format!("{ALGO}, {title}: image EPR {epr:.3}"),
            picture::Canvas::from_rgba(size, size, &rgba),
        ));
        diffs.push((
            format!("{} pixels off", off.iter().filter(|&&o| o).count()),
            picture::difference(size, size, &exact, &rgba, &off),
        ));
    }
    let row = |list: &[(String, picture::Canvas)]| {
        picture::panels(
            &list
                .iter()
                .map(|(title, image)| picture::Panel {
                    title,
                    image: image.clone(),
                })
                .collect::<Vec<_>>(),
        )
    };
    let (top, bottom) = (row(&panels), row(&diffs));
    let mut strip = picture::Canvas::new(
        top.width.max(bottom.width),
        top.height + bottom.height,
        [255, 255, 255],
    );
    strip.blit(&top, 0, 0);
    strip.blit(&bottom, 0, top.height);
    let id = "merging-figure3-strip";
    let path = cfg.out.join(format!("{id}.png"));
    strip
        .write_png(&path)
        .map_err(|source| ReportError::Io { path, source })?;
    s.pictures.push(Picture {
        id: id.into(),
        title: "Figure 3 analogue: z-fighting with and without merging".into(),
        caption: format!(
            "{scene} ({size}x{size}, k = {k}, ordered executor): two boxes on the same six \
             planes, split along opposite diagonals, and two spheres of one radius \
             tessellated differently, so their fragments tie or differ by a rounding step. \
             Without merging the k-buffer keeps whichever of the tied fragments rounding \
             puts first: the speckle of z-fighting. A thickness wider than the gaps merges \
             them into one blended layer (the paper's Figure 3, right). The second row marks \
             the pixels of each image off the exact composite by more than 1/255 (brighter: \
             a larger difference).",
            k = base.params.k
        ),
        command: cfg.command(Paper::Merging),
    });
    Ok(())
}
