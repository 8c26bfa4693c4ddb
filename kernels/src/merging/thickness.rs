//! The z-thickness model (Kim & Kye, "Z-Thickness Blending: Effective Fragment Merging for
//! Multi-Fragment Rendering", section 3.1): every fragment is a translucent band of
//! thickness `t` along the view direction, from `z - t` to its surface depth `z`.
//!
//! The thickness is, by default, twice the z-resolution of a 24-bit depth buffer at the
//! fragment's depth (section 4.1.3, equation 9):
//!
//! `P(z) = b / (b / z - 1 / 2^n) - z`, `b = z_n z_f / (z_n - z_f)`,
//!
//! the smallest view-depth separation a depth buffer of `n` bits resolves at view depth `z`
//! (near plane `z_n`, far plane `z_f`). With `z > 0` and `b < 0` as written the expression is
//! negative; its magnitude is the resolution, which is what we use. A fixed thickness in
//! view depth can be given instead (the paper's "the z-thickness value can be manually
//! adjusted", sections 4.1.3 and 5.2).
//!
//! Kernels see window depth only (`gl_FragCoord.z`, OpenGL's `(z_ndc + 1) / 2`), so
//! [`DepthModel`] recovers the view depth from it, with the near and far planes read off the
//! frame's view-projection matrix (its depth row is `a * w + b` in the clip `w`).

use glam::Mat4;

use super::record::ZFrag;
use crate::algo::{AlgoError, Frame, Params};

/// How thick each fragment is.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Thickness {
    /// `multiple * P(z)` (equation 9) for a depth buffer of `bits` precision bits; the
    /// paper's default is `2 * P(z)` with 24 bits.
    ZResolution { multiple: f32, bits: u32 },
    /// A fixed thickness in view depth (the units of the scene), the same for every fragment.
    Fixed(f32),
}

impl Default for Thickness {
    fn default() -> Self {
        Thickness::ZResolution {
            multiple: 2.0,
            bits: 24,
        }
    }
}

/// Largest number of depth-buffer precision bits accepted (an f32 window depth has 24).
pub const MAX_BITS: u32 = 32;

/// The parameters of fragment merging, one field of [`crate::Params`].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct MergeParams {
    pub thickness: Thickness,
    /// β of equation 4: 0 subdivides a fragment's opacity exactly (equation 2), 1 linearly
    /// (the smoother transition the paper uses for its visual effects, section 5.2).
    pub beta: f32,
}

impl Default for MergeParams {
    fn default() -> Self {
        MergeParams {
            thickness: Thickness::default(),
            beta: 0.0,
        }
    }
}

/// A merging parameter out of its range, or a frame the model cannot read depth from.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MergeParamError {
    #[error("thickness {0} is invalid: a fixed thickness must be a finite view depth >= 0")]
    Thickness(f32),
    #[error("thickness multiple {0} is invalid: the multiple of P(z) must be finite and >= 0")]
    Multiple(f32),
    #[error("z-resolution bits {0} is invalid: the precision must be in 1..={MAX_BITS}")]
    Bits(u32),
    #[error("beta {0} is invalid: beta of equation 4 must be in [0, 1]")]
    Beta(f32),
    #[error("thickness `{0}` is not understood: give a view depth >= 0 (e.g. 0.01), `NxP` (e.g. 2xP, N >= 0, N times the z-resolution of eq. 9) or `NxP:BITS`")]
    Syntax(String),
    #[error("the view-projection matrix maps depth neither perspectively nor affinely (depth row {0:?}), so the view depth of a fragment is unknown")]
    Projection([f32; 4]),
}

impl From<MergeParamError> for AlgoError {
    fn from(e: MergeParamError) -> AlgoError {
        AlgoError::Invalid(e.to_string())
    }
}

impl MergeParams {
    /// Whether these are the defaults (left out of serialised parameters).
    pub fn is_default(&self) -> bool {
        *self == MergeParams::default()
    }

    /// Checks every field against its range.
    pub fn validate(&self) -> Result<(), MergeParamError> {
        self.thickness.validate()?;
        if !(0.0..=1.0).contains(&self.beta) {
            return Err(MergeParamError::Beta(self.beta));
        }
        Ok(())
    }
}

impl Thickness {
    /// Checks the thickness against its range.
    pub fn validate(&self) -> Result<(), MergeParamError> {
        match *self {
            Thickness::Fixed(t) if !(t.is_finite() && t >= 0.0) => {
                Err(MergeParamError::Thickness(t))
            }
            Thickness::ZResolution { multiple, .. }
                if !(multiple.is_finite() && multiple >= 0.0) =>
            {
                Err(MergeParamError::Multiple(multiple))
            }
            Thickness::ZResolution { bits, .. } if bits == 0 || bits > MAX_BITS => {
                Err(MergeParamError::Bits(bits))
            }
            _ => Ok(()),
        }
    }

    /// The thickness of a fragment at view depth `z` under `model`.
    pub fn at(&self, model: &DepthModel, z: f32) -> f32 {
        match *self {
            Thickness::Fixed(t) => t,
            Thickness::ZResolution { multiple, bits } => multiple * model.z_resolution(z, bits),
        }
    }
}

impl std::str::FromStr for Thickness {
    type Err = MergeParamError;

    /// `0.01` (fixed, view depth), `2xP` (2 P(z), 24 bits) or `2xP:16` (2 P(z), 16 bits).
    fn from_str(s: &str) -> Result<Thickness, MergeParamError> {
        let syntax = || MergeParamError::Syntax(s.to_string());
        let t = if let Some((m, rest)) = s.split_once("xP") {
            let multiple: f32 = m.parse().map_err(|_| syntax())?;
            let bits = match rest.strip_prefix(':') {
                Some(b) => b.parse().map_err(|_| syntax())?,
                None if rest.is_empty() => 24,
                None => return Err(syntax()),
            };
            Thickness::ZResolution { multiple, bits }
        } else {
            Thickness::Fixed(s.parse().map_err(|_| syntax())?)
        };
        t.validate()?;
        Ok(t)
    }
}

impl std::fmt::Display for Thickness {
    /// The syntax [`Thickness::from_str`](std::str::FromStr) reads.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Thickness::Fixed(t) => write!(f, "{t}"),
            Thickness::ZResolution { multiple, bits: 24 } => write!(f, "{multiple}xP"),
            Thickness::ZResolution { multiple, bits } => write!(f, "{multiple}xP:{bits}"),
        }
    }
}

/// How window depth maps to view depth for a frame's projection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DepthModel {
    /// A perspective projection with these near and far planes (view depths, `0 < near < far`):
    /// window depth `d = a + b / z` with `a = far / (far - near)` and `b` of equation 9.
    Perspective { near: f64, far: f64 },
    /// An affine (orthographic) projection: view depth `z = d * range` (the view-depth span
    /// of the window-depth range [0, 1], offset dropped: merging uses depth differences only).
    Affine { range: f64 },
}

impl DepthModel {
    /// Reads the model off a view-projection matrix whose clip `w` is the view depth
    /// (perspective: depth row = `a * w_row + b * (0, 0, 0, 1)`, as OpenGL's projection times a
    /// rigid view) or constant (affine).
    pub fn of(view_proj: Mat4) -> Result<DepthModel, MergeParamError> {
        let zr = view_proj.row(2).as_dvec4();
        let wr = view_proj.row(3).as_dvec4();
        let bad = || MergeParamError::Projection(view_proj.row(2).to_array());
        let w_xyz = wr.truncate();
        if w_xyz.length_squared() == 0.0 {
            // Affine: clip w constant, z_ndc = z_row / w.
            let scale = zr.truncate().length() / wr.w.abs();
            if !(scale.is_finite() && scale > 0.0) {
                return Err(bad());
            }
            // window depth = (z_ndc + 1) / 2, so one unit of window depth is 2 / scale.
            return Ok(DepthModel::Affine { range: 2.0 / scale });
        }
        let a = zr.truncate().dot(w_xyz) / w_xyz.length_squared();
        let residual = (zr.truncate() - a * w_xyz).length();
        if residual > 1e-4 * zr.truncate().length().max(1e-30) {
            return Err(bad());
        }
        let b = zr.w - a * wr.w;
        // z_clip = a w + b, a = (f + n) / (f - n), b = -2 f n / (f - n).
        let near = -b / (a + 1.0);
        let far = -b / (a - 1.0);
        if !(near.is_finite() && far.is_finite() && near > 0.0 && far > near) {
            return Err(bad());
        }
        Ok(DepthModel::Perspective { near, far })
    }

    /// The view depth of window depth `d`.
    pub fn view_depth(&self, d: f32) -> f32 {
        let d = f64::from(d);
        let z = match *self {
            DepthModel::Perspective { near, far } => {
                let (a, b) = Self::window_coefficients(near, far);
                b / (d - a)
            }
            DepthModel::Affine { range } => d * range,
        };
        z as f32
    }

    /// `a` and `b` of `d = a + b / z` (b is equation 9's).
    fn window_coefficients(near: f64, far: f64) -> (f64, f64) {
        (far / (far - near), near * far / (near - far))
    }

    /// Equation 9: the z-resolution `P(z)` of a depth buffer of `bits` bits at view depth `z`
    /// (its magnitude; see the module documentation).
    pub fn z_resolution(&self, z: f32, bits: u32) -> f32 {
        let unit = (-f64::from(bits)).exp2();
        let p = match *self {
            DepthModel::Perspective { near, far } => {
                let (_, b) = Self::window_coefficients(near, far);
                let z = f64::from(z);
                b / (b / z - unit) - z
            }
            DepthModel::Affine { range } => range * unit,
        };
        p.abs() as f32
    }
}

/// What a kernel needs to turn a rasterized fragment into a [`ZFrag`]: the frame's depth
/// model, the thickness, and the opacity of every fragment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ZModel {
    pub depth: DepthModel,
    pub thickness: Thickness,
    pub alpha: f32,
}

impl ZModel {
    /// The model of `frame` under `params` (merge parameters checked).
    pub fn of(frame: &Frame<'_>, params: &Params) -> Result<ZModel, MergeParamError> {
        params.merge.validate()?;
        Ok(ZModel {
            depth: DepthModel::of(frame.view_proj)?,
            thickness: params.merge.thickness,
            alpha: params.alpha,
        })
    }

    /// The fragment of primitive `prim` at window depth `window_depth`: its view depth, its
    /// thickness there, its colour at the model's opacity.
    pub fn fragment(&self, window_depth: f32, prim: u32) -> ZFrag {
        let z = self.depth.view_depth(window_depth);
        ZFrag::of_primitive(z, self.thickness.at(&self.depth, z), prim, self.alpha)
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;

    fn perspective(near: f32, far: f32) -> Mat4 {
        let proj = Mat4::perspective_rh_gl(0.8, 1.3, near, far);
        let view = Mat4::look_at_rh(Vec3::new(3.0, 1.0, 4.0), Vec3::ZERO, Vec3::Y);
        proj * view
    }

    #[test]
    fn near_and_far_are_read_off_the_view_projection() {
        let DepthModel::Perspective { near, far } = DepthModel::of(perspective(0.5, 20.0)).unwrap()
        else {
            panic!("perspective expected");
        };
        assert!(
            (near - 0.5).abs() < 1e-5 && (far - 20.0).abs() < 1e-3,
            "{near} {far}"
        );
        assert_eq!(
            DepthModel::of(Mat4::IDENTITY).unwrap(),
            DepthModel::Affine { range: 2.0 }
        );
    }

    #[test]
    fn view_depth_inverts_the_window_depth_of_the_projection() {
        let vp = perspective(0.5, 20.0);
        let model = DepthModel::of(vp).unwrap();
        let eye = Vec3::new(3.0, 1.0, 4.0);
        for s in [0.1f32, 0.5, 0.9] {
            let p = eye * (1.0 - s) * 0.9; // points between the eye and the origin
            let clip = vp * p.extend(1.0);
            let d = (clip.z / clip.w + 1.0) / 2.0;
            let want = (eye - p).dot(-eye.normalize()).abs();
            let got = model.view_depth(d);
            assert!((got - want).abs() < 1e-3 * want, "{got} vs {want}");
        }
    }

    #[test]
    fn z_resolution_is_one_depth_buffer_step() {
        // Equation 9 is the view-depth step of one unit of an n-bit buffer: stepping the
        // window depth of z back by 2^-n lands at z - P(z).
        let model = DepthModel::Perspective {
            near: 1.0,
            far: 100.0,
        };
        let (a, b) = DepthModel::window_coefficients(1.0, 100.0);
        for z in [1.0f64, 10.0, 50.0, 99.0] {
            let d = a + b / z;
            let z2 = b / (d - (-16f64).exp2() - a);
            let p = model.z_resolution(z as f32, 16) as f64;
            assert!(((z - z2) - p).abs() < 1e-5 * p, "{z}: {} vs {p}", z - z2);
        }
        // Precision is lost with distance: P grows like z^2.
        assert!(model.z_resolution(50.0, 24) > 100.0 * model.z_resolution(4.0, 24));
    }

    #[test]
    fn bad_parameters_name_the_value_and_the_range() {
        let e = Thickness::Fixed(-0.5).validate().unwrap_err().to_string();
        assert!(e.contains("-0.5") && e.contains(">= 0"), "{e}");
        let e = "-1xP".parse::<Thickness>().unwrap_err().to_string();
        assert!(e.contains("-1") && e.contains(">= 0"), "{e}");
        let e = "2xP:0".parse::<Thickness>().unwrap_err().to_string();
        assert!(e.contains("bits 0") && e.contains("1..=32"), "{e}");
        let e = MergeParams {
            beta: 1.5,
            ..MergeParams::default()
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert!(e.contains("1.5") && e.contains("[0, 1]"), "{e}");
        assert!("thick".parse::<Thickness>().is_err());
        assert_eq!("0.25".parse::<Thickness>().unwrap(), Thickness::Fixed(0.25));
        assert_eq!(
            "100xP".parse::<Thickness>().unwrap(),
            Thickness::ZResolution {
                multiple: 100.0,
                bits: 24
            }
        );
        for t in ["2xP:16", "2xP", "0.5", "0"] {
            assert_eq!(t.parse::<Thickness>().unwrap().to_string(), t);
        }
    }
}
