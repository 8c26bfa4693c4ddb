//! `f2b2`: the two-pass front-to-back peeling of the depth-fighting paper's results
//! (section 4, "F2B2"): a double-speed depth pass, then an early-z pass with the depth test
//! `EQUAL`.
//!
//! "For the purposes of comparison, we have developed F2B2; a two-pass variation of F2B that
//! uses double speed Z-pass and early Z-culling optimizations." (section 4) Its two passes
//! are the pre-Z technique of section 3.1.1: "a double-speed rendering pass is firstly
//! employed to fill the depth buffer with the scene depth values by depth testing and
//! turning off color writing. Shading the scene with depth write disabled, results on
//! enabling early-Z culling; a component which automatically rejects fragments that do not
//! pass the depth test." Per iteration, over one framebuffer:
//!
//! 1. **depth** (`LESS` with writes, no colour target: double speed): fragments at or in front
//!    of the previous layer are discarded (its depth, the depth buffer of the previous
//!    iteration copied to a texture, bound read-only), so the depth buffer ends holding the
//!    next layer; its occlusion query ends the loop when it passes nothing;
//! 2. **shade** (`EQUAL`, early, no depth writes): every fragment at the layer's depth is
//!    shaded. Blending accumulates the front-to-back composite in an RGBA32F target ("under":
//!    colour `src x dst.alpha + dst`, alpha `dst.alpha x (1 - src.alpha)`, the alpha holding
//!    the transmittance), and ADD blending counts the layer's fragments in an R32F target.
//!
//! **Coplanarity.** Unlike F2B's depth test, the `EQUAL` test passes *every* fragment at the
//! layer's depth, so a coplanar group is shaded whole in one iteration: `R_h = 1` on
//! `coplanar-stack`, where `f2b` keeps one of eight. The fixed-function blend stage sees a
//! pixel's fragments in API order, which for equal depths is primitive order, the truth's;
//! so the blended image is the exact front-to-back composite of the peeled layers, the same
//! under every executor.
//!
//! **What is kept.** The shading pass leaves per pixel a depth (the depth buffer) and a count,
//! not which primitives were at that depth: the capture holds `count` fragments at the
//! layer's depth with no primitive id (`prim = u32::MAX`, as the bucket schemes), which the
//! oracle's `k-nearest` rule compares by depth; the image is the blended composite, not one
//! recomposed on the host. As the other front-to-back peelers it runs at most `k`
//! iterations; the image holds every fragment of the layers peeled (the capture keeps the
//! first `k`).
//!
//! **Invariants (checked on every run).** Each pixel's layers strictly increase in depth; a
//! peel run to the end accounts for every fragment; the composite's transmittance is
//! `(1 - alpha)^n` for the `n` fragments the count target saw (blend and count agree).

use fragrace_emu::{
    BlendEquation, BlendFactor, BlendState, CompareFunc, DepthState, EarlyTests, Format, Fragment,
    FragmentKernel, Framebuffer, Image, KernelInfo, PassReport, PassState, TargetState,
};

use super::Peeled;
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, CapturedFrag, Check, Frame, HazardClass,
    Params,
};
use crate::common::{capture_state, prim_rgb};

/// Targets of the framebuffer.
const COMPOSITE: usize = 0;
const COUNT: usize = 1;

/// Pass 1: the next layer into the depth buffer; no colour.
struct DepthPass<'i> {
    /// The previous layer (R32F depth, `+inf` where the pixel had none).
    prev: Option<&'i Image>,
}

impl FragmentKernel for DepthPass<'_> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("f2b2-depth").with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        if let Some(prev) = self.prev {
            if f.depth() <= f32::from_bits(f.texel(prev, f.x(), f.y(), 0)[0]) {
                f.discard();
            }
        }
    }
}

/// Pass 2: every fragment at the layer, shaded (premultiplied colour, opacity) and counted.
struct ShadePass {
    alpha: f32,
}

impl FragmentKernel for ShadePass {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("f2b2-shade")
    }
    async fn shade(&self, f: impl Fragment) {
        let c = prim_rgb(f.primitive_id());
        let a = self.alpha;
        f.output(COMPOSITE, [c[0] * a, c[1] * a, c[2] * a, a]);
        f.output(COUNT, [1.0, 0.0, 0.0, 0.0]);
    }
}

/// The depth buffer as an R32F image (a depth texture for the next iteration).
fn depth_image(fb: &Framebuffer) -> Image {
    let mut texels = Vec::with_capacity(fb.width as usize * fb.height as usize);
    for y in 0..fb.height {
        for x in 0..fb.width {
            texels.push([fb.depth(x, y, 0).to_bits(), 0, 0, 0]);
        }
    }
    Image {
        width: fb.width,
        height: fb.height,
        samples: 1,
        format: Format::R32F,
        texels,
    }
}

/// The two pass states: depth (`LESS`, writes, no target) and shade (`EQUAL`, early, the
/// under-blended composite and the ADD-blended count).
fn states() -> (PassState, PassState) {
    let mut depth = capture_state();
    depth.fragment.depth = DepthState {
        test: true,
        func: CompareFunc::Less,
        write: true,
    };
    let mut shade = capture_state();
    shade.fragment.depth = DepthState {
        test: true,
        func: CompareFunc::Equal,
        write: false,
    };
    shade.fragment.early = EarlyTests::ForceEarly;
    let under = BlendState {
        color_eq: BlendEquation::Add,
        alpha_eq: BlendEquation::Add,
        src_color: BlendFactor::DstAlpha,
        dst_color: BlendFactor::One,
        src_alpha: BlendFactor::Zero,
        dst_alpha: BlendFactor::OneMinusSrcAlpha,
        constant: [0.0; 4],
    };
    shade.fragment.targets = vec![
        TargetState {
            blend: Some(under),
            ..TargetState::new(Format::RGBA32F)
        },
        TargetState {
            blend: Some(BlendState::equation(BlendEquation::Add)),
            ..TargetState::new(Format::R32F)
        },
    ];
    (depth, shade)
}

/// `f2b2`: see the module documentation.
pub struct F2b2;

impl Algorithm for F2b2 {
    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "f2b2",
            family: "depth peeling",
            summary: "two-pass front-to-back peeling: a double-speed depth pass finds the next layer, an \
                      EQUAL-tested early-z pass shades all of its fragments (coplanar ones too) into a blended \
                      composite and a count",
            source: "depth-fighting paper, section 4 (F2B2) and section 3.1.1 (pre-Z pass); Table 1",
            passes: "2 geometry per layer (at most k), halted by the depth pass's occlusion query",
            memory: "4 + 16 + 4 bytes: depth buffer, RGBA32F composite, R32F count; + 4 bytes of the previous \
                     layer's depth read-only",
            hazard: HazardClass::HazardFree,
            capacity: Capacity::KNearest,
        }
    }

    fn takes_geometry_culling(&self) -> bool {
        true
    }

    fn run_frame(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &fragrace_emu::ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        let mut peeled = Peeled::new(frame, params)?;
        let device = crate::common::fresh(exec);
        let mut objects = super::culling::Objects::new(frame, params)?;
        let mut fb = peeled.framebuffer(&[Format::RGBA32F, Format::R32F])?;
        let (depth_state, shade_state) = states();
        let shade = ShadePass {
            alpha: params.alpha,
        };
        fb.clear_color(COMPOSITE, [0, 0, 0, 1.0f32.to_bits()]);
        let mut report = PassReport::default();
        let mut prev: Option<Image> = None;
        let (mut generated, mut exhausted) = (0u64, false);
        let (mut shaded, mut counted, mut not_increasing) = (0u64, 0u64, 0u64);
        let mut blended = vec![0u32; peeled.lists.len()];
        while peeled.iterations < peeled.k {
            fb.clear_depth(f32::INFINITY);
            let pass = objects.draw(
                &device,
                &mut fb,
                &depth_state,
                &DepthPass {
                    prev: prev.as_ref(),
                },
                exec,
            )?;
            report.merge(&pass);
            // The first pass draws every object (culling skips some later).
            generated = generated.max(pass.stats.fragments_generated);
            if pass.stats.samples_passed == 0 {
                exhausted = true;
                break;
            }
            fb.clear_color(COUNT, [0; 4]);
            let pass = objects.draw(&device, &mut fb, &shade_state, &shade, exec)?;
            report.merge(&pass);
            shaded += pass.stats.samples_passed;
            peeled.iterations += 1;
            let layer = depth_image(&fb);
            let count = fb.image(COUNT);
            for (p, list) in peeled.lists.iter_mut().enumerate() {
                let n = f32::from_bits(count.texels[p][0]) as u32;
                if n == 0 {
                    continue;
                }
                let d = f32::from_bits(layer.texels[p][0]);
                if list.last().is_some_and(|l| l.depth >= d) {
                    not_increasing += 1;
                }
                list.extend((0..n).map(|_| CapturedFrag {
                    depth: d,
                    prim: u32::MAX,
                }));
                blended[p] += n;
                counted += u64::from(n);
            }
            prev = Some(layer);
            objects.end_iteration(
                &device,
                super::culling::Remaining::DepthBuffer(&mut fb),
                exec,
                &mut report,
            )?;
        }
        let composite = fb.image(COMPOSITE);
        let a = params.alpha;
        let bg = params.background;
        let mut transmittance_off = 0u64;
        let image: Vec<[f32; 4]> = composite
            .texels
            .iter()
            .zip(&blended)
            .map(|(t, &n)| {
                let [r, g, b, t] = t.map(f32::from_bits);
                // `composite`'s transmittance, multiplied in the same order.
                let want = (0..n).fold(1.0f32, |t, _| t * (1.0 - a));
                transmittance_off += u64::from(t != want);
                [r + bg[0] * t, g + bg[1] * t, b + bg[2] * t, 1.0 - t]
            })
            .collect();
        let checks = vec![
            super::conservation(exhausted, counted, generated),
            Check::new(
                "each pixel's layers strictly increase in depth",
                not_increasing == 0,
                format!("{not_increasing} layers not behind the one before"),
            ),
            Check::new(
                "the count target holds every fragment shaded, and the composite's transmittance is (1 - \
                 alpha)^count",
                counted == shaded && transmittance_off == 0,
                format!(
                    "{counted} counted of {shaded} shaded; {transmittance_off} pixels whose blended \
                     transmittance is not (1 - alpha)^count"
                ),
            ),
        ];
        let mut result = peeled.finish(report, checks, device.memory.bytes(), 28);
        result.image = Some(image);
        result.geometry_culling = objects.summary();
        Ok(result)
    }
}

/// The algorithms of this file, for its family's registry line.
pub(super) fn algorithms() -> Vec<Box<dyn crate::algo::Algorithm>> {
    vec![Box::new(F2b2)]
}

#[cfg(test)]
mod tests {
    use fragrace_emu::ExecConfig;

    use super::*;
    use crate::testing::{assert_checks, executors, frame, quads, run};

    #[test]
    fn exact_under_every_executor_with_coplanar_fragments() {
        let mesh = quads(16);
        let params = Params {
            k: 32,
            ..Params::default()
        };
        for size in [8, 16] {
            let f = frame(&mesh, size);
            for (what, exec) in executors(1) {
                let (r, m) = run(&F2b2, &f, &params, &exec);
                let what = format!("{size} x {size} under {what}");
                assert_eq!(m.error_pixels, 0, "{what}: {:?}", m.first_error);
                assert_eq!(m.robustness, 1.0, "{what}");
                assert_checks(&r, &what);
                // Every layer peeled: the blended image is the truth's composite, bit for bit.
                let image = m.image.as_ref().expect("image metrics");
                assert_eq!(image.max_diff, 0.0, "{what}");
            }
        }
    }

    #[test]
    fn a_coplanar_stack_is_one_layer_where_f2b_keeps_one_fragment() {
        let mesh = crate::testing::coplanar_stack(8);
        let f = frame(&mesh, 8);
        let (r, m) = run(&F2b2, &f, &Params::default(), &ExecConfig::ordered());
        assert_eq!(m.error_pixels, 0, "{:?}", r.checks);
        assert_eq!(m.robustness, 1.0);
        // One layer: depth + shade, then the depth pass that finds nothing.
        assert_eq!(r.report.stats.geometry_passes, 3);
        let (_, m) = run(
            &super::super::f2b::F2b,
            &f,
            &Params::default(),
            &ExecConfig::ordered(),
        );
        assert_eq!(m.robustness, 1.0 / 8.0);
    }
}
