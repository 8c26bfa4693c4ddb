//! The CPU fallback renderer: pictures of what a run kept, shaded.
//!
//! An algorithm run yields, per pixel, the fragments it kept (depth and primitive id) and
//! its own composite of them in the peer's hash colours at a constant opacity. The
//! renderer shades the kept fragments instead ([`shade`]): materials and normals from the
//! scene ([`crate::scene::Surface`]), a headlight, and the bucket paper's translucency and
//! Fresnel effects. [`Shade::Id`] keeps the algorithm's own image (what the oracle and the
//! llvmpipe peer compare). Counting algorithms give a depth-complexity picture with a legend
//! ([`picture::depth_complexity`]); `check` gives the truth, the algorithm and their
//! difference side by side ([`picture::compare`]); [`turntable`] renders views around the
//! scene.

pub mod picture;
pub mod run;
pub mod shade;
pub mod text;
pub mod turntable;

use std::ops::Range;

use fragrace_kernels::AlgoResult;

use crate::scene::{Scene, SceneError, Surface};
pub use shade::{ShadeStats, Shader};

/// How kept fragments become colours.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shade {
    /// The algorithm's own composite: each primitive in the peer's hash colour at the
    /// constant opacity `--alpha` (what the oracle compares).
    Id,
    /// Headlight and ambient, Lambert and Blinn-Phong per fragment, composited with each
    /// material's opacity.
    Lit,
    /// Beer-Lambert absorption through the thickness between sorted layers.
    Translucent,
    /// [`Shade::Translucent`] times each layer's Fresnel (Schlick) transmittance.
    Fresnel,
}

impl Shade {
    pub const ALL: [Shade; 4] = [Shade::Id, Shade::Lit, Shade::Translucent, Shade::Fresnel];

    pub fn name(self) -> &'static str {
        match self {
            Shade::Id => "id",
            Shade::Lit => "lit",
            Shade::Translucent => "translucent",
            Shade::Fresnel => "fresnel",
        }
    }
}

impl std::str::FromStr for Shade {
    type Err = String;
    fn from_str(s: &str) -> Result<Shade, String> {
        Shade::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                format!(
                    "unknown shading `{s}`; one of: {}",
                    Shade::ALL.map(Shade::name).join(", ")
                )
            })
    }
}

/// The renderer's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Look {
    pub shade: Shade,
    /// Absorption coefficient of translucency, per unit of the normalised scene (whose
    /// largest extent is 1); a channel absorbs `sigma (1 - Kd)`.
    pub sigma: f32,
    pub background: [f32; 3],
    /// Share of the colour lit whatever the normal.
    pub ambient: f32,
    /// Strength and exponent of the Blinn-Phong highlight.
    pub specular: f32,
    pub shininess: f32,
}

impl Default for Look {
    fn default() -> Look {
        Look {
            shade: Shade::Lit,
            sigma: 12.0,
            background: [1.0, 1.0, 1.0],
            ambient: 0.25,
            specular: 0.3,
            shininess: 32.0,
        }
    }
}

impl Look {
    /// Refuses settings out of range, named with their range.
    pub fn validate(&self) -> Result<(), RenderError> {
        let bad = |what: &str, v: f32, range: &str| {
            Err(RenderError::Setting(format!(
                "{what} {v} is outside {range}"
            )))
        };
        if !(self.sigma >= 0.0 && self.sigma.is_finite()) {
            return bad("--sigma", self.sigma, "[0, infinity)");
        }
        for (what, v) in [("ambient", self.ambient), ("specular", self.specular)] {
            if !(0.0..=1.0).contains(&v) {
                return bad(what, v, "[0, 1]");
            }
        }
        if !(self.shininess >= 1.0 && self.shininess.is_finite()) {
            return bad("shininess", self.shininess, "[1, infinity)");
        }
        Ok(())
    }
}

/// `--color` and `--opacity`: one value for every object, or one per object in order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Overrides {
    pub colors: Vec<[f32; 3]>,
    pub opacities: Vec<f32>,
}

impl Overrides {
    /// Refuses a colour channel or opacity outside [0, 1], naming it and its range.
    pub fn validate(&self) -> Result<(), RenderError> {
        for (i, c) in self.colors.iter().enumerate() {
            for (v, name) in c.iter().zip(["red", "green", "blue"]) {
                crate::scene::material::check_unit(&format!("--color (value {})", i + 1), name, *v)
                    .map_err(RenderError::Scene)?;
            }
        }
        for (i, a) in self.opacities.iter().enumerate() {
            crate::scene::material::check_unit(
                &format!("--opacity (value {})", i + 1),
                "opacity",
                *a,
            )
            .map_err(RenderError::Scene)?;
        }
        Ok(())
    }

    /// Gives object `i` (a range of `surface`'s triangles; the whole mesh when `objects` is
    /// empty) colour `colors[i]` and opacity `opacities[i]` (or the single value given).
    pub fn apply(
        &self,
        surface: &mut Surface,
        objects: &[Range<u32>],
        triangles: u32,
    ) -> Result<(), RenderError> {
        let whole = std::iter::once(0..triangles).collect::<Vec<_>>();
        let objects = if objects.is_empty() {
            &whole[..]
        } else {
            objects
        };
        for (what, given) in [
            ("--color", self.colors.len()),
            ("--opacity", self.opacities.len()),
        ] {
            if given > 1 && given != objects.len() {
                return Err(RenderError::Setting(format!(
                    "{what} given {given} times for a scene of {} objects: give it once (every object) or once per object",
                    objects.len()
                )));
            }
        }
        self.validate()?;
        if self.colors.is_empty() && self.opacities.is_empty() {
            return Ok(());
        }
        let pick = |v: &[f32], i: usize| v.get(i).or(v.first()).copied();
        for (i, range) in objects.iter().enumerate() {
            let color = self.colors.get(i).or(self.colors.first()).copied();
            let opacity = pick(&self.opacities, i);
            // Each material the object uses, copied with the overrides (other objects may
            // share the original).
            let mut copies: Vec<(u32, u32)> = Vec::new();
            for t in range.start as usize..range.end as usize {
                let old = surface.triangle_material[t];
                let new = match copies.iter().find(|(o, _)| *o == old) {
                    Some(&(_, n)) => n,
                    None => {
                        let mut m = surface.materials[old as usize].clone();
                        if let Some(c) = color {
                            m.color = c;
                        }
                        if let Some(a) = opacity {
                            m.opacity = a;
                        }
                        surface.materials.push(m);
                        let n = (surface.materials.len() - 1) as u32;
                        copies.push((old, n));
                        n
                    }
                };
                surface.triangle_material[t] = new;
            }
        }
        Ok(())
    }
}

/// Why a picture could not be made.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error("{algo} keeps no fragments (it composites in its kernel: an image only), so --shade {shade} cannot shade them; use --shade id")]
    NoFragments { algo: String, shade: &'static str },
    #[error("{algo} produces no image (a counting algorithm gives a depth-complexity picture)")]
    NoImage { algo: String },
    #[error("{0}")]
    Setting(String),
    #[error(transparent)]
    Scene(SceneError),
    #[error("{}: cannot write: {source}", path.display())]
    Io {
        path: std::path::PathBuf,
        source: std::io::Error,
    },
}

/// What the renderer needs to know of a scene: its mesh, surface and the camera's matrix.
pub struct View<'a> {
    pub scene: &'a Scene,
    pub surface: &'a Surface,
    pub view_proj: glam::Mat4,
    pub width: u32,
    pub height: u32,
    /// The constant opacity of [`Shade::Id`]'s composite (`--alpha`).
    pub alpha: f32,
}

/// The image of a run's result (RGBA, row-major, top row first) as `look` shades it, and
/// what shading saw (nothing under [`Shade::Id`], which takes the algorithm's own image).
pub fn image(
    algo: &str,
    result: &AlgoResult,
    view: &View<'_>,
    look: &Look,
) -> Result<(Vec<[f32; 4]>, ShadeStats), RenderError> {
    if look.shade == Shade::Id {
        if let Some(i) = &result.image {
            return Ok((i.clone(), ShadeStats::default()));
        }
        // The truth keeps fragments only: its composite is the one the oracle compares.
        let c = result
            .capture
            .as_ref()
            .ok_or_else(|| RenderError::NoImage { algo: algo.into() })?;
        let img = (0..c.pixels())
            .map(|p| {
                fragrace_kernels::common::composite_frags(c.pixel(p), view.alpha, look.background)
            })
            .collect();
        return Ok((img, ShadeStats::default()));
    }
    let Some(capture) = &result.capture else {
        return Err(if result.counts.is_some() {
            RenderError::NoImage { algo: algo.into() }
        } else {
            RenderError::NoFragments {
                algo: algo.into(),
                shade: look.shade.name(),
            }
        });
    };
    let shader = Shader::new(
        &view.scene.mesh,
        view.surface,
        view.view_proj,
        view.width,
        view.height,
        *look,
    );
    Ok(shader.image(capture))
}
