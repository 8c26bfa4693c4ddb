//! `dual-2p`: the depth-fighting paper's coplanarity-aware dual depth peeling (section
//! 3.1.2, "DUAL-2P"): F2B-2P (Algorithm 1) run in both directions at once.
//!
//! "To handle coplanarity issues raised at both directions, we have developed a variation of
//! DUAL (DUAL-2P), which adapts the F2B-2P algorithm for working concurrently in both
//! directions. ... DUAL-2P depth peeling as compared to the F2B-2P and F2B-3P variations,
//! reduces the rendering cost to half by extracting up to four fragments simultaneously. The
//! burden for providing this feature is that it requires twice as much memory space."
//! (3.1.2)
//!
//! A pixel's state between iterations is DUAL's min-max range `(near, far)` plus, for each
//! end, F2B-2P's count-pass texel `(-id_min, id_max, 0, count)` of the fragments at that end
//! not peeled yet (the front one at `near`, the back one at `far`; a range of one depth has
//! only a front). A fragment is *non-peeled* when it lies strictly inside the range, or at an
//! end whose count was above two with its id strictly inside that end's id range (the open
//! ranges shrink, so no fragment is peeled twice; Algorithm 1's argument per end). Each
//! iteration has F2B-2P's two geometry passes, depth test off, blending on:
//!
//! 1. **Peel** (MAX blending): fragments outside the range are discarded; at the near end the
//!    fragments whose id is the front `id_min` or `id_max` write their depth to the extracted
//!    target's first two channels, at the far end the back ones to its last two (up to four
//!    fragments per pixel and iteration); every non-peeled fragment writes `(-z, z)` to the
//!    next-range target, so MAX finds the nearest and farthest fragments still to peel (the
//!    same ends again while more than two fragments were left there).
//! 2. **Count** (MAX on the colour channels, ADD on alpha, two RGBA32F targets): the
//!    non-peeled fragments at the next near end write `(-id, id, 0, 1)` to the front target,
//!    those at the next far end (when it is not the near end) to the back target.
//!
//! A first peel pass with no range (every fragment writes `(-z, z)`) and its count pass start
//! the loop, which ends when the peel pass leaves no range anywhere (read back, as DUAL).
//! Every layer is peeled (`Capacity::All`; `k` does not apply). The host appends each
//! iteration's front extractions to the pixel's list and its back ones to a back list, which
//! is appended reversed at the end. Primitive ids travel through float targets, exact below
//! 2^24 primitives (checked).
//!
//! **Invariants (checked on every run).** Every extracted fragment is found at its end's
//! depth; no fragment is extracted twice; fronts increase and backs decrease, fronts before
//! backs; an end stays while more than two fragments are left there; a peel run to the end
//! accounts for every fragment. Robust: `R_h = 1` and EPR 0 on every scene, coplanar or not.
//! No shared memory: the same under every executor.

use fragrace_emu::{
    BlendEquation, BlendState, Format, Fragment, FragmentKernel, Image, KernelInfo,
    PassReport, TargetState,
};

use super::{check_ids_fit_floats, texel_f32, IdExtraction, Peeled};
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, CapturedFrag, Check, Frame, HazardClass,
    Params,
};
use crate::common::capture_state;

const NONE: f32 = f32::NEG_INFINITY;
const NO_IDS: [f32; 4] = [NONE, NONE, 0.0, 0.0];

/// Safety bound on iterations: every iteration peels at least one fragment of each pixel
/// with a range left.
const MAX_ITERATIONS: u32 = 1 << 20;

/// A pixel's state after an iteration: the range and each end's ids, as images.
#[derive(Clone, Copy)]
struct State<'i> {
    /// RG32F `(-near, far)`.
    range: &'i Image,
    /// RGBA32F `(-id_min, id_max, 0, count)` of the near end's non-peeled fragments.
    front: &'i Image,
    /// The same for the far end.
    back: &'i Image,
}

/// One pixel's state, as a fragment reads it.
struct Texels {
    near: f32,
    far: f32,
    front: [f32; 4],
    back: [f32; 4],
}

impl State<'_> {
    fn at(&self, f: &impl Fragment) -> Texels {
        let (x, y) = (f.x(), f.y());
        let [neg_near, far, ..] = f.texel(self.range, x, y, 0).map(f32::from_bits);
        Texels {
            near: -neg_near,
            far,
            front: f.texel(self.front, x, y, 0).map(f32::from_bits),
            back: f.texel(self.back, x, y, 0).map(f32::from_bits),
        }
    }
}

/// Whether `id` is strictly inside an end's id range that has more than two fragments
/// (Algorithm 1's non-peeled test at that end).
fn left_at_end(id: f32, [neg_min, max, _, count]: [f32; 4]) -> bool {
    count > 2.0 && id > -neg_min && id < max
}

/// Whether the fragment `(z, id)` is not peeled yet after the iteration that `t` describes
/// (`None`: before the first one).
fn non_peeled(z: f32, id: f32, t: Option<&Texels>) -> bool {
    match t {
        None => true,
        Some(t) if z < t.near || z > t.far => false,
        // The near end wins when the range is one depth.
        Some(t) if z == t.near => left_at_end(id, t.front),
        Some(t) if z == t.far => left_at_end(id, t.back),
        Some(_) => true,
    }
}

/// Pass 1: extract each end's smallest and largest unpeeled id; the next range.
struct Peel<'i> {
    state: Option<State<'i>>,
}

impl FragmentKernel for Peel<'_> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("dual-2p-peel").with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        let z = f.depth();
        let id = f.primitive_id() as f32;
        let t = self.state.map(|s| s.at(&f));
        if let Some(t) = &t {
            if z < t.near || z > t.far {
                f.discard();
                return;
            }
        }
        let pick = |ids: [f32; 4]| {
            let [neg_min, max, ..] = ids;
            (
                if -neg_min == id { z } else { NONE },
                if max == id { z } else { NONE },
            )
        };
        let mut extracted = [NONE; 4];
        match &t {
            Some(t) if z == t.near => (extracted[0], extracted[1]) = pick(t.front),
            Some(t) if z == t.far => (extracted[2], extracted[3]) = pick(t.back),
            _ => {}
        }
        f.output(1, extracted);
        let next = if non_peeled(z, id, t.as_ref()) {
            [-z, z, 0.0, 0.0]
        } else {
            NO_IDS
        };
        f.output(0, next);
    }
}

/// Pass 2: ids and count of the non-peeled fragments at each end of the next range.
struct Count<'i> {
    /// The next range (RG32F `(-near, far)`).
    next: &'i Image,
    /// The state the peel pass used (`None` before the first).
    prev: Option<State<'i>>,
}

impl FragmentKernel for Count<'_> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("dual-2p-count").with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        let z = f.depth();
        let id = f.primitive_id() as f32;
        let [neg_near, far, ..] = f.texel(self.next, f.x(), f.y(), 0).map(f32::from_bits);
        let t = self.prev.map(|s| s.at(&f));
        if !non_peeled(z, id, t.as_ref()) {
            f.discard();
            return;
        }
        let ids = [-id, id, 0.0, 1.0];
        if z == -neg_near {
            f.output(0, ids);
            f.output(1, NO_IDS);
        } else if z == far {
            f.output(0, NO_IDS);
            f.output(1, ids);
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

/// `dual-2p`: see the module documentation.
pub struct Dual2p;

impl Algorithm for Dual2p {
    /// Peels until the range is empty; k does not apply.
    fn reads(&self, _: crate::Param) -> bool {
        false
    }

    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "dual-2p",
            family: "depth peeling",
            summary: "coplanarity-aware dual depth peeling: F2B-2P at both ends of a min-max range at once, two \
                      passes per iteration peel the smallest and largest unpeeled primitive id at the near and at \
                      the far end (up to four fragments), staying at an end until it is empty",
            source: "depth-fighting paper, section 3.1.2 (DUAL-2P) and Table 1",
            passes: "2 geometry (initial range, count) + 2 geometry per iteration, the last count pass skipped \
                     when no range is left; k does not apply",
            memory: "56 bytes of targets: RG32F range, RGBA32F extracted (two per end), two RGBA32F ids and count \
                     (front, back); + 40 bytes of the previous range and ids read-only (Table 1, DUAL-2P: 24 \
                     words)",
            hazard: HazardClass::HazardFree,
            capacity: Capacity::All,
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
        let mut peeled = Peeled::unbounded(frame, params);
        let device = crate::common::fresh(exec);
        let mut objects = super::culling::Objects::new(frame, params)?;
        let mut peel_fb = peeled.framebuffer(&[Format::RG32F, Format::RGBA32F])?;
        let mut count_fb = peeled.framebuffer(&[Format::RGBA32F, Format::RGBA32F])?;
        let mut peel_state = capture_state();
        peel_state.fragment.targets = vec![max_target(Format::RG32F), max_target(Format::RGBA32F)];
        let ids_target = TargetState {
            blend: Some(BlendState {
                alpha_eq: BlendEquation::Add,
                ..BlendState::equation(BlendEquation::Max)
            }),
            ..TargetState::new(Format::RGBA32F)
        };
        let mut count_state = capture_state();
        count_state.fragment.targets = vec![ids_target; 2];
        let none4 = NO_IDS.map(f32::to_bits);
        let mut report = PassReport::default();
        let mut peel = |state: Option<State<'_>>,
                        objects: &mut super::culling::Objects<'_>,
                        report: &mut PassReport|
         -> Result<(Image, Image, PassReport), AlgoError> {
            peel_fb.clear_color(0, none4);
            peel_fb.clear_color(1, [NONE.to_bits(); 4]);
            let pass = objects.draw(&device, &mut peel_fb, &peel_state, &Peel { state }, exec)?;
            report.merge(&pass);
            Ok((peel_fb.image(0), peel_fb.image(1), pass))
        };
        let mut count = |next: &Image,
                         prev: Option<State<'_>>,
                         objects: &mut super::culling::Objects<'_>,
                         report: &mut PassReport|
         -> Result<(Image, Image), AlgoError> {
            count_fb.clear_color(0, none4);
            count_fb.clear_color(1, none4);
            report.merge(&objects.draw(
                &device,
                &mut count_fb,
                &count_state,
                &Count { next, prev },
                exec,
            )?);
            Ok((count_fb.image(0), count_fb.image(1)))
        };
        let left = |r: &Image| r.texels.iter().any(|t| f32::from_bits(t[1]) != NONE);

        let (mut range, _, first) = peel(None, &mut objects, &mut report)?;
        let generated = first.stats.fragments_generated;
        let (mut front, mut back) = count(&range, None, &mut objects, &mut report)?;
        let pixels = peeled.lists.len();
        let mut backs: Vec<Vec<CapturedFrag>> = vec![Vec::new(); pixels];
        let mut extraction = IdExtraction::default();
        let (mut stalled, mut out_of_order) = (0u64, 0u64);
        let mut layer = Vec::with_capacity(2);
        while left(&range) && peeled.iterations < MAX_ITERATIONS {
            let state = State {
                range: &range,
                front: &front,
                back: &back,
            };
            let (next, extracted, _) = peel(Some(state), &mut objects, &mut report)?;
            peeled.iterations += 1;
            for (p, (list, backs)) in peeled.lists.iter_mut().zip(&mut backs).enumerate() {
                let [neg_near, far, ..] = texel_f32(&range, p);
                if far == NONE {
                    continue;
                }
                let near = -neg_near;
                let got = texel_f32(&extracted, p);
                let (f_ids, b_ids) = (texel_f32(&front, p), texel_f32(&back, p));
                let nf = extraction.take(list, near, f_ids, [got[0], got[1], 0.0, 0.0]);
                let [n2, f2, ..] = texel_f32(&next, p);
                if nf > 2.0 && -n2 != near {
                    stalled += 1;
                }
                if far != near {
                    layer.clear();
                    let nb = extraction.take(&mut layer, far, b_ids, [got[2], got[3], 0.0, 0.0]);
                    if nb > 2.0 && f2 != far {
                        stalled += 1;
                    }
                    for f in layer.drain(..) {
                        if backs.last().is_some_and(|l| l.depth < f.depth)
                            || list.last().is_some_and(|l| l.depth >= f.depth)
                        {
                            out_of_order += 1;
                        }
                        backs.push(f);
                    }
                }
            }
            if !left(&next) {
                range = next;
                break;
            }
            // Geometry culling: objects entirely outside every pixel's next range are done.
            objects.end_iteration(
                &device,
                super::culling::Remaining::Range {
                    image: &next,
                    range: super::dual::dual_range,
                },
                exec,
                &mut report,
            )?;
            (front, back) = count(&next, Some(state), &mut objects, &mut report)?;
            range = next;
        }
        let exhausted = !left(&range);
        for (list, mut back) in peeled.lists.iter_mut().zip(backs) {
            back.reverse();
            list.extend(back);
        }
        let mut checks = extraction.checks(&peeled.lists, exhausted, generated, stalled);
        checks.push(Check::new(
            "fronts increase, backs decrease, fronts before backs",
            out_of_order == 0,
            format!("{out_of_order} back extractions out of order"),
        ));
        let mut result = peeled.finish(report, checks, device.memory.bytes(), 96);
        result.geometry_culling = objects.summary();
        Ok(result)
    }
}

/// The algorithms of this file, for its family's registry line.
pub(super) fn algorithms() -> Vec<Box<dyn crate::algo::Algorithm>> {
    vec![Box::new(Dual2p)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{assert_exact_everywhere, frame, run};

    #[test]
    fn exact_under_every_executor_with_coplanar_fragments() {
        assert_exact_everywhere(&Dual2p, &Params::default(), 1);
    }

    #[test]
    fn peels_up_to_four_fragments_per_iteration() {
        // Two coplanar stacks of 3 at different depths: 3 at the near end, 3 at the far end.
        let mut mesh = fragrace_emu::Mesh::default();
        for z in [-0.3, 0.4] {
            for _ in 0..3 {
                crate::testing::tilted_quad(&mut mesh, [-0.8, 0.8, -0.8, 0.8], z, 0.0);
            }
        }
        let f = frame(&mesh, 8);
        let (r, m) = run(
            &Dual2p,
            &f,
            &Params::default(),
            &fragrace_emu::ExecConfig::ordered(),
        );
        assert_eq!(m.error_pixels, 0, "{:?}", r.checks);
        // Iteration 1 takes 2 + 2, iteration 2 the last one of each end: 2 initial passes,
        // 2 per iteration, the last count pass skipped.
        assert_eq!(r.report.stats.geometry_passes, 2 + 2 + 1);
        let c = r.capture.as_ref().unwrap();
        let ids: Vec<u32> = c.pixel(4 * 8 + 4).iter().map(|f| f.prim / 2).collect();
        assert_eq!(ids, vec![0, 1, 2, 3, 4, 5]);
    }

    #[test]
    fn a_coplanar_stack_is_peeled_whole() {
        let mesh = crate::testing::coplanar_stack(8);
        let f = frame(&mesh, 8);
        let (r, m) = run(
            &Dual2p,
            &f,
            &Params::default(),
            &fragrace_emu::ExecConfig::parallel(2),
        );
        assert_eq!(m.error_pixels, 0, "{:?}", r.checks);
        assert_eq!(m.robustness, 1.0);
    }
}
