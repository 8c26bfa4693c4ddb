//! Normalisation and the orbit camera, exactly as `oit.py` (the llvmpipe reference harness)
//! computes them, so that fragrace and llvmpipe rasterize the same triangles at the same
//! pixels and their fragment counts and timings compare.
//!
//! Everything is computed in f64 (as numpy does) and rounded to f32 once at the end.

use glam::{DMat4, DVec3, DVec4, Mat4, Vec3};
use serde::{Deserialize, Serialize};

use super::SceneError;

/// Centres the bounding box at the origin and scales the largest extent to 1 (the unit
/// cube), in place; returns the bounding-sphere radius about the origin (`oit.py`'s
/// `normalise`). An empty slice returns 0; if every point coincides the points are only
/// centred (there is no extent to scale) and 0 is returned.
pub fn normalise(positions: &mut [Vec3]) -> f32 {
    let Some(first) = positions.first() else {
        return 0.0;
    };
    let (lo, hi) = positions
        .iter()
        .fold((first.as_dvec3(), first.as_dvec3()), |(lo, hi), p| {
            (lo.min(p.as_dvec3()), hi.max(p.as_dvec3()))
        });
    let centre = (lo + hi) / 2.0;
    let extent = (hi - lo).max_element();
    let scale = if extent > 0.0 { extent } else { 1.0 };
    let mut radius2 = 0.0f64;
    for p in positions.iter_mut() {
        let v = (p.as_dvec3() - centre) / scale;
        radius2 = radius2.max(v.length_squared());
        *p = v.as_vec3();
    }
    radius2.sqrt() as f32
}

/// An orbit camera around the origin, as `oit.py`'s `camera()`: the eye is on a sphere,
/// `azimuth` (degrees) rotates about +Y (0 = on +Z, 90 = on +X), `elevation` (degrees) lifts
/// towards +Y; the distance makes the scene's bounding sphere span `fill` of the smaller
/// viewport dimension with a vertical field of view `fovy` (degrees). Stored in case files,
/// so every field has a default and may be omitted.
///
/// The renderer's options leave the peer's camera alone when they are unset (they are then
/// left out of case files too): `distance` puts the eye that far from the point looked at,
/// `look_at` moves that point from the origin (in the normalised scene's units: the scene's
/// bounding box is centred at the origin, its largest extent 1), and
/// [`Projection::Orthographic`] frames the bounding sphere with parallel rays.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Camera {
    pub azimuth: f32,
    pub elevation: f32,
    pub fovy: f32,
    pub fill: f32,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distance: Option<f32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub look_at: Option<[f32; 3]>,
    #[serde(skip_serializing_if = "Projection::is_perspective")]
    pub projection: Projection,
}

/// How the camera projects.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Projection {
    /// A pinhole with the vertical field of view `fovy` (the peer's).
    #[default]
    Perspective,
    /// Parallel rays; the bounding sphere spans `fill` of the smaller viewport dimension.
    Orthographic,
}

impl Projection {
    fn is_perspective(&self) -> bool {
        *self == Projection::Perspective
    }
}

impl Default for Camera {
    /// `oit.py`'s defaults: looking down -Z from +Z, 60 degree fov, 80 % fill.
    fn default() -> Self {
        Camera {
            azimuth: 0.0,
            elevation: 0.0,
            fovy: 60.0,
            fill: 0.8,
            distance: None,
            look_at: None,
            projection: Projection::Perspective,
        }
    }
}

impl Camera {
    /// A camera at the given angles (degrees) with the default fov and fill.
    pub fn new(azimuth: f32, elevation: f32) -> Self {
        Camera {
            azimuth,
            elevation,
            ..Camera::default()
        }
    }

    /// Refuses a camera that cannot frame anything (the matrix would hold NaN or infinity):
    /// non-finite angles, `fovy` outside (0, 180) degrees, `fill` not positive and finite
    /// (above 1 is allowed: it zooms into the scene), or an empty viewport. Case files are checked with this before a run.
    pub fn validate(&self, width: u32, height: u32) -> Result<(), SceneError> {
        let bad = |reason: String| Err(SceneError::BadCamera { reason });
        if !(self.azimuth.is_finite() && self.elevation.is_finite()) {
            return bad(format!(
                "angles must be finite: azimuth {}, elevation {}",
                self.azimuth, self.elevation
            ));
        }
        if !(self.fovy > 0.0 && self.fovy < 180.0) {
            return bad(format!("fovy {} is not in (0, 180) degrees", self.fovy));
        }
        if !(self.fill > 0.0 && self.fill.is_finite()) {
            return bad(format!("fill {} is not positive and finite", self.fill));
        }
        if width == 0 || height == 0 {
            return bad(format!("empty viewport {width}x{height}"));
        }
        if let Some(d) = self.distance {
            if !(d > 0.0 && d.is_finite()) {
                return bad(format!("distance {d} is not positive and finite"));
            }
        }
        if let Some(p) = self.look_at {
            if !p.iter().all(|c| c.is_finite()) {
                return bad(format!("look-at point {p:?} is not finite"));
            }
        }
        Ok(())
    }

    /// Whether this is the peer's orbit camera (no renderer option set).
    pub fn is_orbit(&self) -> bool {
        self.distance.is_none() && self.look_at.is_none() && self.projection.is_perspective()
    }

    /// The full camera set-up for a scene of bounding-sphere `radius` in a `width` x `height`
    /// viewport.
    ///
    /// The f32 angles, fov and fill are widened through their shortest decimal form (0.8f32
    /// becomes 0.8, not 0.800000011920929), so that a camera written `0.8` in a case file
    /// gives the matrix `oit.py --fill 0.8` gives.
    pub fn rig(&self, radius: f32, width: u32, height: u32) -> CameraRig {
        if !self.is_orbit() {
            return self.free_rig(f64::from(radius), width, height);
        }
        camera_rig(
            f64::from(radius),
            decimal(self.azimuth),
            decimal(self.elevation),
            width,
            height,
            decimal(self.fovy),
            decimal(self.fill),
        )
    }

    /// The view-projection matrix (OpenGL clip space, z in `[-w, w]`) for a scene of
    /// bounding-sphere `radius` in a `width` x `height` viewport.
    pub fn view_proj(&self, radius: f32, width: u32, height: u32) -> Mat4 {
        self.rig(radius, width, height).view_proj.as_mat4()
    }
}

impl Camera {
    /// The renderer's camera ([`Camera::is_orbit`] false): the orbit's direction and up
    /// vector, the eye `distance` from `look_at` (default: the orbit's distance and the
    /// origin), near and far around the bounding sphere (the near plane at least a
    /// thousandth of the far one away, so an eye inside the scene still sees what is in
    /// front of it).
    fn free_rig(&self, radius: f64, width: u32, height: u32) -> CameraRig {
        let orbit = camera_rig(
            radius,
            decimal(self.azimuth),
            decimal(self.elevation),
            width,
            height,
            decimal(self.fovy),
            decimal(self.fill),
        );
        let target = self
            .look_at
            .map(|p| DVec3::new(decimal(p[0]), decimal(p[1]), decimal(p[2])))
            .unwrap_or(DVec3::ZERO);
        let dist = self.distance.map(decimal).unwrap_or(orbit.distance);
        let dir = orbit.eye / orbit.eye.length();
        let eye = target + dir * dist;
        // The orbit's view matrix, moved: same axes, another eye.
        let rot = DMat4::from_cols(
            orbit.view.x_axis,
            orbit.view.y_axis,
            orbit.view.z_axis,
            DVec4::W,
        );
        let view = rot * DMat4::from_translation(-eye);
        // Depth of the scene's centre along the view direction.
        let centre = -(view.transform_point3(DVec3::ZERO)).z;
        let aspect = f64::from(width) / f64::from(height);
        let (proj, near, far) = match self.projection {
            Projection::Perspective => {
                let far = (centre + radius) * 1.01;
                let near = ((centre - radius) * 0.99).max(far * 1e-3);
                let far = far.max(near * 2.0);
                let t = 1.0 / (decimal(self.fovy).to_radians() / 2.0).tan();
                let p = DMat4::from_cols_array_2d(&[
                    [t / aspect, 0.0, 0.0, 0.0],
                    [0.0, t, 0.0, 0.0],
                    [0.0, 0.0, (far + near) / (near - far), -1.0],
                    [0.0, 0.0, 2.0 * far * near / (near - far), 0.0],
                ]);
                (p, near, far)
            }
            Projection::Orthographic => {
                let (near, far) = (centre - radius * 1.01, centre + radius * 1.01);
                // Half extents: the sphere spans `fill` of the smaller dimension.
                let h = radius / decimal(self.fill) / aspect.min(1.0);
                let w = h * aspect;
                let p = DMat4::from_cols_array_2d(&[
                    [1.0 / w, 0.0, 0.0, 0.0],
                    [0.0, 1.0 / h, 0.0, 0.0],
                    [0.0, 0.0, -2.0 / (far - near), 0.0],
                    [0.0, 0.0, -(far + near) / (far - near), 1.0],
                ]);
                (p, near, far)
            }
        };
        CameraRig {
            view,
            proj,
            view_proj: proj * view,
            eye,
            distance: dist,
            near,
            far,
            fovy: decimal(self.fovy),
        }
    }
}

/// An f32 widened to the f64 with the same shortest decimal representation.
fn decimal(x: f32) -> f64 {
    // Display of a finite f32 round-trips and always parses; non-finite values widen as is.
    x.to_string().parse().unwrap_or(f64::from(x))
}

/// A camera set-up in f64: what `oit.py`'s `camera()` returns, plus the matrices and the eye
/// (tests and heatmaps need the eye to cast rays).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraRig {
    pub view: DMat4,
    pub proj: DMat4,
    /// `proj * view`.
    pub view_proj: DMat4,
    pub eye: DVec3,
    pub distance: f64,
    pub near: f64,
    pub far: f64,
    pub fovy: f64,
}

/// `oit.py`'s `camera(radius, azimuth, elevation, width, height, fovy_deg, fill)`, term for
/// term. The `up` vector switches to the horizontal azimuth direction within 0.1 degree of
/// the poles (where +Y would be parallel to the view direction); near and far hug the
/// bounding sphere (1 % margins) so depth precision is spent on the scene.
pub fn camera_rig(
    radius: f64,
    azimuth_deg: f64,
    elevation_deg: f64,
    width: u32,
    height: u32,
    fovy_deg: f64,
    fill: f64,
) -> CameraRig {
    let (az, el) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
    let aspect = f64::from(width) / f64::from(height);
    let tan_half = (fovy_deg.to_radians() / 2.0).tan() * aspect.min(1.0); // narrower half-fov
    let dist = radius / (fill * tan_half).atan().sin();
    let eye = dist * DVec3::new(el.cos() * az.sin(), el.sin(), el.cos() * az.cos());
    let up = if elevation_deg.abs() < 89.9 {
        DVec3::Y
    } else {
        DVec3::new(-az.sin(), 0.0, -az.cos())
    };
    let f = -eye / eye.length();
    let s = f.cross(up);
    let s = s / s.length();
    let u = s.cross(f);
    let rows = |r: [DVec3; 3]| -> [[f64; 4]; 4] {
        let t = |v: DVec3| -v.dot(eye);
        [
            [r[0].x, r[0].y, r[0].z, t(r[0])],
            [r[1].x, r[1].y, r[1].z, t(r[1])],
            [r[2].x, r[2].y, r[2].z, t(r[2])],
            [0.0, 0.0, 0.0, 1.0],
        ]
    };
    let view = rows([s, u, -f]);
    let near = (dist - radius) * 0.99;
    let far = (dist + radius) * 1.01;
    let t = 1.0 / (fovy_deg.to_radians() / 2.0).tan();
    let proj = [
        [t / aspect, 0.0, 0.0, 0.0],
        [0.0, t, 0.0, 0.0],
        [
            0.0,
            0.0,
            (far + near) / (near - far),
            2.0 * far * near / (near - far),
        ],
        [0.0, 0.0, -1.0, 0.0],
    ];
    let mut vp = [[0.0f64; 4]; 4];
    for (i, row) in vp.iter_mut().enumerate() {
        for (j, out) in row.iter_mut().enumerate() {
            *out = (0..4).fold(0.0, |acc, k| acc + proj[i][k] * view[k][j]);
        }
    }
    // glam is column-major: the transpose of the row-major array is the matrix.
    let from_rows = |m: [[f64; 4]; 4]| DMat4::from_cols_array_2d(&m).transpose();
    CameraRig {
        view: from_rows(view),
        proj: from_rows(proj),
        view_proj: from_rows(vp),
        eye,
        distance: dist,
        near,
        far,
        fovy: fovy_deg,
    }
}

/// `oit.py`'s `camera()` matrix as f32 (glam, column-major).
pub fn camera(
    radius: f64,
    azimuth_deg: f64,
    elevation_deg: f64,
    width: u32,
    height: u32,
    fovy_deg: f64,
    fill: f64,
) -> Mat4 {
    camera_rig(
        radius,
        azimuth_deg,
        elevation_deg,
        width,
        height,
        fovy_deg,
        fill,
    )
    .view_proj
    .as_mat4()
}
