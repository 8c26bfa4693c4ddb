//! `dfb`: the dynamic fragment buffer (Maule et al. 2012, "\[MCTB12\]" of the z-thickness paper),
//! and the slot claim its store pass shares with SB's (`claim_slot`).
//!
//! DFB as the z-thickness fragment-merging paper uses it (section 4.3, "Unbounded memory usage
//! approach", and section 5.1.2, "Performance analysis"): a **count pass** counts the fragments
//! of every pixel with an atomic add, an **offset table** (the exclusive prefix sum of the
//! counts over all pixels) gives every pixel a contiguous range, a **store pass** puts each
//! fragment at `offset + atomicAdd(fill)` (only an atomic count, no read-modify-write of the
//! fragment data, hence no hazard), and the **resolve pass** sorts each range (insertion sort
//! under 16 fragments, shell sort above, \[VPF15\] as cited in 5.1.2) and composites.
//!
//! The prefix sum runs on the device as three full-screen passes (a reduce-then-scan with rows
//! as blocks, the classic three-phase GPU scan): one invocation per row scans its row, one
//! invocation scans the row totals, then every pixel adds its row's base. Only the total is
//! read back by the host, to allocate the fragment arrays (a GPU would read back the same
//! word, or allocate a worst-case chunk as the z-thickness paper does with N = 1024).
//!
//! The array resolve and readback it shares with FAB and SB are in [`super::array`], the
//! checks in [`super::checks`], the run scaffolding (with what follows the scan, shared with
//! SB: [`super::run::Counted`]) in [`super::run`].

use fragrace_emu::{Buf, ExecConfig, Fragment, FragmentKernel, KernelInfo};

use super::array::{store_fragment, FragmentArrays, Layout};
use super::run::{AbRun, Counted};
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Frame, HazardClass, Params,
};
use crate::basic::CountKernel;

pub(super) fn algorithms() -> Vec<Box<dyn Algorithm>> {
    vec![Box::new(Dfb)]
}

/// Scan phase 1: the invocation at column 0 of each row writes the exclusive prefix sum of
/// its row's counts into `offsets` and the row's total into `row_total[y]` (a row is one
/// scan block; the other invocations of the row have nothing to do).
pub(crate) struct RowScan {
    pub counts: Buf<u32>,
    pub offsets: Buf<u32>,
    pub row_total: Buf<u32>,
}

impl FragmentKernel for RowScan {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("dfb-scan-rows")
    }
    async fn shade(&self, f: impl Fragment) {
        if f.x() != 0 {
            return;
        }
        let row = f.y() * f.width();
        let mut sum = 0u32;
        for x in 0..f.width() {
            let c = f.load(self.counts, row + x).await;
            f.store(self.offsets, row + x, sum).await;
            sum = sum.wrapping_add(c);
        }
        f.store(self.row_total, f.y(), sum).await;
    }
}

/// Scan phase 2: pixel (0, 0) turns the row totals into the rows' exclusive bases, in place,
/// and writes the grand total.
pub(crate) struct RowTotalsScan {
    pub row_total: Buf<u32>,
    pub total: Buf<u32>,
}

impl FragmentKernel for RowTotalsScan {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("dfb-scan-row-totals")
    }
    async fn shade(&self, f: impl Fragment) {
        if f.pixel_index() != 0 {
            return;
        }
        let mut sum = 0u32;
        for y in 0..f.height() {
            let t = f.load(self.row_total, y).await;
            f.store(self.row_total, y, sum).await;
            sum = sum.wrapping_add(t);
        }
        f.store(self.total, 0, sum).await;
    }
}

/// Scan phase 3: every pixel adds its row's base to its offset.
pub(crate) struct AddRowBase {
    pub offsets: Buf<u32>,
    pub row_base: Buf<u32>,
}

impl FragmentKernel for AddRowBase {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("dfb-scan-add")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let base = f.load(self.row_base, f.y()).await;
        let o = f.load(self.offsets, p).await;
        f.store(self.offsets, p, o.wrapping_add(base)).await;
    }
}

/// The index of the invoking fragment within its pixel's counted range, as the store passes
/// of DFB and SB take it: `i = atomicAdd(fill[p], 1)`. Past `counts[p]` (impossible unless
/// the count and store passes disagree) the fragment gets none: it is dropped and counted in
/// `overflow[0]` rather than written into another pixel's range.
pub(super) async fn claim_slot(
    f: &impl Fragment,
    counts: Buf<u32>,
    fill: Buf<u32>,
    overflow: Buf<u32>,
) -> Option<u32> {
    let p = f.pixel_index();
    let i = f.atomic_add(fill, p, 1).await;
    if i >= f.load(counts, p).await {
        f.atomic_add(overflow, 0, 1).await;
        return None;
    }
    Some(i)
}

/// DFB store pass: slot = `offsets[p] + atomicAdd(fill[p], 1)` (`claim_slot`).
pub struct DfbStore {
    pub counts: Buf<u32>,
    pub offsets: Buf<u32>,
    pub fill: Buf<u32>,
    pub depth: Buf<f32>,
    pub prim: Buf<u32>,
    pub overflow: Buf<u32>,
}

impl FragmentKernel for DfbStore {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("dfb-store")
    }
    async fn shade(&self, f: impl Fragment) {
        let Some(i) = claim_slot(&f, self.counts, self.fill, self.overflow).await else {
            return;
        };
        let p = f.pixel_index();
        let slot = f.load(self.offsets, p).await.wrapping_add(i);
        store_fragment(&f, self.depth, self.prim, slot).await;
    }
}

/// `dfb`: the dynamic fragment buffer (count, device scan, store, sort-and-composite resolve).
pub struct Dfb;

impl Algorithm for Dfb {
    /// Neither k (it keeps every fragment) nor a spin cap.
    fn reads(&self, _: crate::Param) -> bool {
        false
    }

    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "dfb",
            family: "a-buffer",
            summary: "dynamic fragment buffer: count pass, prefix sum of the counts (3 full-screen passes), \
                      store at offset + atomic fill, resolve sorts (insertion < 16, shell above) and composites",
            source: "Maule et al. 2012 [MCTB12] as used by the z-thickness fragment-merging paper, sections 4.3 and 5.1.2",
            passes: "2 geometry (count, store) + 4 full-screen (3 scan, resolve)",
            memory: "12 + 8 n bytes (count, offset, fill; depth + primitive per fragment), \
                     as SB's 2 C(Zall) + 3 words in Table 1 of the depth-fighting paper",
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
        let device = &mut run.device;
        let counts = device.buffer::<u32>("dfb-counts", n as u64)?;
        let offsets = device.buffer::<u32>("dfb-offsets", n as u64)?;
        let fill = device.buffer::<u32>("dfb-fill", n as u64)?;
        let row_total = device.buffer::<u32>("dfb-row-totals", frame.height.max(1) as u64)?;
        let total_buf = device.buffer::<u32>("dfb-total", 1)?;
        let overflow = device.buffer::<u32>("dfb-overflow", 1)?;

        let mut report = run.capture(&CountKernel { counts })?;
        report.merge(&run.fullscreen(&RowScan {
            counts,
            offsets,
            row_total,
        })?);
        report.merge(&run.fullscreen(&RowTotalsScan {
            row_total,
            total: total_buf,
        })?);
        report.merge(&run.fullscreen(&AddRowBase {
            offsets,
            row_base: row_total,
        })?);
        let total = run.device.memory.read(total_buf)?[0];

        let arrays = FragmentArrays::new(&mut run.device, "dfb", total as u64)?;
        let store = DfbStore {
            counts,
            offsets,
            fill,
            depth: arrays.depth,
            prim: arrays.prim,
            overflow,
        };
        let counted = Counted {
            counts,
            fill,
            overflow,
            layout: Layout::Offsets { offsets },
            arrays,
            total,
        };
        counted.store_and_finish(run, report, &store, [])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::*;

    #[test]
    fn dfb_is_exact_under_every_executor() {
        assert_exact_and_hazard_free_everywhere(&Dfb);
    }

    #[test]
    fn dfb_shell_sorts_deep_pixels() {
        // 20 fragments per pixel: the resolve takes the shell-sort branch.
        let mesh = stack(20);
        let f = frame_sized(&mesh, 6, 5);
        for exec in [
            ExecConfig::ordered(),
            ExecConfig::parallel(3),
            ExecConfig::scheduled(fragrace_emu::Policy::Random, 3),
        ] {
            assert_exact(&Dfb, &f, &Params::default(), &exec);
        }
    }
}
