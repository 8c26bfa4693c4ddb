//! Shading the fragments a run kept: deferred, from what every algorithm stores per fragment
//! (its window depth and primitive id), as the bucket paper's deferred shading pass does from
//! its buckets ("Efficient Depth Peeling via Bucket Sort", section 4, "Translucency" and the
//! Fresnel paragraph after it).
//!
//! For each kept fragment the pixel centre and depth are unprojected to the scene point it
//! shows; the point's barycentric coordinates in its triangle interpolate the corner normals
//! (a visibility buffer: the primitive id stands for every attribute). Then, per pixel, the
//! fragments sorted front to back (depth, then primitive id: the truth's order) are:
//! - [`Shade::Lit`]: lit by a headlight and an ambient term (Lambert diffuse, Blinn-Phong
//!   specular; back faces with their normal turned to the eye) and composited "over" with
//!   their material's opacity;
//! - [`Shade::Translucent`]: Beer-Lambert absorption `exp(-sigma l)`, `l` the thickness
//!   between layers 0 and 1, 2 and 3, ... (an object is entered and left); the absorption
//!   per channel is `sigma (1 - Kd)`, so a material transmits its colour;
//! - [`Shade::Fresnel`]: the same, times every fragment's Schlick transmittance
//!   `1 - (1 - cos theta)^5`.
//!
//! The shading is the same for every algorithm, so an exact algorithm's picture equals the
//! truth's, and a race's lost or wrong fragments show as what they are: a missing layer, a
//! thickness counted between the wrong surfaces.

use fragrace_kernels::algo::{Capture, CapturedFrag};
use glam::{DMat4, DVec4, Mat4, Vec3};
use rayon::prelude::*;

use super::{Look, Shade};
use crate::scene::Surface;
use fragrace_emu::Mesh;

/// Everything shading needs besides the fragments.
pub struct Shader<'a> {
    pub mesh: &'a Mesh,
    pub surface: &'a Surface,
    /// The inverse of the view-projection matrix the run drew with (in f64: thicknesses are
    /// differences of nearby points).
    inverse: DMat4,
    pub width: u32,
    pub height: u32,
    pub look: Look,
}

/// What shading found besides the image.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ShadeStats {
    /// Fragments shaded.
    pub fragments: u64,
    /// Fragments the algorithm kept without a primitive id (the bucket schemes keep depths
    /// only): shaded with the scene's first material and a normal facing the eye.
    pub without_primitive: u64,
}

/// One kept fragment, ready to composite.
#[derive(Clone, Copy)]
struct Lit {
    color: [f32; 3],
    opacity: f32,
    /// The scene point it shows.
    point: Vec3,
    /// `|n . v|`: the cosine of the angle between the normal and the eye direction.
    cos: f32,
    /// The material's colour (absorption is `sigma (1 - kd)`).
    kd: [f32; 3],
}

impl<'a> Shader<'a> {
    pub fn new(
        mesh: &'a Mesh,
        surface: &'a Surface,
        view_proj: Mat4,
        width: u32,
        height: u32,
        look: Look,
    ) -> Shader<'a> {
        Shader {
            mesh,
            surface,
            inverse: view_proj.as_dmat4().inverse(),
            width,
            height,
            look,
        }
    }

    /// The scene point at pixel `(x, y)` (top row first) and window depth `depth`.
    fn unproject(&self, x: u32, y: u32, depth: f32) -> Vec3 {
        let ndc = DVec4::new(
            2.0 * (f64::from(x) + 0.5) / f64::from(self.width) - 1.0,
            1.0 - 2.0 * (f64::from(y) + 0.5) / f64::from(self.height),
            2.0 * f64::from(depth) - 1.0,
            1.0,
        );
        let p = self.inverse * ndc;
        (p.truncate() / p.w).as_vec3()
    }

    /// The shaded image of `capture` (RGBA, row-major, top row first) and what shading saw.
    /// [`Shade::Id`] is not shading: the caller takes the algorithm's own image.
    pub fn image(&self, capture: &Capture) -> (Vec<[f32; 4]>, ShadeStats) {
        let w = self.width as usize;
        let mut out = vec![[0.0f32; 4]; w * self.height as usize];
        let stats: Vec<ShadeStats> = out
            .par_chunks_mut(w)
            .enumerate()
            .map(|(y, row)| {
                let mut stats = ShadeStats::default();
                let mut sorted: Vec<CapturedFrag> = Vec::new();
                let mut lit: Vec<Lit> = Vec::new();
                for (x, px) in row.iter_mut().enumerate() {
                    let frags = capture.pixel(y * w + x);
                    sorted.clear();
                    sorted.extend_from_slice(frags);
                    sorted.sort_unstable_by(fragrace_kernels::common::depth_order);
                    lit.clear();
                    for f in &sorted {
                        lit.push(self.fragment(x as u32, y as u32, f, &mut stats));
                    }
                    *px = self.composite(x as u32, y as u32, &lit);
                }
                stats
            })
            .collect();
        let total = stats.iter().fold(ShadeStats::default(), |a, s| ShadeStats {
            fragments: a.fragments + s.fragments,
            without_primitive: a.without_primitive + s.without_primitive,
        });
        (out, total)
    }

    /// One fragment: its point, normal, material and lit colour.
    fn fragment(&self, x: u32, y: u32, f: &CapturedFrag, stats: &mut ShadeStats) -> Lit {
        stats.fragments += 1;
        let point = self.unproject(x, y, f.depth);
        let eye_point = self.unproject(x, y, 0.0);
        let v = (eye_point - point).normalize_or_zero();
        let (n, material) = match self.mesh.indices.get(f.prim as usize) {
            Some(t) => {
                let prim = f.prim as usize;
                let n = self.normal(prim, *t, point);
                let m = &self.surface.materials[self.surface.triangle_material[prim] as usize];
                (n, m)
            }
            None => {
                stats.without_primitive += 1;
                (v, &self.surface.materials[0])
            }
        };
        // Back faces are lit as back faces: their normal turned towards the eye.
        let n = if n.dot(v) < 0.0 { -n } else { n };
        let cos = n.dot(v).clamp(0.0, 1.0);
        let l = &self.look;
        // Headlight: the light is at the eye, so the half vector is the eye direction.
        let diffuse = cos;
        let specular = l.specular * cos.powf(l.shininess);
        let color = material
            .color
            .map(|c| (c * (l.ambient + (1.0 - l.ambient) * diffuse) + specular).min(1.0));
        Lit {
            color,
            opacity: material.opacity,
            point,
            cos,
            kd: material.color,
        }
    }

    /// The interpolated normal of triangle `prim` (corners `t`) at `p`: barycentric
    /// coordinates of `p` in the triangle (clamped into it), or the face normal where the
    /// corner normals cancel out or the triangle is degenerate.
    fn normal(&self, prim: usize, t: [u32; 3], p: Vec3) -> Vec3 {
        let [a, b, c] = t.map(|i| self.mesh.positions[i as usize]);
        let (e0, e1, e2) = (b - a, c - a, p - a);
        let face = e0.cross(e1);
        let (d00, d01, d11) = (e0.dot(e0), e0.dot(e1), e1.dot(e1));
        let (d20, d21) = (e2.dot(e0), e2.dot(e1));
        let den = d00 * d11 - d01 * d01;
        if den > 0.0 {
            let v = ((d11 * d20 - d01 * d21) / den).clamp(0.0, 1.0);
            let w = ((d00 * d21 - d01 * d20) / den).clamp(0.0, 1.0 - v);
            let u = 1.0 - v - w;
            let [na, nb, nc] =
                self.surface.normal_indices[prim].map(|i| self.surface.normals[i as usize]);
            let n = (na * u + nb * v + nc * w).normalize_or_zero();
            if n != Vec3::ZERO {
                return n;
            }
        }
        face.normalize_or_zero()
    }

    /// A pixel's fragments (front to back) composited as [`Look::shade`] says.
    fn composite(&self, _x: u32, _y: u32, frags: &[Lit]) -> [f32; 4] {
        let bg = self.look.background;
        match self.look.shade {
            Shade::Lit | Shade::Id => {
                let mut acc = [0.0f32; 3];
                let mut t = 1.0f32;
                for f in frags {
                    for (a, c) in acc.iter_mut().zip(f.color) {
                        *a += c * f.opacity * t;
                    }
                    t *= 1.0 - f.opacity;
                }
                [
                    acc[0] + bg[0] * t,
                    acc[1] + bg[1] * t,
                    acc[2] + bg[2] * t,
                    1.0 - t,
                ]
            }
            Shade::Translucent | Shade::Fresnel => {
                let (tau, _) = optical_depth(frags.iter().map(|f| (f.point, f.kd)));
                let mut out = [0.0f32; 3];
                for c in 0..3 {
                    out[c] = bg[c] * (-self.look.sigma * tau[c]).exp();
                }
                if self.look.shade == Shade::Fresnel {
                    let ft: f32 = frags.iter().map(|f| schlick_transmittance(f.cos)).product();
                    out = out.map(|c| c * ft);
                }
                let covered = if frags.is_empty() { 0.0 } else { 1.0 };
                [out[0], out[1], out[2], covered]
            }
        }
    }
}

/// Per channel, the absorbing thickness `sum (1 - kd) |p_{2i+1} - p_{2i}|` of layers taken in
/// pairs (entering and leaving an object, front to back; `kd` is the entering layer's
/// material colour), and the plain thickness `l` (the same sum without `1 - kd`). An odd
/// last layer has no partner and adds nothing.
pub fn optical_depth(layers: impl Iterator<Item = (Vec3, [f32; 3])>) -> ([f32; 3], f32) {
    let mut tau = [0.0f32; 3];
    let mut l = 0.0;
    let mut entering: Option<(Vec3, [f32; 3])> = None;
    for (p, kd) in layers {
        match entering.take() {
            None => entering = Some((p, kd)),
            Some((q, kd_in)) => {
                let d = (p - q).length();
                l += d;
                for c in 0..3 {
                    tau[c] += (1.0 - kd_in[c]) * d;
                }
            }
        }
    }
    (tau, l)
}

/// Schlick's approximation of the Fresnel transmittance at a surface seen at `cos` (the
/// cosine between its normal and the eye direction): `1 - (1 - cos)^5`.
pub fn schlick_transmittance(cos: f32) -> f32 {
    1.0 - (1.0 - cos.clamp(0.0, 1.0)).powi(5)
}
