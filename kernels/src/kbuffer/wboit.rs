//! Weighted blended order-independent transparency (WBOIT; McGuire & Bavoil, "Weighted
//! Blended Order-Independent Transparency", JCGT 2(2), 2013; \[MB13\] in the z-thickness seed,
//! section 2, the blended-OIT baseline it compares against): no fragment is stored and
//! nothing is sorted. One geometry pass accumulates, with plain additive blending,
//!
//! - `accum` (RGBA32F, blend `ONE, ONE`): `sum_i (C_i w_i, a_i w_i)` with `C_i = c_i a_i`
//!   the premultiplied colour and `w_i = w(z_i, a_i)` a depth weight;
//! - `revealage` (R32F, blend `ZERO, ONE_MINUS_SRC_COLOR`, cleared to 1): `prod_i (1 - a_i)`;
//!
//! and a full-screen resolve composites over the background (the paper's equation 6):
//! `C = accum.rgb / clamp(accum.a, 1e-4, 5e4) * (1 - revealage) + background * revealage`.
//! Coverage (`1 - revealage`) is exact; colour is a weighted average that approximates the
//! depth order by favouring near fragments, so the image differs from the exact "over"
//! composite wherever two or more fragments of different colours overlap. Its EPR against
//! the truth is therefore expected to be above 0 on deep pixels: an approximation error,
//! not a race (the blending is fixed-function, applied in API order: deterministic under
//! every executor).
//!
//! **Weight function.** We use the paper's depth-buffer weight (equation 10 of the JCGT
//! paper), `w(z, a) = a * max(1e-2, 3e3 * (1 - d)^3)` with `d` the window depth
//! (`gl_FragCoord.z`): the kernels see window depth only, and this weight needs no scene
//! scale, unlike the view-space-distance weights of equations 7 to 9.
//!
//! **Float16 overflow.** The paper stores `accum` as RGBA16F (largest finite value 65504)
//! and revealage as R8. With weights up to `3e3`, a few hundred near layers overflow a
//! half-float accumulator to infinity (and the `5e4` clamp in the resolve is there to keep
//! the division in range). We accumulate in f32, which does not overflow at any realistic
//! depth complexity; an informational check counts the pixels whose accumulator would have
//! overflowed RGBA16F.

use fragrace_emu::{
    BlendEquation, BlendFactor, BlendState, Coverage, ExecConfig, Format, Fragment, FragmentKernel, Image,
    KernelInfo, SampleCount, TargetState,
};

use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Check, Deferred, Frame, HazardClass, Params,
};
use crate::common::{
    self, capture_state, framebuffer, geometry_pass, pixels, prim_rgb,
};
use crate::resolve;

/// Largest finite half float: what the paper's RGBA16F accumulator can hold.
pub const F16_MAX: f32 = 65504.0;

/// `wboit`: weighted blended OIT.
pub struct Wboit;

pub(super) fn algorithms() -> Vec<Box<dyn Algorithm>> {
    vec![Box::new(Wboit)]
}

/// The weight of equation 10 of McGuire & Bavoil 2013 for window depth `d` and opacity `a`.
pub fn weight(d: f32, a: f32) -> f32 {
    let t = 1.0 - d;
    a * (3e3 * t * t * t).max(1e-2)
}

/// The accumulation pass: weighted premultiplied colour to target 0, opacity to target 1
/// (its blend multiplies the revealage by `1 - a`).
struct Accumulate {
    alpha: f32,
}

impl FragmentKernel for Accumulate {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("wboit-accumulate")
    }
    async fn shade(&self, f: impl Fragment) {
        let c = prim_rgb(f.primitive_id());
        let a = self.alpha;
        let w = weight(f.depth(), a);
        f.output(0, [c[0] * a * w, c[1] * a * w, c[2] * a * w, a * w]);
        f.output(1, [a, a, a, a]);
    }
}

/// The composite (full screen): the paper's resolve, over the background.
struct Resolve<'a> {
    accum: &'a Image,
    revealage: &'a Image,
    background: [f32; 3],
}

impl FragmentKernel for Resolve<'_> {
    fn info(&self) -> KernelInfo {
        // At a pixel no geometry reached the revealage is still its clear, 1: the
        // background, as below.
        let bg = self.background;
        KernelInfo::new("wboit-resolve")
            .with_untouched_output([bg[0], bg[1], bg[2], 0.0].map(f32::to_bits))
    }
    async fn shade(&self, f: impl Fragment) {
        let (x, y) = (f.x(), f.y());
        let acc = f.texel(self.accum, x, y, 0).map(f32::from_bits);
        let r = f32::from_bits(f.texel(self.revealage, x, y, 0)[0]);
        let bg = self.background;
        if r >= 1.0 {
            // Nothing was drawn here (the paper discards, leaving the background).
            f.output(0, [bg[0], bg[1], bg[2], 0.0]);
            return;
        }
        let a = acc[3].clamp(1e-4, 5e4);
        let mut out = [0.0; 4];
        for c in 0..3 {
            out[c] = acc[c] / a * (1.0 - r) + bg[c] * r;
        }
        out[3] = 1.0 - r;
        f.output(0, out);
    }
}

impl Algorithm for Wboit {
    /// Neither k (it blends every fragment) nor a spin cap.
    fn reads(&self, _: crate::Param) -> bool {
        false
    }

    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "wboit",
            family: "baseline",
            summary: "weighted blended OIT: additive accumulation of weighted premultiplied colour and \
                      multiplicative revealage, one full-screen composite; approximate colour, exact coverage",
            source: "McGuire & Bavoil, Weighted Blended Order-Independent Transparency, JCGT 2(2) 2013 \
                     (eq. 6 composite, eq. 10 weight); the z-thickness seed's blended-OIT baseline [MB13] (sec. 2)",
            passes: "1 geometry + 1 full-screen",
            memory: "16 + 4 bytes (RGBA32F accum + R32F revealage; the paper's RGBA16F + R8 is 8 + 1 bytes)",
            hazard: HazardClass::HazardFree,
            capacity: Capacity::Image,
        }
    }

    fn run_frame(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        let n = pixels(frame);
        // The resolve skips the pixels no geometry reached (`with_untouched_output`).
        let device = common::fresh(exec).with_coverage(Coverage::Tracked);
        let mut fb = framebuffer(frame, SampleCount::X1, &[Format::RGBA32F, Format::R32F])?;
        fb.clear_color(0, [0; 4]);
        fb.clear_color(1, [1f32.to_bits(), 0, 0, 0]);
        let mut state = capture_state();
        let revealage_blend = BlendState {
            color_eq: BlendEquation::Add,
            alpha_eq: BlendEquation::Add,
            src_color: BlendFactor::Zero,
            dst_color: BlendFactor::OneMinusSrcColor,
            src_alpha: BlendFactor::Zero,
            dst_alpha: BlendFactor::OneMinusSrcAlpha,
            constant: [0.0; 4],
        };
        state.fragment.targets = vec![
            TargetState {
                blend: Some(BlendState::equation(BlendEquation::Add)),
                ..TargetState::new(Format::RGBA32F)
            },
            TargetState {
                blend: Some(revealage_blend),
                ..TargetState::new(Format::R32F)
            },
        ];
        let mut report = geometry_pass(
            &device,
            &mut fb,
            frame,
            &state,
            &Accumulate {
                alpha: params.alpha,
            },
            exec,
        )?;
        let accum = fb.image(0);
        let revealage = fb.image(1);

        let mut out_fb = resolve::framebuffer(frame)?;
        let kernel = Resolve {
            accum: &accum,
            revealage: &revealage,
            background: params.background,
        };
        report.merge(&resolve::pass(&device, &mut out_fb, &kernel, exec)?);
        // The image and the targets are read back and checked after the frame
        // ([`AlgoResult::deferred`]).
        let alpha = params.alpha;
        let deferred = Deferred::new(move |r: &mut AlgoResult| {
            let image = resolve::read_image(&out_fb);

            let acc: Vec<[f32; 4]> = accum.texels.iter().map(|t| t.map(f32::from_bits)).collect();
            let rev: Vec<f32> = revealage
                .texels
                .iter()
                .map(|t| f32::from_bits(t[0]))
                .collect();
            let first = |bad: &dyn Fn(usize) -> bool| (0..n).find(|&p| bad(p));
            let acc_bad = first(&|p| acc[p].iter().any(|v| !v.is_finite() || *v < 0.0));
            let rev_bad = first(&|p| !(0.0..=1.0).contains(&rev[p]));
            let cov_bad = first(&|p| (acc[p][3] > 0.0) != (rev[p] < 1.0) && alpha > 0.0);
            let img_bad = first(&|p| image[p].iter().any(|v| !v.is_finite()));
            let f16 = (0..n)
                .filter(|&p| acc[p].iter().any(|v| *v > F16_MAX))
                .count();
            let detail = |bad: Option<usize>, what: &str| match bad {
                Some(p) => format!("pixel {p}: {what} accum {:?}, revealage {}", acc[p], rev[p]),
                None => format!("{n} pixels"),
            };
            let checks = vec![
                Check::new(
                    "accumulator finite and non-negative",
                    acc_bad.is_none(),
                    detail(acc_bad, ""),
                ),
                Check::new(
                    "revealage in [0, 1]",
                    rev_bad.is_none(),
                    detail(rev_bad, ""),
                ),
                Check::new(
                    "coverage consistent: accumulated weight exactly where revealage < 1",
                    cov_bad.is_none(),
                    detail(cov_bad, ""),
                ),
                Check::new(
                    "composite finite everywhere",
                    img_bad.is_none(),
                    detail(img_bad, "image non-finite;"),
                ),
                Check::new(
                    "pixels whose accumulator would overflow RGBA16F (informational)",
                    true,
                    format!("{f16} pixels above {F16_MAX}"),
                ),
            ];
            r.image = Some(image);
            r.checks.extend(checks);
            Ok(())
        });
        Ok(AlgoResult {
            report,
            deferred: Some(deferred),
            // Accumulation targets (RGBA32F + R32F) and the resolve target.
            storage_bytes: n as u64 * (16 + 4 + resolve::TARGET_BYTES),
            ..Default::default()
        })
    }
}

#[cfg(test)]
mod tests {
    use fragrace_emu::{Mesh, Policy};

    use super::*;
    use crate::basic::Truth;
    use crate::oracle;
    use crate::testing::{frame_sized, tilted_quad};

    fn execs() -> Vec<ExecConfig> {
        let mut v = vec![ExecConfig::ordered(), ExecConfig::parallel(2)];
        for p in Policy::all() {
            v.push(ExecConfig::scheduled(p, 5));
        }
        v
    }

    #[test]
    fn one_layer_is_exact_under_every_executor() {
        let mut mesh = Mesh::default();
        tilted_quad(&mut mesh, [-0.8, 0.3, -0.9, 0.1], 0.2, 0.05);
        tilted_quad(&mut mesh, [0.35, 0.9, -0.2, 0.8], -0.4, 0.05);
        let frame = frame_sized(&mesh, 20, 16);
        let truth = Truth::capture(&frame, 1).unwrap();
        for alpha in [0.3, 0.75, 1.0] {
            let params = Params {
                alpha,
                ..Params::default()
            };
            for exec in execs() {
                let r = Wboit.run(&frame, &params, &exec).unwrap();
                for c in &r.checks {
                    assert!(c.passed, "{}: {}", c.name, c.detail);
                }
                let m = oracle::compare(&Wboit.info(), &r, &truth, &params);
                assert_eq!(
                    m.epr, 0.0,
                    "alpha {alpha} {:?}: {:?}",
                    exec.mode, m.first_error
                );
                // Background untouched where nothing was drawn.
                let img = r.image.as_ref().unwrap();
                let t = truth.capture.as_ref().unwrap();
                for (p, got) in img.iter().enumerate() {
                    if t.pixel(p).is_empty() {
                        assert_eq!(&got[..3], &params.background[..]);
                    }
                }
            }
        }
    }

    #[test]
    fn deep_pixels_are_approximate_but_finite_and_coverage_is_exact() {
        let mut mesh = Mesh::default();
        for i in 0..40 {
            let o = (i % 5) as f32 * 0.08;
            tilted_quad(
                &mut mesh,
                [-0.9 + o, 0.9 - o, -0.9 + o, 0.9],
                -0.95 + 0.045 * i as f32,
                0.05,
            );
        }
        let frame = frame_sized(&mesh, 16, 16);
        let truth = Truth::capture(&frame, 1).unwrap();
        let t = truth.capture.as_ref().unwrap();
        let params = Params::default();
        let mut reference: Option<Vec<[f32; 4]>> = None;
        for exec in execs() {
            let r = Wboit.run(&frame, &params, &exec).unwrap();
            for c in &r.checks {
                assert!(c.passed, "{}: {}", c.name, c.detail);
            }
            let img = r.image.clone().unwrap();
            // Coverage (alpha) matches the exact composite's within rounding.
            for (p, got) in img.iter().enumerate() {
                let want = common::composite_frags(t.pixel(p), params.alpha, params.background);
                assert!(
                    (got[3] - want[3]).abs() < 1e-5,
                    "pixel {p}: {} vs {}",
                    got[3],
                    want[3]
                );
            }
            // Fixed-function blending in API order: bit-identical under every executor.
            match &reference {
                None => reference = Some(img),
                Some(r0) => assert_eq!(r0, &img, "{:?}", exec.mode),
            }
            let m = oracle::compare(&Wboit.info(), &r, &truth, &params);
            assert!(
                m.epr > 0.0,
                "weighted blending is an approximation on deep pixels"
            );
            assert!(m
                .error_mask
                .iter()
                .enumerate()
                .all(|(p, &e)| !e || t.pixel(p).len() >= 2));
        }
    }

    #[test]
    fn weight_is_equation_10() {
        assert_eq!(weight(0.0, 1.0), 3e3);
        assert_eq!(weight(1.0, 0.5), 0.5e-2);
        assert!((weight(0.5, 1.0) - 375.0).abs() < 1e-3);
        assert!(weight(0.2, 0.3) > weight(0.4, 0.3));
    }

    #[test]
    fn near_layers_would_overflow_half_floats() {
        // 400 layers near the camera: accum.a = sum a * w ~ 400 * 0.3 * 0.3 * 3e3 * (1 - d)^3 ~ 1e5.
        let mut mesh = Mesh::default();
        for i in 0..400 {
            tilted_quad(
                &mut mesh,
                [-1.0, 1.0, -1.0, 1.0],
                -0.99 + 0.0001 * i as f32,
                0.0,
            );
        }
        let frame = frame_sized(&mesh, 4, 4);
        let r = Wboit
            .run(&frame, &Params::default(), &ExecConfig::ordered())
            .unwrap();
        let f16 = r
            .checks
            .iter()
            .find(|c| c.name.contains("RGBA16F"))
            .unwrap();
        assert_eq!(f16.detail, format!("16 pixels above {F16_MAX}"));
        assert!(r
            .image
            .unwrap()
            .iter()
            .all(|p| p.iter().all(|v| v.is_finite())));
    }
}
