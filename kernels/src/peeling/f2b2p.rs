//! `f2b-2p`: the depth-fighting paper's two-pass coplanarity-aware front-to-back peeling
//! (section 3.1.1, Algorithm 1 "F2B-2P Depth Peeling").
//!
//! F2B peels one fragment per layer and loses the rest of a coplanar group. F2B-2P stays at
//! a layer until all of its fragments are peeled, two per iteration: the ones with the
//! smallest and the largest primitive id among the fragments of the layer not peeled yet.
//! "We define as non-peeled a fragment f that has a primitive identifier in the range of the
//! identifiers determined during the previous step" (3.1.1): the open range
//! `(id_min, id_max)` of the previous iteration shrinks each time, so no fragment is peeled
//! twice and none is skipped.
//!
//! Each iteration has the paper's two geometry passes, depth test off, blending on:
//!
//! 1. **Peel** (MAX blending): fragments in front of the current layer are discarded; the
//!    fragments whose id is the layer's `id_min` or `id_max` write their depth (the paper
//!    writes their colour: what is extracted); every fragment writes `-depth` to the
//!    next-layer target, except fragments *at* the current layer when the layer is finished
//!    (counter `<= 2`), so MAX picks the current layer again when fragments are left there,
//!    else the nearest one behind it. (The paper writes `-1.0` for "none", which a fragment
//!    at depth 1.0 would also write; this crate uses `-inf`.)
//! 2. **Count** (MAX on the colour channels, ADD on alpha, one RGBA32F target as the paper's):
//!    the fragments at the next layer that are non-peeled write `(-id, id, 0, 1)`: the new
//!    `id_min` (negated, so that MAX finds the minimum), `id_max` and the count.
//!
//! The first iteration is preceded by a pass that finds the nearest layer (the paper:
//! "Initially, we render the scene so as to efficiently capture only the closest depth
//! layer before proceeding with the counter and identifier computation pass") and its count
//! pass. The loop ends when a count pass passes no sample (nothing left anywhere), or after
//! `k` iterations (each peels at least one fragment of every unfinished pixel).
//!
//! Primitive ids travel through float targets, exact below 2^24 primitives (checked).
//!
//! **Invariants (checked on every run).** Every extracted fragment is found at its layer's
//! depth (the peel pass met the ids the count pass chose); no fragment is extracted twice;
//! layers never go backwards. Robust: `R_h = 1` and EPR 0 on every scene, coplanar or not
//! (asserted by the differential harness). No shared memory: the same under every executor.

use fragrace_emu::{
    BlendEquation, BlendState, Format, Fragment, FragmentKernel, Image, KernelInfo,
    PassReport, PassState, TargetState,
};

use super::{check_ids_fit_floats, texel_f32, Peeled};
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Frame, HazardClass, Params,
};
use crate::common::capture_state;

const NONE: f32 = f32::NEG_INFINITY;

/// Pass 1 of Algorithm 1 (and, with no current layer, the initial nearest-layer pass).
struct Peel<'i> {
    /// Current layer and its ids: (R32F `-depth`, RGBA32F `(-id_min, id_max, 0, count)`).
    current: Option<(&'i Image, &'i Image)>,
}

impl FragmentKernel for Peel<'_> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("f2b-2p-peel").with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        let z = f.depth();
        let Some((layer, ids)) = self.current else {
            // The initial pass: the nearest layer.
            f.output(0, [NONE, NONE, 0.0, 0.0]);
            f.output(1, [-z, 0.0, 0.0, 0.0]);
            return;
        };
        let (x, y) = (f.x(), f.y());
        let d = -f32::from_bits(f.texel(layer, x, y, 0)[0]);
        if z < d {
            f.discard();
            return;
        }
        let [id_min, id_max, _, count] = f.texel(ids, x, y, 0).map(f32::from_bits);
        let id = f.primitive_id() as f32;
        let at_layer = z == d;
        let min_out = if at_layer && -id_min == id { z } else { NONE };
        let max_out = if at_layer && id_max == id { z } else { NONE };
        f.output(0, [min_out, max_out, 0.0, 0.0]);
        let next = if count > 2.0 || !at_layer { -z } else { NONE };
        f.output(1, [next, 0.0, 0.0, 0.0]);
    }
}

/// Pass 2 of Algorithm 1: ids and count of the non-peeled fragments at the next layer.
struct Count<'i> {
    /// The next layer (R32F `-depth`).
    layer: &'i Image,
    /// The previous count pass's ids (`None` before the first layer).
    prev: Option<&'i Image>,
}

impl FragmentKernel for Count<'_> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("f2b-2p-count").with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        let z = f.depth();
        let (x, y) = (f.x(), f.y());
        let id = f.primitive_id() as f32;
        let d = -f32::from_bits(f.texel(self.layer, x, y, 0)[0]);
        let non_peeled = match self.prev {
            None => true,
            Some(prev) => {
                let [id_min, id_max, _, count] = f.texel(prev, x, y, 0).map(f32::from_bits);
                count <= 2.0 || (id > -id_min && id < id_max)
            }
        };
        if non_peeled && z == d {
            f.output(0, [-id, id, 0.0, 1.0]);
        } else {
            f.discard();
        }
    }
}

fn max_target(format: Format) -> TargetState {
    TargetState {
        blend: Some(BlendState::equation(BlendEquation::Max)),
        ..TargetState::new(format)
    }
}

/// `f2b-2p`: see the module documentation.
pub struct F2b2p;

impl Algorithm for F2b2p {
    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "f2b-2p",
            family: "depth peeling",
            summary: "coplanarity-aware front-to-back peeling: two passes per iteration peel the smallest and largest \
                      primitive id of the current layer's unpeeled fragments (MAX/ADD blending), staying at a layer \
                      until it is empty",
            source: "depth-fighting paper, section 3.1.1 (F2B-2P, Algorithm 1) and Table 1",
            passes: "2 geometry (nearest layer, count) + 2 geometry per iteration (at most k iterations), halted \
                     by an occlusion query",
            memory: "32 bytes of targets: R32F layer, RGBA32F ids and count (the paper's extra RGBA_32F texture), \
                     RG32F extracted, R32F next layer; + 20 bytes of the previous passes' images bound read-only",
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
        check_ids_fit_floats(frame)?;
        let mut peeled = Peeled::new(frame, params)?;
        let device = crate::common::fresh(exec);
        let mut objects = super::culling::Objects::new(frame, params)?;
        let mut peel_fb = peeled.framebuffer(&[Format::RG32F, Format::R32F])?;
        let mut count_fb = peeled.framebuffer(&[Format::RGBA32F])?;
        let peel_state = PassState {
            fragment: fragrace_emu::FragmentState {
                targets: vec![max_target(Format::RG32F), max_target(Format::R32F)],
                ..capture_state().fragment
            },
            ..capture_state()
        };
        let mut count_state = capture_state();
        count_state.fragment.targets = vec![TargetState {
            blend: Some(BlendState {
                alpha_eq: BlendEquation::Add,
                ..BlendState::equation(BlendEquation::Max)
            }),
            ..TargetState::new(Format::RGBA32F)
        }];
        let mut report = PassReport::default();
        let mut peel = |current: Option<(&Image, &Image)>,
                        objects: &mut super::culling::Objects<'_>,
                        report: &mut PassReport|
         -> Result<(Image, Image), AlgoError> {
            peel_fb.clear_color(0, [NONE.to_bits(), NONE.to_bits(), 0, 0]);
            peel_fb.clear_color(1, [NONE.to_bits(), 0, 0, 0]);
            report.merge(&objects.draw(
                &device,
                &mut peel_fb,
                &peel_state,
                &Peel { current },
                exec,
            )?);
            Ok((peel_fb.image(0), peel_fb.image(1)))
        };
        let mut count = |layer: &Image,
                         prev: Option<&Image>,
                         objects: &mut super::culling::Objects<'_>,
                         report: &mut PassReport|
         -> Result<(Image, PassReport), AlgoError> {
            count_fb.clear_color(0, [NONE.to_bits(), NONE.to_bits(), 0, 0]);
            let pass = objects.draw(
                &device,
                &mut count_fb,
                &count_state,
                &Count { layer, prev },
                exec,
            )?;
            report.merge(&pass);
            Ok((count_fb.image(0), pass))
        };
        // Geometry culling: an object is done when its box lies in front of the current
        // layer (`-depth` in R32F; `-inf`, i.e. `+inf`, where nothing is left).
        let layer_depth = |t: [u32; 4]| -f32::from_bits(t[0]);

        let (_, mut layer) = peel(None, &mut objects, &mut report)?;
        let (mut ids, mut counted) = count(&layer, None, &mut objects, &mut report)?;
        let mut extraction = super::IdExtraction::default();
        let mut stalled = 0u64;
        let generated = counted.stats.fragments_generated;
        while counted.stats.samples_passed > 0 && peeled.iterations < peeled.k {
            let (extracted, next) = peel(Some((&layer, &ids)), &mut objects, &mut report)?;
            peeled.iterations += 1;
            for (p, list) in peeled.lists.iter_mut().enumerate() {
                let d = -texel_f32(&layer, p)[0];
                let n = extraction.take(list, d, texel_f32(&ids, p), texel_f32(&extracted, p));
                let next_d = -texel_f32(&next, p)[0];
                if n > 2.0 && next_d != d {
                    // Fragments left at the layer, yet the peel moved on.
                    stalled += 1;
                }
            }
            layer = next;
            objects.end_iteration(
                &device,
                super::culling::Remaining::Front {
                    image: &layer,
                    depth: layer_depth,
                },
                exec,
                &mut report,
            )?;
            if peeled.iterations < peeled.k {
                (ids, counted) = count(&layer, Some(&ids), &mut objects, &mut report)?;
            }
        }
        let exhausted = counted.stats.samples_passed == 0;
        let checks = extraction.checks(&peeled.lists, exhausted, generated, stalled);
        let mut result = peeled.finish(report, checks, device.memory.bytes(), 52);
        result.geometry_culling = objects.summary();
        Ok(result)
    }
}


/// The algorithms of this file, for its family's registry line.
pub(super) fn algorithms() -> Vec<Box<dyn crate::algo::Algorithm>> {
    vec![Box::new(F2b2p)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{assert_exact_everywhere, frame, run};

    #[test]
    fn exact_under_every_executor_with_coplanar_fragments() {
        assert_exact_everywhere(&F2b2p, &Params::default(), 1);
    }

    #[test]
    fn a_deep_coplanar_stack_is_peeled_two_by_two() {
        // Seven identical quads: one layer of 7 coplanar fragments per pixel.
        let mesh = crate::testing::coplanar_stack(7);
        let f = frame(&mesh, 8);
        let (r, m) = run(
            &F2b2p,
            &f,
            &Params::default(),
            &fragrace_emu::ExecConfig::ordered(),
        );
        assert_eq!(m.error_pixels, 0, "{:?}", r.checks);
        // 7 per pixel, two per iteration (the ends of the shrinking id range): 4 iterations
        // of 2 passes after the initial 2. The two triangles of quad q are 2q, 2q+1.
        let c = r.capture.as_ref().unwrap();
        let p = (4 * 8 + 4) as usize;
        let ids: Vec<u32> = c.pixel(p).iter().map(|f| f.prim / 2).collect();
        assert_eq!(ids, vec![0, 1, 2, 3, 4, 5, 6]);
        assert_eq!(r.report.stats.geometry_passes, 10);
    }
}
