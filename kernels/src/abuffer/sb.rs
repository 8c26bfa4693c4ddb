//! `sb`: the S-buffer, a sparsity-aware A-buffer (Vasilakis and Fudos 2012, \[25\] of the
//! depth-fighting paper; section 2 and Fig. 3(c) there).
//!
//! The S-buffer "organizes linearly memory into variable contiguous regions for each pixel"
//! and computes "the memory offset lookup table ... in a parallel fashion exploiting sparsity
//! in the pixel space" (depth-fighting paper, section 2). Passes:
//! 1. **count** (geometry): `atomicAdd(count[p], 1)`;
//! 2. **allocate** (full-screen, sparsity-aware): only a *covered* pixel reserves a range,
//!    with one `atomicAdd(group_total[p % G], count[p])` on the counter of its pixel group;
//!    uncovered pixels do nothing and get no range. The returned value is the pixel's offset
//!    inside its group;
//! 3. **group scan** (full-screen, one invocation): the exclusive prefix sum of the `G`
//!    group totals gives every group its base and the grand total (the host reads the total
//!    back to allocate the fragment arrays);
//! 4. **store** (geometry): `slot = group_base[p % G] + offset[p] + atomicAdd(fill[p], 1)`;
//! 5. **resolve** (full-screen): sort each range, composite.
//!
//! Ranges are not in pixel order (their order within a group is the order in which the
//! allocate invocations ran), but they are disjoint and cover `[0, total)` exactly, which is
//! checked on every run together with "the count pass equals the store pass".

use fragrace_emu::{Buf, ExecConfig, Fragment, FragmentKernel, KernelInfo};

use super::array::{store_fragment, FragmentArrays, Layout};
use super::dfb::claim_slot;
use super::run::{AbRun, Counted};
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Check, Frame, HazardClass, Params,
};
use crate::basic::CountKernel;
use crate::common::EMPTY;

pub(super) fn algorithms() -> Vec<Box<dyn Algorithm>> {
    vec![Box::new(SBuffer)]
}

/// Pixel groups sharing one allocation counter: enough to spread the contention of the
/// allocate pass, few enough that their scan is one short serial loop.
const GROUPS: u32 = 64;

/// Allocate pass: a covered pixel reserves `count[p]` words on its group's counter.
pub struct SparseAllocate {
    pub counts: Buf<u32>,
    pub offsets: Buf<u32>,
    pub group_total: Buf<u32>,
    pub groups: u32,
}

impl FragmentKernel for SparseAllocate {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("sb-allocate")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let c = f.load(self.counts, p).await;
        if c == 0 {
            return;
        }
        let local = f.atomic_add(self.group_total, p % self.groups, c).await;
        f.store(self.offsets, p, local).await;
    }
}

/// Group scan: pixel 0 turns the group totals into exclusive group bases and writes the total.
struct GroupScan {
    group_total: Buf<u32>,
    group_base: Buf<u32>,
    total: Buf<u32>,
    groups: u32,
}

impl FragmentKernel for GroupScan {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("sb-group-scan")
    }
    async fn shade(&self, f: impl Fragment) {
        if f.pixel_index() != 0 {
            return;
        }
        let mut sum = 0u32;
        for g in 0..self.groups {
            f.store(self.group_base, g, sum).await;
            sum = sum.wrapping_add(f.load(self.group_total, g).await);
        }
        f.store(self.total, 0, sum).await;
    }
}

/// Store pass: `slot = group_base[g] + offset[p] + atomicAdd(fill[p], 1)`; a fragment past its
/// pixel's counted range (the passes disagree) is dropped and counted, never written into
/// another pixel's range (the claim is DFB's, `claim_slot`).
pub struct SbStore {
    pub counts: Buf<u32>,
    pub offsets: Buf<u32>,
    pub group_base: Buf<u32>,
    pub fill: Buf<u32>,
    pub depth: Buf<f32>,
    pub prim: Buf<u32>,
    pub overflow: Buf<u32>,
    pub groups: u32,
}

impl FragmentKernel for SbStore {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("sb-store")
    }
    async fn shade(&self, f: impl Fragment) {
        let Some(i) = claim_slot(&f, self.counts, self.fill, self.overflow).await else {
            return;
        };
        let p = f.pixel_index();
        let base = f
            .load(self.group_base, p % self.groups)
            .await
            .wrapping_add(f.load(self.offsets, p).await);
        store_fragment(&f, self.depth, self.prim, base.wrapping_add(i)).await;
    }
}

/// `sb`: the S-buffer.
pub struct SBuffer;

impl Algorithm for SBuffer {
    /// Neither k (it keeps every fragment) nor a spin cap.
    fn reads(&self, _: crate::Param) -> bool {
        false
    }

    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "sb",
            family: "a-buffer",
            summary: "S-buffer: count pass, sparsity-aware allocation (covered pixels reserve ranges on per-group \
                      atomic counters, then a scan of the group totals), store pass, sort-and-composite resolve",
            source: "S-buffer (Vasilakis and Fudos 2012), ref [25] of the depth-fighting paper, section 2, Fig. 3(c), Table 1",
            passes: "2 geometry (count, store) + 3 full-screen (allocate, group scan, resolve)",
            memory: "12 + 8 n bytes (count, offset, fill; depth + primitive per fragment); Table 1: 2 C(Zall) + 3 words",
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
        let mut run = AbRun::new(frame, params, exec)?;
        let n = run.n;
        let groups = GROUPS.min(n.max(1) as u32);
        let device = &mut run.device;
        let counts = device.buffer::<u32>("sb-counts", n as u64)?;
        let offsets = device.buffer::<u32>("sb-offsets", n as u64)?;
        device.memory.fill(offsets, EMPTY)?;
        let fill = device.buffer::<u32>("sb-fill", n as u64)?;
        let group_total = device.buffer::<u32>("sb-group-totals", groups as u64)?;
        let group_base = device.buffer::<u32>("sb-group-bases", groups as u64)?;
        let total_buf = device.buffer::<u32>("sb-total", 1)?;
        let overflow = device.buffer::<u32>("sb-overflow", 1)?;

        let mut report = run.capture(&CountKernel { counts })?;
        report.merge(&run.fullscreen(&SparseAllocate {
            counts,
            offsets,
            group_total,
            groups,
        })?);
        report.merge(&run.fullscreen(&GroupScan {
            group_total,
            group_base,
            total: total_buf,
            groups,
        })?);
        let total = run.device.memory.read(total_buf)?[0];

        // Only the allocate pass writes `offsets` (the store pass and the resolve read them),
        // so its invariant holds from here on.
        let counts_v = run.device.memory.read(counts)?;
        let offsets_v = run.device.memory.read(offsets)?;
        let covered = counts_v.iter().filter(|&&c| c > 0).count();
        let uncovered_with_range = (0..n)
            .filter(|&p| counts_v[p] == 0 && offsets_v[p] != EMPTY)
            .count();
        let only_covered = Check::new(
            "only covered pixels get ranges",
            uncovered_with_range == 0,
            format!("{uncovered_with_range} uncovered pixels with an offset; {covered} covered"),
        );

        let arrays = FragmentArrays::new(&mut run.device, "sb", total as u64)?;
        let store = SbStore {
            counts,
            offsets,
            group_base,
            fill,
            depth: arrays.depth,
            prim: arrays.prim,
            overflow,
            groups,
        };
        let counted = Counted {
            counts,
            fill,
            overflow,
            layout: Layout::Grouped {
                offsets,
                group_base,
                groups,
            },
            arrays,
            total,
        };
        counted.store_and_finish(run, report, &store, [only_covered])
    }
}

#[cfg(test)]
mod tests {
    use fragrace_emu::Policy;

    use super::*;
    use crate::testing::*;

    #[test]
    fn sb_is_exact_under_every_executor() {
        assert_exact_and_hazard_free_everywhere(&SBuffer);
    }

    #[test]
    fn sb_allocates_only_covered_pixels() {
        // One small quad in a larger frame: most pixels uncovered; total storage for fragments
        // equals the fragments generated.
        let mut mesh = fragrace_emu::Mesh::default();
        quad(&mut mesh, [-0.3, -0.3, 0.2, 0.1], 0.1, 0.3);
        quad(&mut mesh, [-0.1, -0.5, 0.4, 0.0], -0.2, 0.0);
        let f = frame_sized(&mesh, 40, 30);
        for exec in [
            ExecConfig::ordered(),
            ExecConfig::parallel(4),
            ExecConfig::scheduled(Policy::Random, 11),
        ] {
            let r = assert_exact(&SBuffer, &f, &Params::default(), &exec);
            let covered = r.capture.as_ref().unwrap();
            let n_covered = (0..covered.pixels())
                .filter(|&p| !covered.pixel(p).is_empty())
                .count();
            assert!(n_covered > 0 && n_covered < 40 * 30 / 4, "{n_covered}");
        }
    }

    #[test]
    fn sb_deep_pixels() {
        let mesh = stack(18);
        let f = frame_sized(&mesh, 5, 7);
        for exec in [
            ExecConfig::ordered(),
            ExecConfig::parallel(2),
            ExecConfig::scheduled(Policy::Pct { depth: 2 }, 1),
        ] {
            assert_exact(&SBuffer, &f, &Params::default(), &exec);
        }
    }
}
