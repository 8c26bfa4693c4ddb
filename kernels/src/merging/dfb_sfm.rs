//! `dfb-sfm`: the dynamic fragment buffer with smooth fragment merging in its resolve (Kim &
//! Kye, "Z-Thickness Blending: Effective Fragment Merging for Multi-Fragment Rendering",
//! section 4.3, "Unbounded memory usage approach", and section 5.1, DFB+SFM).
//!
//! The store side is `dfb`'s (Maule et al. 2012, \[MCTB12\]): a count pass (atomic add per
//! pixel), the offset table (the device prefix sum of `dfb`), a store pass that writes each
//! fragment at `offset + atomicAdd(fill)`: only an atomic count, no read-modify-write, hence
//! no hazard. The resolve pass reads at most N = 1024 fragments of its pixel (the paper's
//! preallocated chunk; fragments past it are dropped and counted), sorts them (insertion sort
//! under 16, shell sort above, section 5.1.2), gives each its z-thickness, runs Algorithm 1
//! (SFM of overlapping neighbours, at most M = k out, tail handling) and composites the M
//! fragments front to back (Algorithm 1, line 23). Every step is deterministic once the
//! fragments are stored, so the image is the same bits under every executor.

use fragrace_emu::{
    Buf, Coverage, ExecConfig, Fragment, FragmentKernel, FragmentState, KernelInfo,
};

use super::algorithm1::output_fragments;
use super::record::{composite, ZFrag};
use super::thickness::ZModel;
use crate::abuffer::dfb::{AddRowBase, DfbStore, RowScan, RowTotalsScan};
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, CapturedFrag, Check, Deferred, Frame,
    HazardClass, Params,
};
use crate::basic::CountKernel;
use crate::common::{self, capture_state, geometry_pass, pixels, sort_fragments};
use crate::resolve;

/// N of Algorithm 1: the most fragments the resolve reads per pixel (the paper's chunk).
pub const MAX_N: u32 = 1024;

/// `dfb-sfm`.
pub struct DfbSfm;

/// The resolve pass: Algorithm 1 over the pixel's sorted fragments, then the composite.
struct SfmResolve {
    counts: Buf<u32>,
    offsets: Buf<u32>,
    fill: Buf<u32>,
    depth: Buf<f32>,
    prim: Buf<u32>,
    model: ZModel,
    beta: f32,
    /// M of Algorithm 1.
    m: u32,
    background: [f32; 3],
    /// Per pixel: fragments output (M' <= M), fragments merged into them, fragments past N.
    out_count: Buf<u32>,
    merged: Buf<u32>,
    past_n: Buf<u32>,
}

impl FragmentKernel for SfmResolve {
    fn info(&self) -> KernelInfo {
        // At a pixel no geometry reached the count is 0: the resolve would store zeros into
        // its zeroed instrumentation words and output the composite of nothing.
        KernelInfo::new("dfb-sfm-resolve")
            .with_untouched_output(composite(&[], self.background).map(f32::to_bits))
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let stored = f.load(self.fill, p).await.min(f.load(self.counts, p).await);
        let n = stored.min(MAX_N);
        let base = f.load(self.offsets, p).await;
        let mut sorted = Vec::with_capacity(n as usize);
        for i in 0..n {
            let slot = base.wrapping_add(i);
            let depth = f.load(self.depth, slot).await;
            let prim = f.load(self.prim, slot).await;
            sorted.push(CapturedFrag { depth, prim });
        }
        sort_fragments(&mut sorted);
        let input: Vec<ZFrag> = sorted
            .iter()
            .map(|c| self.model.fragment(c.depth, c.prim))
            .collect();
        let mut out = Vec::with_capacity(self.m as usize);
        output_fragments(&input, self.m as usize, self.beta, &mut out);
        f.store(self.out_count, p, out.len() as u32).await;
        let merged: f32 = out.iter().map(|z| z.n).sum();
        f.store(self.merged, p, merged as u32).await;
        f.store(self.past_n, p, stored - n).await;
        f.output(0, composite(&out, self.background));
    }
}

impl Algorithm for DfbSfm {
    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "dfb-sfm",
            family: "merging",
            summary:
                "dynamic fragment buffer + smooth fragment merging: count, scan, store as dfb; \
                      the resolve sorts up to N = 1024 fragments, gives each its z-thickness and \
                      merges overlaps with SFM into at most M = k (Algorithm 1, tail handling)",
            source:
                "Kim & Kye, Z-Thickness Blending: Effective Fragment Merging for Multi-Fragment \
                     Rendering, CGF 2021: sec. 3.2.1, 3.3, 4.1, 4.3, Algorithm 1 (DFB+SFM); DFB of \
                     Maule et al. 2012 [MCTB12]",
            passes: "2 geometry (count, store) + 4 full-screen (3 scan, resolve)",
            memory: "24 + 8 n bytes (count, offset, fill; depth + primitive per fragment; \
                     3 words of resolve instrumentation)",
            hazard: HazardClass::HazardFree,
            capacity: Capacity::Image,
        }
    }

    fn run_frame(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        if params.k == 0 {
            return Err(AlgoError::Invalid(
                "k = 0 is invalid: M of Algorithm 1 (--k) must be >= 1".into(),
            ));
        }
        let model = ZModel::of(frame, params)?;
        let n = pixels(frame) as u64;
        // The resolve skips the pixels no geometry reached (`with_untouched_output`).
        let mut device = common::fresh(exec).with_coverage(Coverage::Tracked);
        let counts = device.buffer::<u32>("dfb-sfm-counts", n)?;
        let offsets = device.buffer::<u32>("dfb-sfm-offsets", n)?;
        let fill = device.buffer::<u32>("dfb-sfm-fill", n)?;
        let row_total = device.buffer::<u32>("dfb-sfm-row-totals", frame.height.max(1).into())?;
        let total_buf = device.buffer::<u32>("dfb-sfm-total", 1)?;
        let overflow = device.buffer::<u32>("dfb-sfm-overflow", 1)?;
        let out_count = device.buffer::<u32>("dfb-sfm-out-count", n)?;
        let merged = device.buffer::<u32>("dfb-sfm-merged", n)?;
        let past_n = device.buffer::<u32>("dfb-sfm-past-n", n)?;

        let mut fb = resolve::framebuffer(frame)?;
        let passes = FragmentState::new();
        let mut report = geometry_pass(
            &device,
            &mut fb,
            frame,
            &capture_state(),
            &CountKernel { counts },
            exec,
        )?;
        let scan_rows = RowScan {
            counts,
            offsets,
            row_total,
        };
        report.merge(&device.fullscreen(&mut fb, &passes, &scan_rows, exec)?);
        let scan_totals = RowTotalsScan {
            row_total,
            total: total_buf,
        };
        report.merge(&device.fullscreen(&mut fb, &passes, &scan_totals, exec)?);
        let add = AddRowBase {
            offsets,
            row_base: row_total,
        };
        report.merge(&device.fullscreen(&mut fb, &passes, &add, exec)?);
        let total = device.memory.read(total_buf)?[0];

        let depth = device.buffer::<f32>("dfb-sfm-depth", u64::from(total).max(1))?;
        let prim = device.buffer::<u32>("dfb-sfm-prim", u64::from(total).max(1))?;
        let store = DfbStore {
            counts,
            offsets,
            fill,
            depth,
            prim,
            overflow,
        };
        let store_report = geometry_pass(&device, &mut fb, frame, &capture_state(), &store, exec)?;
        report.merge(&store_report);
        let resolve_kernel = SfmResolve {
            counts,
            offsets,
            fill,
            depth,
            prim,
            model,
            beta: params.merge.beta,
            m: params.k,
            background: params.background,
            out_count,
            merged,
            past_n,
        };
        report.merge(&resolve::pass(&device, &mut fb, &resolve_kernel, exec)?);
        let storage_bytes = device.memory.bytes() + n * resolve::TARGET_BYTES;
        let stats = store_report.stats.clone();
        let m_max = params.k;
        // The buffers are read back and checked after the frame ([`AlgoResult::deferred`]).
        let deferred = Deferred::new(move |r: &mut AlgoResult| {
            let image = resolve::read_image(&fb);
            let memory = &device.memory;
            let (counts, fill) = (memory.read(counts)?, memory.read(fill)?);
            let (out_count, merged) = (memory.read(out_count)?, memory.read(merged)?);
            let past_n = memory.read(past_n)?;
            let lost = u64::from(memory.read(overflow)?[0]);
            let beyond_n: u64 = past_n.iter().map(|&c| u64::from(c)).sum();
            let first = |bad: &dyn Fn(usize) -> bool| (0..counts.len()).find(|&p| bad(p));
            let fill_bad = first(&|p| fill[p] != counts[p]);
            let m_bad = first(&|p| out_count[p] > m_max || (counts[p] > 0) != (out_count[p] > 0));
            let merged_bad = first(&|p| merged[p] + past_n[p] != counts[p]);
            let at = |bad: Option<usize>| match bad {
                Some(p) => format!(
                    "pixel {p}: counted {}, stored {}, out {}, merged {}, past N {}",
                    counts[p], fill[p], out_count[p], merged[p], past_n[p]
                ),
                None => format!("{} pixels", counts.len()),
            };
            let checks = vec![
                Check::all_shaded(&stats, r.report.faults.len()),
                Check::new(
                    "store pass filled what the count pass counted",
                    fill_bad.is_none() && lost == 0,
                    at(fill_bad),
                ),
                Check::new(
                    "1 <= M' <= M = k fragments out of every covered pixel",
                    m_bad.is_none(),
                    at(m_bad),
                ),
                Check::new(
                    "every stored fragment merged into exactly one output fragment (or past N)",
                    merged_bad.is_none(),
                    at(merged_bad),
                ),
                Check::image_finite(&image),
            ];
            r.image = Some(image);
            r.checks.extend(checks);
            r.dropped = lost + beyond_n;
            Ok(())
        });
        Ok(AlgoResult {
            storage_bytes,
            report,
            deferred: Some(deferred),
            ..Default::default()
        })
    }
}

/// The algorithms of this file, for its family's registry line.
pub(super) fn algorithms() -> Vec<Box<dyn crate::algo::Algorithm>> {
    vec![Box::new(DfbSfm)]
}
