//! Scene files (`--scene-file PATH`): JSON listing objects (OBJ files with a placement and an
//! optional colour and opacity) and a camera. Every key is checked: an unknown one is an
//! error naming it and its line, so a typo never silently changes a picture.
//!
//! ```json
//! {
//!   "objects": [
//!     { "obj": "slab.obj", "translate": [0, 0, 0], "rotate": [0, 30, 0], "scale": 1.0,
//!       "color": [0.9, 0.4, 0.3], "opacity": 0.5 },
//!     { "obj": "../assets/bunny.obj.gz", "translate": [1.2, 0, 0] }
//!   ],
//!   "camera": { "azimuth": 30, "elevation": 20, "fov": 45, "fill": 0.8,
//!               "distance": 3.0, "look_at": [0, 0, 0], "orthographic": false }
//! }
//! ```
//!
//! Paths are relative to the scene file's folder. Placements apply in the object's own units:
//! scale, then rotation about X, Y, Z (degrees), then translation; the whole scene is then
//! normalised as any (centred, largest extent 1). `color` and `opacity` replace the MTL's
//! for the whole object; the camera's keys are those of `--azimuth`, `--elevation`, `--fov`,
//! `--fill`, `--distance`, `--look-at` and `--orthographic` (the command line's win).

use std::path::{Path, PathBuf};

use glam::{EulerRot, Mat4, Quat, Vec3};
use serde::Deserialize;

use super::camera::{Camera, Projection};
use super::material::check_unit;
use super::{Part, SceneError};

/// A scene file, as read.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    pub objects: Vec<ObjectEntry>,
    #[serde(default)]
    pub camera: CameraEntry,
}

/// One object of a scene file.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectEntry {
    /// The OBJ file (plain or gzip), relative to the scene file's folder.
    pub obj: PathBuf,
    #[serde(default)]
    pub translate: [f32; 3],
    /// Degrees about X, then Y, then Z.
    #[serde(default)]
    pub rotate: [f32; 3],
    #[serde(default = "one")]
    pub scale: f32,
    pub color: Option<[f32; 3]>,
    pub opacity: Option<f32>,
}

fn one() -> f32 {
    1.0
}

/// The camera of a scene file: every key optional.
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraEntry {
    pub azimuth: Option<f32>,
    pub elevation: Option<f32>,
    pub fov: Option<f32>,
    pub fill: Option<f32>,
    pub distance: Option<f32>,
    pub look_at: Option<[f32; 3]>,
    #[serde(default)]
    pub orthographic: bool,
}

impl SceneFile {
    /// Reads and checks a scene file (syntax, keys, ranges; the OBJ files are read by
    /// [`SceneFile::parts`]).
    pub fn read(path: &Path) -> Result<SceneFile, SceneError> {
        let bytes = std::fs::read(path).map_err(|source| match source.kind() {
            std::io::ErrorKind::NotFound => SceneError::NotFound {
                path: path.to_owned(),
            },
            _ => SceneError::Io {
                path: path.to_owned(),
                source,
            },
        })?;
        SceneFile::parse(&bytes, path)
    }

    /// [`SceneFile::read`] of bytes already read; `path` names them in errors.
    pub fn parse(bytes: &[u8], path: &Path) -> Result<SceneFile, SceneError> {
        let bad = |reason: String| SceneError::SceneFile {
            path: path.to_owned(),
            reason,
        };
        // serde_json's messages name the key and say "at line L column C".
        let file: SceneFile = serde_json::from_slice(bytes).map_err(|e| bad(e.to_string()))?;
        if file.objects.is_empty() {
            return Err(bad(
                "\"objects\" is empty: a scene needs at least one".into()
            ));
        }
        for (i, o) in file.objects.iter().enumerate() {
            let what = format!("{}: object {} ({})", path.display(), i, o.obj.display());
            if let Some(a) = o.opacity {
                check_unit(&what, "opacity", a)?;
            }
            if let Some(c) = o.color {
                for (v, name) in c.iter().zip(["red", "green", "blue"]) {
                    check_unit(&what, &format!("colour ({name})"), *v)?;
                }
            }
            if !(o.scale.is_finite() && o.scale != 0.0) {
                return Err(bad(format!(
                    "object {i}: scale {} must be finite and not 0",
                    o.scale
                )));
            }
            if !o.translate.iter().chain(&o.rotate).all(|v| v.is_finite()) {
                return Err(bad(format!(
                    "object {i}: translate and rotate must be finite"
                )));
            }
        }
        Ok(file)
    }

    /// The objects, loaded (paths relative to `dir`, the scene file's folder) and placed, with
    /// their colour and opacity overrides.
    pub fn parts(&self, dir: &Path) -> Result<Vec<Part>, SceneError> {
        self.objects
            .iter()
            .enumerate()
            .map(|(i, o)| {
                let mut part = Part::from_obj(&dir.join(&o.obj), i)?;
                let [rx, ry, rz] = o.rotate.map(f32::to_radians);
                part.placement = Mat4::from_scale_rotation_translation(
                    Vec3::splat(o.scale),
                    Quat::from_euler(EulerRot::ZYX, rz, ry, rx),
                    Vec3::from_array(o.translate),
                );
                part.surface.override_material(|m| {
                    if let Some(c) = o.color {
                        m.color = c;
                    }
                    if let Some(a) = o.opacity {
                        m.opacity = a;
                    }
                });
                Ok(part)
            })
            .collect()
    }

    /// `base` with the keys this file's camera sets.
    pub fn camera(&self, base: Camera) -> Camera {
        let c = &self.camera;
        Camera {
            azimuth: c.azimuth.unwrap_or(base.azimuth),
            elevation: c.elevation.unwrap_or(base.elevation),
            fovy: c.fov.unwrap_or(base.fovy),
            fill: c.fill.unwrap_or(base.fill),
            distance: c.distance.or(base.distance),
            look_at: c.look_at.or(base.look_at),
            projection: if c.orthographic {
                Projection::Orthographic
            } else {
                base.projection
            },
        }
    }
}

/// The folder of a scene file, where its OBJ paths start.
pub fn folder(path: &Path) -> PathBuf {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => PathBuf::from("."),
    }
}
