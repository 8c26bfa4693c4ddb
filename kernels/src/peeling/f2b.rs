//! `f2b`: classic front-to-back depth peeling (Everitt, "Interactive order-independent
//! transparency", 2001; \[12\] of the depth-fighting paper, section 3.1.1 "Overview").
//!
//! "The algorithm starts by rendering the scene normally with a depth test, which returns the
//! closest per-pixel fragment to the observer. In a second pass, previously extracted
//! fragments are eliminated based on the depth value extracted during the last iteration
//! (pass) returning the next nearest layer underneath. The iteration loop halts either if it
//! reaches the maximum number of iterations set by the user or if no more fragments are
//! produced." (section 3.1.1)
//!
//! Each iteration is one geometry pass with the depth test `LESS` (depth buffer cleared past
//! every fragment) whose kernel discards fragments at or in front of the previous layer's
//! depth (read from the previous pass's RG32F target, bound read-only) and writes its depth
//! and primitive id to the target: the depth test keeps, per pixel, the nearest fragment
//! strictly behind the previous layer, the first in API order among equal depths.
//!
//! **Coplanarity.** "Fragments with depth identical to the depth layer detected in the
//! previous iteration are discarded and thus not considered" (section 3.1.1): of `c`
//! coplanar fragments one is peeled and `c - 1` are lost. Robustness ratio `R_h < 1` and EPR
//! above 0 wherever the scene has coplanar fragments (`cubes`, `coplanar-stack`); the same
//! loss under every executor (no shared memory: the depth test is API ordered). `dropped`
//! counts the companions of every layer a later pass met again: all of them when the peel
//! runs to the end, none of the `k`-th layer's when it stops at `k` (no pass follows it).
//!
//! **Invariants (checked on every run).** Each pixel's layers are strictly increasing in
//! depth; a peel run to the end accounts for every fragment (peeled, or lost as a coplanar
//! companion).

use fragrace_emu::{
    Buf, CompareFunc, DepthState, Format, Fragment, FragmentKernel, Image, KernelInfo, PassReport,
    PassState, TargetState,
};

use super::{texel_f32, Peeled};
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, CapturedFrag, Check, Frame, HazardClass,
    Params,
};
use crate::common::{capture_state, EMPTY};

/// One peel: the nearest fragment strictly behind the previous layer.
struct Peel<'i> {
    /// The previous layer (RG32F: depth, primitive bits); `None` in the first pass.
    prev: Option<&'i Image>,
    /// One word: fragments at exactly the previous layer's depth (the peeled one and its
    /// coplanar companions, which are lost), counted for the `dropped` figure.
    coplanar: Buf<u32>,
}

impl FragmentKernel for Peel<'_> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("f2b-peel").with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        let z = f.depth();
        if let Some(prev) = self.prev {
            // At or in front of the last peeled layer: peeled already, or coplanar with it
            // (the classic algorithm's loss, counted).
            let d = f32::from_bits(f.texel(prev, f.x(), f.y(), 0)[0]);
            if z <= d {
                if z == d {
                    f.atomic_add(self.coplanar, 0, 1).await;
                }
                f.discard();
                return;
            }
        }
        f.output(0, [z, f32::from_bits(f.primitive_id()), 0.0, 0.0]);
    }
}

/// The pass state of a peel: depth test `LESS` with writes, target 0 RG32F.
pub(super) fn peel_state() -> PassState {
    let mut s = capture_state();
    s.fragment.depth = DepthState {
        test: true,
        func: CompareFunc::Less,
        write: true,
    };
    s.fragment.targets = vec![TargetState::new(Format::RG32F)];
    s
}

/// `f2b`: see the module documentation.
pub struct F2b;

impl Algorithm for F2b {
    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "f2b",
            family: "depth peeling",
            summary: "classic front-to-back depth peeling: one geometry pass per layer, the depth test keeps the \
                      nearest fragment behind the last peeled layer; coplanar fragments collapse into one",
            source: "Everitt 2001 ([12] of the depth-fighting paper); depth-fighting paper, section 3.1.1 \
                     (Overview) and Table 1 (F2B)",
            passes: "1 geometry per layer (at most k), halted by an occlusion query",
            memory: "4 + 8 + 8 bytes: depth buffer, RG32F layer target (depth, primitive) and the previous \
                     layer bound read-only",
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
        let mut device = crate::common::fresh(exec);
        let coplanar = device.buffer::<u32>("f2b-coplanar", 1)?;
        let mut objects = super::culling::Objects::new(frame, params)?;
        let mut fb = peeled.framebuffer(&[Format::RG32F])?;
        let state = peel_state();
        let mut report = PassReport::default();
        let mut prev: Option<Image> = None;
        let mut not_increasing = 0u64;
        // Pixels peeled by a pass that another pass followed (which met the peeled fragment
        // again at its layer's depth), and by the last pass.
        let (mut revisited, mut last_gained) = (0u64, 0u64);
        let (mut kept, mut generated, mut exhausted) = (0u64, 0u64, false);
        while peeled.iterations < peeled.k {
            fb.clear_depth(f32::INFINITY);
            fb.clear_color(0, [f32::INFINITY.to_bits(), EMPTY, 0, 0]);
            let pass = objects.draw(
                &device,
                &mut fb,
                &state,
                &Peel {
                    prev: prev.as_ref(),
                    coplanar,
                },
                exec,
            )?;
            report.merge(&pass);
            revisited += last_gained;
            // The first pass draws every object (culling skips some later).
            generated = generated.max(pass.stats.fragments_generated);
            if pass.stats.samples_passed == 0 {
                exhausted = true;
                break;
            }
            peeled.iterations += 1;
            let layer = fb.image(0);
            let mut gained = 0u64;
            for (p, list) in peeled.lists.iter_mut().enumerate() {
                let t = texel_f32(&layer, p);
                if t[0] == f32::INFINITY {
                    continue;
                }
                if list.last().is_some_and(|l| l.depth >= t[0]) {
                    not_increasing += 1;
                }
                list.push(CapturedFrag {
                    depth: t[0],
                    prim: t[1].to_bits(),
                });
                gained += 1;
            }
            last_gained = gained;
            kept += gained;
            prev = Some(layer);
            objects.end_iteration(
                &device,
                super::culling::Remaining::DepthBuffer(&mut fb),
                exec,
                &mut report,
            )?;
        }
        let at_layers = u64::from(device.memory.read(coplanar)?[0]);
        let lost = at_layers.saturating_sub(revisited);
        let checks = vec![
            super::conservation(exhausted, kept + lost, generated),
            Check::new(
                "each pixel's layers strictly increase in depth",
                not_increasing == 0,
                format!("{not_increasing} layers not behind the one before"),
            ),
        ];
        let mut result = peeled.finish(report, checks, device.memory.bytes(), 20);
        // Coplanar companions of a peeled fragment: generated, never kept.
        result.dropped = lost;
        result.geometry_culling = objects.summary();
        Ok(result)
    }
}


/// The algorithms of this file, for its family's registry line.
pub(super) fn algorithms() -> Vec<Box<dyn crate::algo::Algorithm>> {
    vec![Box::new(F2b)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{frame, run};

    #[test]
    fn peels_the_nearest_layers_and_loses_exactly_the_coplanar_ones() {
        // The scene has coplanar quads: classic peeling loses fragments there.
        super::super::assert_same_loss_everywhere(&F2b);
    }

    #[test]
    fn exact_without_coplanarity() {
        // Quads at distinct depths only.
        let mut mesh = fragrace_emu::Mesh::default();
        for i in 0..6 {
            crate::testing::tilted_quad(
                &mut mesh,
                [-0.9 + 0.1 * i as f32, 0.8, -0.7, 0.9],
                -0.5 + 0.17 * ((i * 5) % 6) as f32,
                0.05,
            );
        }
        let f = frame(&mesh, 16);
        for k in [1, 3, 8] {
            let params = Params {
                k,
                ..Params::default()
            };
            let (r, m) = run(&F2b, &f, &params, &fragrace_emu::ExecConfig::parallel(2));
            assert_eq!(m.error_pixels, 0, "k = {k}: {:?}", m.first_error);
            assert_eq!(r.dropped, 0, "k = {k}: nothing coplanar, nothing lost");
            assert!(r.report.stats.geometry_passes <= k + 1);
        }
    }
}
