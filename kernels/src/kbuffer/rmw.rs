//! `kb-rmw`: the original k-buffer (Bavoil et al. 2007, "Multi-fragment effects on the GPU
//! using the k-buffer", cited as \[17\] by the depth-fighting paper, section 2 and Table 1 row
//! KB; the llvmpipe peer's `kbuf-rmw`). What the other k-buffers of this folder that keep
//! `(depth, primitive)` slots share with it lives beside it: [`super::slots`] (slot layout,
//! sorted read-modify-write insertion), [`super::run`] (capture, resolve, readback) and
//! [`super::checks`] (slot-shape invariants).
//!
//! Each pixel owns k depth slots (`+inf` = empty) and k primitive slots (`EMPTY`). A fragment
//! plain-loads its pixel's k slots, inserts itself by sorted insertion if it is nearer than
//! the farthest, and plain-stores all k back. Two fragments of one pixel in flight together
//! read the same slots and the second store overwrites the first: the read-modify-write
//! hazard (RMWH) every seed names (bucket-depth-peeling paper, section 2; depth-fighting
//! paper, section 2; occupancy paper, section 1). Run one fragment at a time (`ordered`) it is
//! exact.

use fragrace_emu::{ExecConfig, Fragment, FragmentKernel, KernelInfo};

use super::checks::Shape;
use super::run::KbRun;
use super::slots::{rmw_insert, Slots, SplitSlots};
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Check, Frame,
    HazardClass, Params,
};

pub(super) fn algorithms() -> Vec<Box<dyn Algorithm>> {
    vec![Box::new(KbRmw)]
}

/// The read-modify-write capture kernel (Bavoil et al. 2007; `oit.py`'s
/// `FS_KBUF_RMW`).
pub struct RmwStore {
    pub kb: SplitSlots,
    pub k: u32,
}

impl FragmentKernel for RmwStore {
    fn info(&self) -> KernelInfo {
        // Each fragment loads its pixel's k depths first: prefetched ahead of shading.
        KernelInfo::new("kb-rmw-store").with_pixel_array(self.kb.depth, self.k)
    }
    async fn shade(&self, f: impl Fragment) {
        let base = f.pixel_index() * self.k;
        rmw_insert(
            f,
            self.kb,
            base,
            self.k as usize,
            f.depth(),
            f.primitive_id(),
        )
        .await;
    }
}

/// `kb-rmw`: see the module documentation.
pub struct KbRmw;

impl Algorithm for KbRmw {
    /// Its capture passes run through `KbRun::capture`, which puts them behind occupancy
    /// culling when asked.
    fn takes_occupancy(&self) -> bool {
        true
    }
    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "kb-rmw",
            family: "k-buffer",
            summary: "the original k-buffer: plain load of the k slots, sorted insertion, plain store of all k \
                      (read-modify-write hazard by design)",
            source: "Bavoil et al. 2007 (I3D); depth-fighting paper [17], section 2 and Table 1 (KB); \
                     llvmpipe peer `kbuf-rmw`",
            passes: "1 geometry + 1 full-screen (resolve)",
            memory: "8 k bytes: k depths + k primitive ids (Table 1, KB: 2K + 2 words with the colour and depth \
                     targets); + 16-byte resolve target",
            hazard: HazardClass::HazardProne,
            capacity: Capacity::KNearest,
        }
    }


    /// The capture pass and the resolve; the slots are read back and checked afterwards
    /// ([`AlgoResult::deferred`]).
    fn run_frame(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        let mut run = KbRun::new(frame, params, exec)?;
        let kb = SplitSlots::new(&mut run.device, run.n, run.k)?;
        let report = run.capture(&RmwStore { kb, k: run.k })?;
        let slots = Slots::Split(kb);
        let h = report.hazards;
        let width = frame.width;
        run.finish_deferred(slots, report, 0, 0, move |_, raw| {
            let shape = Shape::of(raw, true, None);
            Ok(vec![
                Check::new(
                    "slot corruption by races (informational)",
                    true,
                    shape.detail(width),
                ),
                Check::new(
                    "hazards seen by the detector (informational)",
                    true,
                    format!(
                        "lost updates {}, races {}, torn records {}",
                        h.lost_updates, h.races, h.torn
                    ),
                ),
            ])
        })
    }
}

#[cfg(test)]
mod tests {
    use fragrace_emu::{ExecConfig, Policy};

    use super::super::slots::{depth_key, pack64, unpack64, MAX_K};
    use super::*;
    use crate::algo::CapturedFrag;
    use crate::testing::*;

    #[test]
    fn exact_when_run_in_order() {
        let mesh = quads(16);
        let frame = frame(&mesh, 16);
        for k in [1, 4, 8, 16] {
            let params = Params {
                k,
                ..Params::default()
            };
            let (r, m) = run(&KbRmw, &frame, &params, &ExecConfig::ordered());
            assert_eq!(
                m.error_pixels, 0,
                "k = {k}: first error {:?}",
                m.first_error
            );
            assert_eq!(r.report.hazards.total(), 0);
            assert_image_matches_capture(&r, &params, "ordered");
        }
    }

    #[test]
    fn loses_fragments_when_fragments_of_a_pixel_race() {
        let mesh = quads(16);
        let frame = frame(&mesh, 16);
        let params = Params::default();
        let mut wrong_runs = 0;
        for seed in 0..4 {
            let (r, m) = run(&KbRmw, &frame, &params, &scheduled(Policy::Random, seed));
            assert!(
                r.report.hazards.lost_updates > 0,
                "seed {seed}: the detector sees lost updates"
            );
            assert!(
                r.report.hazards.races > 0,
                "seed {seed}: the detector sees races"
            );
            if m.error_pixels > 0 {
                wrong_runs += 1;
            }
            assert!(m.robustness <= 1.0);
        }
        assert_eq!(
            wrong_runs, 4,
            "every random schedule loses fragments somewhere (EPR > 0)"
        );
    }

    #[test]
    fn loses_fragments_in_lockstep_warps() {
        // At 8 x 8 a warp of 64 fragments holds fragments of one pixel from consecutive
        // quads, whose lanes interleave at every access whatever the threads do.
        let mesh = quads(16);
        let frame = frame(&mesh, 8);
        let (_, m) = run(&KbRmw, &frame, &Params::default(), &ExecConfig::parallel(2));
        assert!(
            m.error_pixels > 0,
            "parallel lockstep warps lose fragments too"
        );
    }

    #[test]
    fn rejects_bad_k() {
        let mesh = quads(2);
        let frame = frame(&mesh, 8);
        for k in [0, MAX_K + 1] {
            let params = Params {
                k,
                ..Params::default()
            };
            assert!(matches!(
                KbRmw.run(&frame, &params, &ExecConfig::ordered()),
                Err(AlgoError::Invalid(_))
            ));
        }
    }

    #[test]
    fn depth_keys_keep_the_float_order() {
        let ds = [0.0f32, -0.0, 1e-30, 0.25, 0.5, 0.5000001, 0.999, 1.0];
        for a in ds {
            for b in ds {
                assert_eq!(depth_key(a) < depth_key(b), a < b, "{a} vs {b}");
            }
            let c = unpack64(pack64(a, 7));
            assert_eq!((c.depth, c.prim), (a + 0.0, 7));
        }
    }

    #[test]
    fn shape_flags_corruption() {
        let f = |d: f32, p: u32| Some(CapturedFrag { depth: d, prim: p });
        let good = vec![vec![f(0.1, 1), f(0.2, 0), None]];
        assert!(Shape::of(&good, true, Some(&[2])).ok());
        assert_eq!(Shape::of(&good, true, Some(&[1])).wrong_count, 1);
        assert_eq!(
            Shape::of(&[vec![f(0.2, 1), f(0.1, 0), None]], true, None).unsorted,
            1
        );
        assert_eq!(
            Shape::of(&[vec![f(0.1, 1), None, f(0.2, 0)]], true, None).gaps,
            1
        );
        assert_eq!(
            Shape::of(&[vec![f(0.1, 1), f(0.1, 1), None]], true, None).duplicates,
            1
        );
        // Depth-only order accepts primitives in any order at equal depths.
        assert!(Shape::of(&[vec![f(0.1, 5), f(0.1, 2)]], false, None).ok());
    }
}
