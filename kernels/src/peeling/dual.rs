//! `dual`: dual depth peeling (Bavoil & Myers, "Order independent transparency with dual
//! depth peeling", NVIDIA 2008; \[13\] of the depth-fighting paper, section 3.1.2
//! "Overview").
//!
//! "DUAL depth peeling increases performance by applying the F2B method for the
//! front-to-back and the back-to-front directions simultaneously. Due to the unavailable
//! support of multiple depth buffers on the GPU, a custom min-max depth buffer is
//! introduced. In every iteration, the algorithm extracts the fragment information which
//! match the min-max depth values of the previous iteration and performs depth peeling on
//! the fragments inside this depth set. An additional rendering pass is needed to initialize
//! depth buffer to the closest and the further layers." (section 3.1.2)
//!
//! One geometry pass per iteration, depth test off, MAX blending on three RG32F targets (the
//! min-max depth buffer as `(-near, far)`, and the front and back layers' `(depth, id)`):
//! a fragment strictly inside the previous min-max range writes `(-z, z)` (the next range);
//! one at the range's near end writes itself to the front target, one at the far end to the
//! back target (a pixel whose range is one depth has only a front); fragments outside the
//! range were peeled before and are discarded. The front layers are kept in order, the back
//! layers in reverse, and the pixel's list is the front ones then the back ones reversed.
//! The loop ends when no pixel has a range left (read back from the min-max target), so it
//! peels every layer: `k` does not apply (`Capacity::All`), `ceil(D/2) + 1` passes for a depth
//! complexity `D` (Table 1).
//!
//! **Coplanarity.** As F2B, DUAL keeps one fragment per layer per direction: of `c` fragments
//! at a layer's depth MAX blending keeps the largest id (Bavoil's shader keeps the MAX of the
//! colours, a z-fighting artefact) and `c - 1` are lost, counted in `dropped` (an atomic
//! counter of the fragments met at a layer's ends). "Robustness ratio D/C(Zall)" (Table 1).
//! The loss is the same under every executor: the rest is fixed-function.
//!
//! **Invariants (checked on every run).** Each pixel's ranges shrink strictly; its front
//! layers increase and its back layers decrease, the front ones in front of the back ones;
//! the kept fragments plus the lost ones are the fragments met at the layers' ends.

use fragrace_emu::{
    BlendEquation, BlendState, Buf, Format, Fragment, FragmentKernel, Image, KernelInfo,
    PassReport, TargetState,
};

use super::{check_ids_fit_floats, texel_f32, Peeled};
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, CapturedFrag, Check, Frame, HazardClass,
    Params,
};
use crate::common::capture_state;

const NONE: f32 = f32::NEG_INFINITY;

/// Safety bound on iterations: a pixel's range shrinks by a layer at each end per pass.
const MAX_ITERATIONS: u32 = 1 << 16;

struct Peel<'i> {
    /// The previous min-max range (RG32F `(-near, far)`); `None` in the initial pass.
    range: Option<&'i Image>,
    /// One word: fragments met at a range's ends (kept or lost).
    at_ends: Buf<u32>,
}

impl FragmentKernel for Peel<'_> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("dual-peel").with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        let z = f.depth();
        let id = f.primitive_id() as f32;
        let none = [NONE, NONE, 0.0, 0.0];
        let Some(range) = self.range else {
            f.output(0, [-z, z, 0.0, 0.0]);
            f.output(1, none);
            f.output(2, none);
            return;
        };
        let [neg_near, far, ..] = f.texel(range, f.x(), f.y(), 0).map(f32::from_bits);
        let near = -neg_near;
        if z < near || z > far {
            f.discard();
            return;
        }
        if z == near || z == far {
            f.atomic_add(self.at_ends, 0, 1).await;
            f.output(0, none);
            // The near end wins when the range is one depth: one layer, kept once.
            let layer = [z, id, 0.0, 0.0];
            let (front, back) = if z == near {
                (layer, none)
            } else {
                (none, layer)
            };
            f.output(1, front);
            f.output(2, back);
        } else {
            f.output(0, [-z, z, 0.0, 0.0]);
            f.output(1, none);
            f.output(2, none);
        }
    }
}

/// A dual range texel `(-near, far)` as `(near, far)`; `near > far` (`+inf`, `-inf`) where
/// nothing is left.
pub(super) fn dual_range(t: [u32; 4]) -> (f32, f32) {
    (-f32::from_bits(t[0]), f32::from_bits(t[1]))
}

/// `dual`: see the module documentation.
pub struct Dual;

impl Algorithm for Dual {
    /// Neither k (it peels every layer) nor a spin cap.
    fn reads(&self, _: crate::Param) -> bool {
        false
    }

    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "dual",
            family: "depth peeling",
            summary: "dual depth peeling: one pass per iteration peels the nearest and the farthest remaining layer \
                      through a min-max depth buffer (MAX blending); every layer, coplanar fragments collapse",
            source: "Bavoil & Myers 2008 ([13] of the depth-fighting paper); depth-fighting paper, section 3.1.2 \
                     (Overview) and Table 1 (DUAL)",
            passes: "1 geometry (initial range) + 1 geometry per iteration (ceil(D/2) + 1 in all); k does not apply",
            memory: "24 bytes of targets: RG32F min-max range, RG32F front and back layers (depth, id); + 8 bytes \
                     of the previous range read-only (Table 1, DUAL: 6 words)",
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
        // Every layer is peeled: no `k` cap on the lists.
        let mut peeled = Peeled::unbounded(frame, params);
        let mut device = crate::common::fresh(exec);
        let at_ends = device.buffer::<u32>("dual-at-ends", 1)?;
        let mut objects = super::culling::Objects::new(frame, params)?;
        let mut fb = peeled.framebuffer(&[Format::RG32F; 3])?;
        let max = TargetState {
            blend: Some(BlendState::equation(BlendEquation::Max)),
            ..TargetState::new(Format::RG32F)
        };
        let mut state = capture_state();
        state.fragment.targets = vec![max; 3];
        let mut report = PassReport::default();
        let mut backs: Vec<Vec<CapturedFrag>> = vec![Vec::new(); peeled.lists.len()];
        let (mut not_shrinking, mut out_of_order, mut kept) = (0u64, 0u64, 0u64);
        let mut range: Option<Image> = None;
        let mut generated = 0u64;
        let mut unfinished = false;
        loop {
            for t in 0..3 {
                fb.clear_color(t, [NONE.to_bits(), NONE.to_bits(), 0, 0]);
            }
            let pass = objects.draw(
                &device,
                &mut fb,
                &state,
                &Peel {
                    range: range.as_ref(),
                    at_ends,
                },
                exec,
            )?;
            report.merge(&pass);
            if range.is_none() {
                generated = pass.stats.fragments_generated;
            }
            let next = fb.image(0);
            if let Some(prev) = &range {
                peeled.iterations += 1;
                let (front, back) = (fb.image(1), fb.image(2));
                for (p, (list, backs)) in peeled.lists.iter_mut().zip(&mut backs).enumerate() {
                    let [neg_near, far, ..] = texel_f32(prev, p);
                    if far == NONE {
                        continue;
                    }
                    let [n2, f2, ..] = texel_f32(&next, p);
                    if f2 != NONE && (-n2 <= -neg_near || f2 >= far) {
                        not_shrinking += 1;
                    }
                    let [fz, fid, ..] = texel_f32(&front, p);
                    if fz != NONE {
                        if list.last().is_some_and(|l| l.depth >= fz) {
                            out_of_order += 1;
                        }
                        list.push(CapturedFrag {
                            depth: fz,
                            prim: fid as u32,
                        });
                        kept += 1;
                    }
                    let [bz, bid, ..] = texel_f32(&back, p);
                    if bz != NONE {
                        if backs.last().is_some_and(|l| l.depth <= bz)
                            || list.last().is_some_and(|l| l.depth >= bz)
                        {
                            out_of_order += 1;
                        }
                        backs.push(CapturedFrag {
                            depth: bz,
                            prim: bid as u32,
                        });
                        kept += 1;
                    }
                }
            }
            let any_left = next.texels.iter().any(|t| f32::from_bits(t[1]) != NONE);
            if !any_left {
                break;
            }
            if peeled.iterations >= MAX_ITERATIONS {
                unfinished = true;
                break;
            }
            // Geometry culling: objects entirely outside every pixel's range are done.
            objects.end_iteration(
                &device,
                super::culling::Remaining::Range {
                    image: &next,
                    range: dual_range,
                },
                exec,
                &mut report,
            )?;
            range = Some(next);
        }
        for (list, mut back) in peeled.lists.iter_mut().zip(backs) {
            back.reverse();
            list.extend(back);
        }
        let met = u64::from(device.memory.read(at_ends)?[0]);
        let lost = met.saturating_sub(kept);
        let checks = vec![
            Check::new(
                "each pixel's range shrinks at both ends every iteration",
                not_shrinking == 0,
                format!("{not_shrinking} ranges that did not shrink"),
            ),
            Check::new(
                "front layers increase, back layers decrease, fronts before backs",
                out_of_order == 0,
                format!("{out_of_order} layers out of order"),
            ),
            Check::new(
                "every fragment is met at a range's end exactly once: kept or lost",
                !unfinished && met == generated && met >= kept,
                format!(
                    "{met} fragments at the ends of {generated} generated, {kept} kept, {lost} coplanar fragments \
                     lost{}",
                    if unfinished {
                        format!("; stopped after {MAX_ITERATIONS} iterations with ranges left")
                    } else {
                        String::new()
                    }
                ),
            ),
        ];
        let mut result = peeled.finish(report, checks, device.memory.bytes(), 32);
        result.dropped = lost;
        result.geometry_culling = objects.summary();
        Ok(result)
    }
}


/// The algorithms of this file, for its family's registry line.
pub(super) fn algorithms() -> Vec<Box<dyn crate::algo::Algorithm>> {
    vec![Box::new(Dual)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{frame, run};

    #[test]
    fn peels_every_layer_and_loses_exactly_the_coplanar_ones() {
        for (what, r, m) in super::super::assert_same_loss_everywhere(&Dual) {
            // Every fragment generated is kept or counted as lost.
            assert_eq!(m.captured + r.dropped, m.expected, "{what}: {m:?}");
        }
    }

    #[test]
    fn exact_without_coplanarity_in_half_the_passes() {
        let mut mesh = fragrace_emu::Mesh::default();
        for i in 0..7 {
            crate::testing::tilted_quad(
                &mut mesh,
                [-0.9 + 0.05 * i as f32, 0.8, -0.7, 0.9],
                -0.6 + 0.17 * ((i * 3) % 7) as f32,
                0.05,
            );
        }
        let f = frame(&mesh, 16);
        let (r, m) = run(
            &Dual,
            &f,
            &Params::default(),
            &fragrace_emu::ExecConfig::parallel(2),
        );
        assert_eq!(m.error_pixels, 0, "{:?} {:?}", m.first_error, r.checks);
        assert_eq!(r.dropped, 0);
        // 7 layers: the initial pass and 4 iterations (3 pairs and a middle one).
        assert_eq!(r.report.stats.geometry_passes, 5);
    }
}
