//! `f2b-3p`: the depth-fighting paper's three-pass variant of F2B-2P (section 3.1.1, "F2B-3P").
//!
//! "The idea is to carry out the first rendering pass of F2B-2P in two passes. A
//! double-speed depth rendering pass is performed to compute the (next) closest depth layer.
//! Then, by exploiting early-Z culling, we perform counting and identifier queries by
//! enabling blending, turning off depth writing and changing depth comparison direction to
//! EQUAL. ... Shading is performed in a subsequent pass by matching the fragments of the
//! extracted identifier set without modifying pixel-processing modes (blending or Z-test) of
//! the previous pass." (3.1.1)
//!
//! Per iteration, over one framebuffer whose depth buffer the three passes share:
//!
//! 1. **depth** (`LESS`, writes): the fragments not peeled yet — behind the current layer,
//!    or at it with an id strictly inside the range the last count pass found when that
//!    count was above two (its min and max were extracted) — and the depth test keeps the
//!    nearest: the current layer again while fragments are left there, else the next one;
//! 2. **count** (`EQUAL`, early, no depth writes; MAX on colour, ADD on alpha of an RGBA32F
//!    target): the non-peeled fragments of the layer write `(-id, id, 0, 1)`, as F2B-2P's
//!    second pass;
//! 3. **extract** (`EQUAL`, early; MAX on an RG32F target): the fragments whose id is the
//!    layer's min or max write their depth; the host takes them.
//!
//! The early depth test keeps the fragments of other layers out of the count and extract
//! kernels (the paper's point: "depth comparisons inside the shader are not needed"). Passes
//! not writing a target mask it (write mask 0), so the three targets live in one framebuffer
//! with the depth buffer. Same invariants and result as `f2b-2p` (exact, `R_h = 1`), one more
//! pass per iteration.

use fragrace_emu::{
    BlendEquation, BlendState, CompareFunc, DepthState, EarlyTests, Format, Fragment,
    FragmentKernel, Image, KernelInfo, PassReport, PassState, TargetState,
};

use super::{check_ids_fit_floats, texel_f32, Peeled};
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Frame, HazardClass, Params,
};
use crate::common::capture_state;

const NONE: f32 = f32::NEG_INFINITY;

/// Targets of the shared framebuffer.
const LAYER: usize = 0;
const IDS: usize = 1;
const EXTRACTED: usize = 2;

/// Whether a fragment at depth `z` with id `id` is not peeled yet, given the last layer
/// (`None` before the first) and its count pass's `(-id_min, id_max, _, count)`.
fn non_peeled(z: f32, id: f32, last: Option<(f32, [f32; 4])>) -> bool {
    match last {
        None => true,
        Some((d, [neg_min, max, _, count])) => {
            z > d || (z == d && count > 2.0 && id > -neg_min && id < max)
        }
    }
}

/// The last layer and its ids, as the passes read them.
#[derive(Clone, Copy)]
struct Last<'i> {
    layer: &'i Image,
    ids: &'i Image,
}

impl Last<'_> {
    fn at(&self, f: &impl Fragment) -> (f32, [f32; 4]) {
        let (x, y) = (f.x(), f.y());
        (
            f32::from_bits(f.texel(self.layer, x, y, 0)[0]),
            f.texel(self.ids, x, y, 0).map(f32::from_bits),
        )
    }
}

/// Pass 1: the next layer into the depth buffer (and the layer target).
struct DepthPass<'i> {
    last: Option<Last<'i>>,
}

impl FragmentKernel for DepthPass<'_> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("f2b-3p-depth").with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        let z = f.depth();
        let last = self.last.map(|l| l.at(&f));
        if !non_peeled(z, f.primitive_id() as f32, last) {
            f.discard();
            return;
        }
        f.output(LAYER, [z, 0.0, 0.0, 0.0]);
    }
}

/// Pass 2: ids and count of the layer's non-peeled fragments (depth test `EQUAL`).
struct CountPass<'i> {
    last: Option<Last<'i>>,
}

impl FragmentKernel for CountPass<'_> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("f2b-3p-count").with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        let id = f.primitive_id() as f32;
        let last = self.last.map(|l| l.at(&f));
        if !non_peeled(f.depth(), id, last) {
            f.discard();
            return;
        }
        f.output(IDS, [-id, id, 0.0, 1.0]);
    }
}

/// Pass 3: the fragments with the layer's min and max ids write their depth.
struct ExtractPass<'i> {
    ids: &'i Image,
}

impl FragmentKernel for ExtractPass<'_> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("f2b-3p-extract")
    }
    async fn shade(&self, f: impl Fragment) {
        let z = f.depth();
        let id = f.primitive_id() as f32;
        let [neg_min, max, ..] = f.texel(self.ids, f.x(), f.y(), 0).map(f32::from_bits);
        let pick = |hit: bool| if hit { z } else { NONE };
        f.output(EXTRACTED, [pick(-neg_min == id), pick(max == id), 0.0, 0.0]);
    }
}

/// The three targets, with only `written` unmasked.
fn targets(written: usize) -> Vec<TargetState> {
    let max = BlendState::equation(BlendEquation::Max);
    let mut t = vec![
        TargetState::new(Format::R32F),
        TargetState {
            blend: Some(BlendState {
                alpha_eq: BlendEquation::Add,
                ..max
            }),
            ..TargetState::new(Format::RGBA32F)
        },
        TargetState {
            blend: Some(max),
            ..TargetState::new(Format::RG32F)
        },
    ];
    for (i, target) in t.iter_mut().enumerate() {
        if i != written {
            target.write_mask = 0;
        }
    }
    t
}

/// `f2b-3p`: see the module documentation.
pub struct F2b3p;

impl Algorithm for F2b3p {
    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "f2b-3p",
            family: "depth peeling",
            summary: "F2B-2P in three passes per iteration: a depth pass finds the layer, EQUAL-tested count and \
                      extract passes (early-z keeps other layers out) find and take its smallest and largest \
                      unpeeled primitive ids",
            source: "depth-fighting paper, section 3.1.1 (F2B-3P) and Table 1",
            passes: "3 geometry per iteration (at most k), halted by an occlusion query",
            memory: "4 + 28 bytes: depth buffer, R32F layer, RGBA32F ids and count, RG32F extracted; + 20 bytes of \
                     the previous layer and ids read-only",
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
        let mut fb = peeled.framebuffer(&[Format::R32F, Format::RGBA32F, Format::RG32F])?;
        let mut depth_state = capture_state();
        depth_state.fragment.depth = DepthState {
            test: true,
            func: CompareFunc::Less,
            write: true,
        };
        depth_state.fragment.targets = targets(LAYER);
        let equal = |written| {
            let mut s: PassState = capture_state();
            s.fragment.depth = DepthState {
                test: true,
                func: CompareFunc::Equal,
                write: false,
            };
            s.fragment.early = EarlyTests::ForceEarly;
            s.fragment.targets = targets(written);
            s
        };
        let (count_state, extract_state) = (equal(IDS), equal(EXTRACTED));

        let mut report = PassReport::default();
        let mut last: Option<(Image, Image)> = None;
        let mut extraction = super::IdExtraction::default();
        let (mut generated, mut exhausted) = (0u64, false);
        while peeled.iterations < peeled.k {
            let view = last.as_ref().map(|(layer, ids)| Last { layer, ids });
            fb.clear_depth(f32::INFINITY);
            fb.clear_color(LAYER, [f32::INFINITY.to_bits(), 0, 0, 0]);
            fb.clear_color(IDS, [NONE.to_bits(), NONE.to_bits(), 0, 0]);
            fb.clear_color(EXTRACTED, [NONE.to_bits(), NONE.to_bits(), 0, 0]);
            let depth = objects.draw(
                &device,
                &mut fb,
                &depth_state,
                &DepthPass { last: view },
                exec,
            )?;
            report.merge(&depth);
            // The first pass draws every object (culling skips some later).
            generated = generated.max(depth.stats.fragments_generated);
            if depth.stats.samples_passed == 0 {
                exhausted = true;
                break;
            }
            report.merge(&objects.draw(
                &device,
                &mut fb,
                &count_state,
                &CountPass { last: view },
                exec,
            )?);
            let ids = fb.image(IDS);
            report.merge(&objects.draw(
                &device,
                &mut fb,
                &extract_state,
                &ExtractPass { ids: &ids },
                exec,
            )?);
            peeled.iterations += 1;
            let (layer, extracted) = (fb.image(LAYER), fb.image(EXTRACTED));
            for (p, list) in peeled.lists.iter_mut().enumerate() {
                let d = texel_f32(&layer, p)[0];
                extraction.take(list, d, texel_f32(&ids, p), texel_f32(&extracted, p));
            }
            last = Some((layer, ids));
            // Geometry culling: the depth buffer holds the layer just peeled.
            objects.end_iteration(
                &device,
                super::culling::Remaining::DepthBuffer(&mut fb),
                exec,
                &mut report,
            )?;
        }
        // The depth pass picks the layer itself: it cannot leave one early (`stalled` 0).
        let checks = extraction.checks(&peeled.lists, exhausted, generated, 0);
        let mut result = peeled.finish(report, checks, device.memory.bytes(), 52);
        result.geometry_culling = objects.summary();
        Ok(result)
    }
}


/// The algorithms of this file, for its family's registry line.
pub(super) fn algorithms() -> Vec<Box<dyn crate::algo::Algorithm>> {
    vec![Box::new(F2b3p)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{assert_exact_everywhere, frame, run};

    #[test]
    fn exact_under_every_executor_with_coplanar_fragments() {
        assert_exact_everywhere(&F2b3p, &Params::default(), 1);
    }

    #[test]
    fn peels_a_coplanar_stack_as_f2b_2p_does() {
        let mesh = crate::testing::coplanar_stack(7);
        let f = frame(&mesh, 8);
        let (r, m) = run(
            &F2b3p,
            &f,
            &Params::default(),
            &fragrace_emu::ExecConfig::ordered(),
        );
        assert_eq!(m.error_pixels, 0, "{:?}", r.checks);
        let c = r.capture.as_ref().unwrap();
        let ids: Vec<u32> = c.pixel(4 * 8 + 4).iter().map(|f| f.prim / 2).collect();
        assert_eq!(ids, vec![0, 1, 2, 3, 4, 5, 6]);
        // 4 iterations of 3 passes, and the depth pass that finds nothing left.
        assert_eq!(r.report.stats.geometry_passes, 13);
    }
}
