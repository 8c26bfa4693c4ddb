//! `dual-ll`: the depth-fighting paper's coplanarity-aware dual depth peeling with linked
//! lists (section 3.1.3, "F2B-LL and DUAL-LL").
//!
//! DUAL peels the nearest and the farthest layer of each pixel per iteration but keeps one
//! fragment per layer end. DUAL-LL keeps all of them: per iteration a range pass builds the
//! min-max depth buffer of the fragments strictly inside the previous range (MAX blending of
//! `(-z, z)`, depth test off: "construction of a min/max depth buffer for DUAL-LL disables
//! depth testing"), and a capture pass pushes every fragment at the range's near end onto the
//! pixel's front list and every fragment at its far end onto its back list. "To avoid a
//! slight increase of contention ... from both front and back fragments, an additional
//! address counter variable for back layers is used (next_back). Conflicts between front and
//! back fragments are avoided by employing an inverse memory mapping strategy for the
//! fragments extracted in the back-to-front direction. Specifically, we route them starting
//! from the end of the node buffer towards the beginning." (3.1.3) Both counters share one
//! pool, sized by the fragments of the first pass, so the two ends never meet (checked).
//!
//! Every layer is peeled (`Capacity::All`; `k` does not apply), `ceil(D/2)` iterations of two
//! passes. The host walks both lists of each pixel and sorts them by (depth, primitive).
//!
//! **Invariants (checked on every run).** The lists hold each captured fragment once, in the
//! pool, acyclic (stored = front + back allocations = the fragments the capture passes let
//! through); the front and back allocations never meet; nothing is dropped.

use fragrace_emu::{
    BlendEquation, BlendState, Format, Fragment, FragmentKernel, Image, KernelInfo,
    PassReport, TargetState,
};

use super::f2bll::{link, Lists, Walked};
use super::{texel_f32, Peeled};
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Check, Frame, HazardClass, Params,
};
use crate::common::capture_state;

const NONE: f32 = f32::NEG_INFINITY;

/// Counter words: front allocation, dropped, back allocation.
const FRONT: u32 = 0;
const DROPPED: u32 = 1;
const BACK: u32 = 2;

/// The range pass: the min-max depth of the fragments strictly inside the previous range
/// (shared with DUAL-B).
pub(super) struct Range<'i> {
    pub prev: Option<&'i Image>,
}

impl FragmentKernel for Range<'_> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("dual-ll-range").with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        let z = f.depth();
        if let Some(prev) = self.prev {
            let [neg_near, far, ..] = f.texel(prev, f.x(), f.y(), 0).map(f32::from_bits);
            if z <= -neg_near || z >= far {
                f.discard();
                return;
            }
        }
        f.output(0, [-z, z, 0.0, 0.0]);
    }
}

/// The capture pass: fragments at the range's ends onto the front or back list.
struct Capture<'i> {
    range: &'i Image,
    lists: Lists,
    pixels: u32,
}

impl FragmentKernel for Capture<'_> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("dual-ll-capture").with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        let z = f.depth();
        let [neg_near, far, ..] = f.texel(self.range, f.x(), f.y(), 0).map(f32::from_bits);
        let l = &self.lists;
        let p = f.pixel_index();
        let (counter, head) = if z == -neg_near {
            (FRONT, p)
        } else if z == far {
            (BACK, self.pixels + p)
        } else {
            f.discard();
            return;
        };
        let i = f.atomic_add(l.counters, counter, 1).await;
        if i >= l.capacity {
            f.atomic_add(l.counters, DROPPED, 1).await;
            return;
        }
        // Back fragments are routed from the end of the pool.
        let node = if counter == FRONT {
            i
        } else {
            l.capacity - 1 - i
        };
        link(&f, l, head, node).await;
    }
}

/// `dual-ll`: see the module documentation.
pub struct DualLl;

impl Algorithm for DualLl {
    /// Neither k (it peels every layer) nor a spin cap.
    fn reads(&self, _: crate::Param) -> bool {
        false
    }

    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "dual-ll",
            family: "depth peeling",
            summary: "coplanarity-aware dual depth peeling: a min-max range pass, then every fragment at the range's \
                      near end onto a front list and at its far end onto a back list (two counters, one pool \
                      filled from both ends)",
            source: "depth-fighting paper, section 3.1.3 (DUAL-LL) and Table 1",
            passes: "1 geometry (initial range) + 2 geometry per iteration (ceil(D/2) iterations); k does not apply",
            memory: "24 + 12 n bytes: RG32F range, the previous range read-only, front and back heads; depth, \
                     primitive and next per node, one pool for the whole scene (Table 1's 2C(Zf,Zb) + 6 words \
                     assume a pool reused per iteration)",
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
        let pixels = peeled.lists.len() as u64;
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
        // Every fragment is captured once: the first pass's fragments bound the pool.
        let lists = Lists::new(
            &mut device,
            "dual-ll",
            2 * pixels,
            first.stats.fragments_generated,
            3,
        )?;
        let mut let_through = 0u64;
        let mut not_shrinking = 0u64;
        let left = |r: &Image| r.texels.iter().any(|t| f32::from_bits(t[1]) != NONE);
        while left(&range) && peeled.iterations < MAX_ITERATIONS {
            let kernel = Capture {
                range: &range,
                lists,
                pixels: pixels as u32,
            };
            let pass = objects.draw(&device, &mut fb, &capture, &kernel, exec)?;
            report.merge(&pass);
            let_through += pass.stats.samples_passed;
            peeled.iterations += 1;
            let (next, _) = range_pass(&mut fb, &device, &mut objects, Some(&range), &mut report)?;
            for p in 0..pixels as usize {
                let ([n0, f0, ..], [n1, f1, ..]) = (texel_f32(&range, p), texel_f32(&next, p));
                if f1 != NONE && (-n1 <= -n0 || f1 >= f0) {
                    not_shrinking += 1;
                }
            }
            objects.end_dual_iteration(&device, &next, exec, &mut report)?;
            range = next;
        }
        let unfinished = left(&range);
        let generated = first.stats.fragments_generated;
        let counters = device.memory.read(lists.counters)?;
        let (front, dropped, back) = (
            u64::from(counters[FRONT as usize]),
            u64::from(counters[DROPPED as usize]),
            u64::from(counters[BACK as usize]),
        );
        let Walked {
            stored,
            bad_links,
            revisits,
        } = lists.walk(&device, &mut peeled.lists)?;
        let checks = vec![
            Check::new(
                "the lists hold each captured fragment once, in range, acyclic",
                bad_links == 0
                    && revisits == 0
                    && stored == let_through
                    && front + back == let_through
                    && let_through == generated
                    && !unfinished,
                format!(
                    "{stored} stored of {let_through} at the ranges' ends of {generated} generated ({front} front, \
                     {back} back); {bad_links} links out of the pool, {revisits} nodes reached twice{}",
                    if unfinished {
                        format!("; stopped after {MAX_ITERATIONS} iterations with ranges left")
                    } else {
                        String::new()
                    }
                ),
            ),
            Check::new(
                "front and back allocations never meet; nothing dropped",
                front + back <= u64::from(lists.capacity) && dropped == 0,
                format!("{front} + {back} of {} nodes, {dropped} dropped", lists.capacity),
            ),
            Check::new(
                "each pixel's range shrinks at both ends every iteration",
                not_shrinking == 0,
                format!("{not_shrinking} ranges that did not shrink"),
            ),
        ];
        let bytes = device.memory.bytes();
        let mut result = peeled.finish(report, checks, bytes, 16);
        result.geometry_culling = objects.summary();
        Ok(result)
    }
}

/// Safety bound on iterations.
const MAX_ITERATIONS: u32 = 1 << 16;


/// The algorithms of this file, for its family's registry line.
pub(super) fn algorithms() -> Vec<Box<dyn crate::algo::Algorithm>> {
    vec![Box::new(DualLl)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::assert_exact_everywhere;

    #[test]
    fn exact_under_every_executor_with_coplanar_fragments() {
        assert_exact_everywhere(&DualLl, &Params::default(), 1);
    }
}
