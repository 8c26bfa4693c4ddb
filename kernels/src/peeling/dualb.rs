//! `dual-fab` and `dual-kb`: the depth-fighting paper's approximate coplanarity-aware dual
//! depth peeling with fixed-size buffers (section 3.2.1, "DUAL-B").
//!
//! "We introduce a solution for combining FAB/KB with F2B and DUAL (F2B-B, DUAL-B) to
//! partially treat fragment coplanarity. ... In the case of DUAL-FAB, we have to allocate two
//! buffer arrays for front and back peeling at the same time. Without loss of generality, we
//! use the same length for both buffers." (3.2.1)
//!
//! Each iteration is DUAL-LL's two passes (section 3.1.3) with Algorithm 3's storage in place
//! of the lists: a range pass (MAX blending of `(-z, z)` over the fragments strictly inside
//! the previous range, depth test off) finds each pixel's next near and far layer, and a
//! capture pass stores every fragment at the near end into the pixel's front row of `K` = 8
//! slots (`f2bb::SLOTS`) and every fragment at the far end into its back row (the near end
//! wins when the range is one depth). The host takes both rows after each capture pass and
//! clears them; the pixel's list is its front layers, then its back layers reversed. A layer
//! end with more than `K` coplanar fragments loses the rest: robustness `sum K / C(Z_i)`
//! (Table 1); within `K`, every fragment is peeled (`R_h = 1` on `coplanar-stack`, where
//! `dual` keeps one of eight).
//!
//! - **DUAL-FAB** (`dual-fab`): a per-row atomic counter hands out the slots, as `f2b-fab`:
//!   hazard-free; what does not fit is counted (`dropped`).
//! - **DUAL-KB** (`dual-kb`): the first empty slot found and filled with plain loads and
//!   stores, the reading of `f2b-kb` (a k-buffer on render targets has no atomic search):
//!   coplanar fragments of one end in flight together race for a slot. Hazard-prone, on
//!   coplanar scenes only.
//!
//! Every layer is peeled (`Capacity::All`; `k` does not apply), `ceil(D/2)` iterations of two
//! passes after the first range pass.
//!
//! **Invariants (checked on every run).** Rows fill from the first slot with no gap and hold
//! fragments of their end's depth, each once; each pixel's range shrinks at both ends every
//! iteration; DUAL-FAB: kept + dropped = the fragments the capture passes met = the fragments
//! generated.

use fragrace_emu::{
    BlendEquation, BlendState, Format, Fragment, FragmentKernel, Image, KernelInfo,
    PassReport, TargetState,
};

use super::dualll::Range;
use super::f2bb::{Allocation, SlotTally, Slots};
use super::{check_ids_fit_floats, texel_f32, Peeled};
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, CapturedFrag, Check, Frame, HazardClass,
    Params,
};
use crate::common::capture_state;

const NONE: f32 = f32::NEG_INFINITY;

/// Safety bound on iterations: a pixel's range shrinks by a layer at each end per pass.
const MAX_ITERATIONS: u32 = 1 << 16;

/// The capture pass: fragments at the range's near end into the front row, at its far end
/// into the back row.
struct Capture<'i> {
    range: &'i Image,
    s: Slots,
    alloc: Allocation,
    pixels: u32,
}

impl FragmentKernel for Capture<'_> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new(match self.alloc {
            Allocation::Counter => "dual-fab-capture",
            _ => "dual-kb-capture",
        })
        .with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        let z = f.depth();
        let [neg_near, far, ..] = f.texel(self.range, f.x(), f.y(), 0).map(f32::from_bits);
        let p = f.pixel_index();
        let row = if z == -neg_near {
            p
        } else if z == far {
            self.pixels + p
        } else {
            f.discard();
            return;
        };
        self.s.store(&f, self.alloc, row).await;
    }
}

/// `dual-fab` (`Allocation::Counter`) or `dual-kb` (`Allocation::Search`).
pub struct DualB(Allocation);

impl DualB {
    pub const fn fab() -> DualB {
        DualB(Allocation::Counter)
    }
    pub const fn kb() -> DualB {
        DualB(Allocation::Search)
    }
}

impl Algorithm for DualB {
    /// Peels until the range is empty with K = 8 slots per end; k does not apply.
    fn reads(&self, _: crate::Param) -> bool {
        false
    }

    fn info(&self) -> AlgoInfo {
        let common = AlgoInfo {
            name: "dual-fab",
            family: "depth peeling",
            summary: "approximate coplanarity-aware dual depth peeling: a min-max range pass, then each end's \
                      coplanar fragments into K = 8 front or back slots per pixel handed out by atomic counters; \
                      more than K at one end are lost (counted)",
            source: "depth-fighting paper, section 3.2.1 (DUAL-B) and Table 1",
            passes: "1 geometry (initial range) + 2 geometry per iteration (ceil(D/2) iterations); k does not apply",
            memory: "24 + 16 K bytes (K = 8): RG32F range, the previous range read-only, two counters; front and \
                     back rows of K slots of depth and primitive (Table 1, DUAL-B: K + 6 words with a one-word \
                     colour per slot, per direction here)",
            hazard: HazardClass::HazardFree,
            capacity: Capacity::All,
        };
        match self.0 {
            Allocation::Counter => common,
            _ => AlgoInfo {
                name: "dual-kb",
                summary: "DUAL-B with k-buffers: each end's coplanar fragments into the first empty of K = 8 front or \
                          back slots, found with plain loads and stores; coplanar fragments in flight together race \
                          for a slot and overwrite each other",
                memory: "16 + 16 K bytes (K = 8): RG32F range, the previous range read-only; front and back rows \
                         of K slots of depth and primitive (Table 1, DUAL-B: K + 4 words with a one-word colour \
                         per slot, per direction here)",
                hazard: HazardClass::HazardProne,
                ..common
            },
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
        let mut device = crate::common::fresh(exec);
        let mut objects = super::culling::Objects::new(frame, params)?;
        let mut fb = peeled.framebuffer(&[Format::RG32F])?;
        let mut range_state = capture_state();
        range_state.fragment.targets = vec![TargetState {
            blend: Some(BlendState::equation(BlendEquation::Max)),
            ..TargetState::new(Format::RG32F)
        }];
        let capture = capture_state();
        let pixels = peeled.lists.len();
        let s = Slots::new(&mut device, "dual-b", 2 * pixels as u64, self.0)?;
        let mut report = PassReport::default();
        let range_pass = |fb: &mut fragrace_emu::Framebuffer,
                          device: &fragrace_emu::Device,
                          objects: &mut super::culling::Objects<'_>,
                          prev: Option<&Image>,
                          report: &mut PassReport|
         -> Result<(Image, PassReport), AlgoError> {
            fb.clear_color(0, [NONE.to_bits(), NONE.to_bits(), 0, 0]);
            let pass = objects.draw(device, fb, &range_state, &Range { prev }, exec)?;
            report.merge(&pass);
            Ok((fb.image(0), pass))
        };
        let (mut range, first) = range_pass(&mut fb, &device, &mut objects, None, &mut report)?;
        // Geometry culling: after each range pass, objects entirely outside every pixel's
        // range are done.
        objects.end_dual_iteration(&device, &range, exec, &mut report)?;
        let generated = first.stats.fragments_generated;
        let mut backs: Vec<Vec<CapturedFrag>> = vec![Vec::new(); pixels];
        let (mut met, mut not_shrinking) = (0u64, 0u64);
        let mut tally = SlotTally::default();
        let left = |r: &Image| r.texels.iter().any(|t| f32::from_bits(t[1]) != NONE);
        while left(&range) && peeled.iterations < MAX_ITERATIONS {
            s.clear(&device)?;
            let kernel = Capture {
                range: &range,
                s,
                alloc: self.0,
                pixels: pixels as u32,
            };
            let pass = objects.draw(&device, &mut fb, &capture, &kernel, exec)?;
            report.merge(&pass);
            met += pass.stats.samples_passed;
            peeled.iterations += 1;
            let (lists, backs) = (&mut peeled.lists, &mut backs);
            s.read(
                &device,
                &mut tally,
                |row| {
                    let [neg_near, far, ..] = texel_f32(&range, row % pixels);
                    Some(if row < pixels { -neg_near } else { far })
                },
                |row, frags| {
                    if row < pixels {
                        lists[row].extend(frags);
                    } else {
                        backs[row - pixels].extend(frags.into_iter().rev());
                    }
                },
            )?;
            let (next, _) = range_pass(&mut fb, &device, &mut objects, Some(&range), &mut report)?;
            for p in 0..pixels {
                let ([n0, f0, ..], [n1, f1, ..]) = (texel_f32(&range, p), texel_f32(&next, p));
                if f1 != NONE && (-n1 <= -n0 || f1 >= f0) {
                    not_shrinking += 1;
                }
            }
            objects.end_dual_iteration(&device, &next, exec, &mut report)?;
            range = next;
        }
        let unfinished = left(&range);
        for (list, mut back) in peeled.lists.iter_mut().zip(backs) {
            back.reverse();
            list.extend(back);
        }
        let dropped = s.dropped(&device)?;
        let kept = tally.kept;
        let mut checks = vec![
            tally.check(),
            Check::new(
                "each pixel's range shrinks at both ends every iteration",
                not_shrinking == 0 && !unfinished,
                format!(
                    "{not_shrinking} ranges that did not shrink{}",
                    if unfinished {
                        format!("; stopped after {MAX_ITERATIONS} iterations with ranges left")
                    } else {
                        String::new()
                    }
                ),
            ),
        ];
        if self.0 == Allocation::Counter {
            checks.push(Check::new(
                "every fragment is met at a range's end once: kept or counted as dropped",
                kept + dropped == met && met == generated,
                format!(
                    "{kept} kept + {dropped} dropped of {met} at the ends, {generated} generated"
                ),
            ));
        } else {
            checks.push(Check::new(
                "fragments overwritten in a slot by a racing one (informational)",
                true,
                format!(
                    "{} of {met} at the ends: {kept} kept, {dropped} found no slot",
                    met.saturating_sub(kept + dropped)
                ),
            ));
        }
        let bytes = device.memory.bytes();
        let mut result = peeled.finish(report, checks, bytes, 16);
        result.geometry_culling = objects.summary();
        result.dropped = dropped;
        Ok(result)
    }
}

/// The algorithms of this file, for its family's registry line.
pub(super) fn algorithms() -> Vec<Box<dyn crate::algo::Algorithm>> {
    vec![Box::new(DualB::fab()), Box::new(DualB::kb())]
}

#[cfg(test)]
mod tests {
    use fragrace_emu::{ExecConfig, Policy};

    use super::*;
    use crate::testing::{assert_exact_everywhere, frame, run, scheduled};

    #[test]
    fn fab_is_exact_under_every_executor_while_ends_fit() {
        assert_exact_everywhere(&DualB::fab(), &Params::default(), 1);
    }

    #[test]
    fn a_coplanar_stack_is_peeled_whole_where_dual_keeps_one() {
        let mesh = crate::testing::coplanar_stack(8);
        let f = frame(&mesh, 8);
        let (r, m) = run(
            &DualB::fab(),
            &f,
            &Params::default(),
            &ExecConfig::parallel(2),
        );
        assert_eq!(m.error_pixels, 0, "{:?}", r.checks);
        assert_eq!(m.robustness, 1.0);
        // One range pass, one iteration of capture + range.
        assert_eq!(r.report.stats.geometry_passes, 3);
        let (_, m) = run(
            &super::super::dual::Dual,
            &f,
            &Params::default(),
            &ExecConfig::parallel(2),
        );
        assert_eq!(m.robustness, 1.0 / 8.0);
    }

    #[test]
    fn fab_keeps_k_slots_of_an_end_and_counts_the_rest() {
        let mesh = crate::testing::coplanar_stack(11);
        let f = frame(&mesh, 8);
        let (r, m) = run(
            &DualB::fab(),
            &f,
            &Params::default(),
            &ExecConfig::ordered(),
        );
        for c in &r.checks {
            assert!(c.passed, "{}: {}", c.name, c.detail);
        }
        assert_eq!(r.dropped, 3 * m.covered_pixels);
        assert_eq!(m.captured, 8 * m.covered_pixels);
    }

    #[test]
    fn kb_loses_racing_coplanar_fragments_and_the_detector_sees_it() {
        let mesh = crate::testing::coplanar_stack(6);
        let f = frame(&mesh, 8);
        let params = Params::default();
        let (r, m) = run(&DualB::kb(), &f, &params, &ExecConfig::ordered());
        assert_eq!(m.error_pixels, 0, "one at a time, the slot search is exact");
        assert_eq!(r.report.hazards.total(), 0);
        let mut lost = 0;
        for seed in 0..3 {
            let (r, m) = run(&DualB::kb(), &f, &params, &scheduled(Policy::Random, seed));
            assert!(r.report.hazards.lost_updates > 0, "seed {seed}");
            lost += m.error_pixels;
        }
        assert!(lost > 0, "racing coplanar fragments overwrite each other");
    }
}
