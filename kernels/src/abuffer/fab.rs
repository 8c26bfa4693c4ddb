//! `fab`: the fixed-array A-buffer (FreePipe, Liu et al. 2010, \[21\] of the depth-fighting
//! paper; realised with OpenGL atomics as FAB, \[23\]).
//!
//! Every pixel owns `params.fab_capacity` slots and an atomic counter (depth-fighting paper,
//! section 2 and Fig. 3(a)): a fragment takes `slot = atomicAdd(count[p], 1)` and writes its
//! depth and primitive there if `slot < capacity`. The counter keeps counting past the
//! capacity, so the fragments that did not fit are counted exactly
//! (`sum_p max(count[p] - capacity, 0)`) and never silently lost. The same memory per pixel
//! whatever the depth complexity is FAB's known cost (section 4.2 and 4.4: "extremely large
//! memory requirements"). The resolve sorts each pixel's array and composites.

use fragrace_emu::{Buf, ExecConfig, Fragment, FragmentKernel, KernelInfo};

use super::array::{store_fragment, ArrayResolve, FragmentArrays, Layout};
use super::run::AbRun;
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Check, Frame, HazardClass, Params,
};
use crate::common::pixels;
use crate::resolve::Composite;

pub(super) fn algorithms() -> Vec<Box<dyn Algorithm>> {
    vec![Box::new(Fab)]
}

/// FAB store pass: `slot = atomicAdd(count[p], 1)`; kept if `slot < cap`, else counted as
/// dropped (the FreePipe overflow).
struct FabStore {
    counts: Buf<u32>,
    depth: Buf<f32>,
    prim: Buf<u32>,
    dropped: Buf<u32>,
    cap: u32,
}

impl FragmentKernel for FabStore {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("fab-store")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let slot = f.atomic_add(self.counts, p, 1).await;
        if slot >= self.cap {
            f.atomic_add(self.dropped, 0, 1).await;
            return;
        }
        store_fragment(&f, self.depth, self.prim, p * self.cap + slot).await;
    }
}

/// `fab`: FreePipe's fixed-size per-pixel arrays.
pub struct Fab;

impl Algorithm for Fab {
    /// Neither k (it keeps up to `fab_capacity` fragments) nor a spin cap.
    fn reads(&self, _: crate::Param) -> bool {
        false
    }

    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "fab",
            family: "a-buffer",
            summary: "fixed-array A-buffer (FreePipe/FAB): fab_capacity slots per pixel taken with an atomic per-pixel \
                      counter; overflowing fragments dropped and counted; resolve sorts and composites",
            source: "FreePipe (Liu et al. 2010) / FAB, refs [21, 23] of the depth-fighting paper, section 2, Fig. 3(a), Table 1",
            passes: "1 geometry + 1 full-screen",
            memory: "4 + 8 D bytes (counter; depth + primitive per slot, D = fab_capacity); Table 1: 2D + 2 words",
            hazard: HazardClass::HazardFree,
            capacity: Capacity::All,
        }
    }

    fn run_frame(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        let cap = params.fab_capacity;
        let n = pixels(frame);
        let slots = n as u64 * cap as u64;
        if slots > u32::MAX as u64 {
            return Err(AlgoError::Invalid(format!(
                "FAB needs {slots} slots ({n} pixels x {cap}): more than a buffer can index"
            )));
        }
        let mut run = AbRun::new(frame, params, exec)?;
        let counts = run.device.buffer::<u32>("fab-counts", n as u64)?;
        let arrays = FragmentArrays::new(&mut run.device, "fab", slots)?;
        let dropped_buf = run.device.buffer::<u32>("fab-dropped", 1)?;

        let store = FabStore {
            counts,
            depth: arrays.depth,
            prim: arrays.prim,
            dropped: dropped_buf,
            cap,
        };
        let mut report = run.capture(&store)?;
        let generated = report.stats.fragments_generated;
        let resolve = ArrayResolve {
            layout: Layout::Fixed { cap },
            lens: counts,
            limit: None,
            arrays,
            composite: Composite::of(params),
        };
        report.merge(&run.resolve(&resolve)?);

        let counts_v = run.device.memory.read(counts)?;
        let capture = resolve.capture(&run.device, frame)?;
        let dropped = run.device.memory.read(dropped_buf)?[0] as u64;
        let overflow: u64 = counts_v.iter().map(|&c| c.saturating_sub(cap) as u64).sum();
        let counted: u64 = counts_v.iter().map(|&c| c as u64).sum();
        let stored = capture.frags.len() as u64;
        let checks = vec![
            Check::new(
                "every generated fragment stored exactly once unless its array overflowed",
                stored + dropped == generated && counted == generated,
                format!(
                    "stored {stored}, dropped {dropped}, generated {generated}, counted {counted}"
                ),
            ),
            Check::new(
                "overflow counted exactly",
                dropped == overflow,
                format!("dropped counter {dropped}, sum of max(count - {cap}, 0) = {overflow}"),
            ),
        ];
        Ok(run.finish(capture, report, dropped, checks, []))
    }
}

#[cfg(test)]
mod tests {
    use fragrace_emu::Policy;

    use super::*;
    use crate::basic::Truth;
    use crate::oracle;
    use crate::testing::*;

    #[test]
    fn fab_is_exact_under_every_executor() {
        assert_exact_and_hazard_free_everywhere(&Fab);
        let mesh = layers();
        let f = frame_sized(&mesh, 24, 20);
        // Exactly sized arrays: capacity = the deepest pixel.
        let params = Params {
            fab_capacity: 6,
            ..Params::default()
        };
        assert_exact(&Fab, &f, &params, &ExecConfig::scheduled(Policy::Random, 5));
    }

    #[test]
    fn fab_overflow_is_counted_exactly_and_keeps_the_rest() {
        let mesh = stack(7);
        let f = frame_sized(&mesh, 6, 5);
        let params = Params {
            fab_capacity: 3,
            ..Params::default()
        };
        let truth = Truth::capture(&f, 1).unwrap();
        for exec in executor_configs() {
            let r = Fab.run(&f, &params, &exec).unwrap();
            for c in &r.checks {
                assert!(c.passed, "{:?}: `{}`: {}", exec.mode, c.name, c.detail);
            }
            assert_eq!(r.dropped, 30 * 4, "{:?}", exec.mode);
            let m = oracle::compare(&Fab.info(), &r, &truth, &params);
            assert_eq!(m.captured, 30 * 3);
            assert_eq!(m.generated, 30 * 7);
            // Which 3 of the 7 a pixel keeps depends on the interleaving; each kept one is real.
            let c = r.capture.as_ref().unwrap();
            let t = truth.capture.as_ref().unwrap();
            for p in 0..c.pixels() {
                assert_eq!(c.pixel(p).len(), 3);
                for fr in c.pixel(p) {
                    assert!(
                        t.pixel(p).contains(fr),
                        "pixel {p}: {fr:?} is not one of truth's"
                    );
                }
            }
        }
    }
}
