//! One run of an A-buffer: the scaffolding every algorithm of this family shares around its
//! own kernels.
//!
//! Every A-buffer runs on a fresh device, puts all its passes on one framebuffer whose only
//! target is the resolve's composite ([`crate::resolve`]), captures with the pass state that
//! lets every fragment through ([`capture_state`]), ends with a full-screen resolve, and
//! returns the capture, the image, the shared invariants ([`super::checks::capture_checks`])
//! after its own, and the storage of its buffers plus the resolve target. [`AbRun`] does
//! those steps once for all of them, so that an algorithm's `run` reads as its passes and
//! its own invariants only. (The k-buffers' counterpart is `kbuffer::run::KbRun`.) The
//! count-scan-store A-buffers (DFB, z-thickness paper section 4.3; SB, depth-fighting paper
//! section 2) differ only in their scans, so [`Counted`] does what follows the scan once.
//!
//! Each algorithm keeps its merged [`PassReport`] itself, starting it from its first pass
//! (or from an empty report, as `ll` does when its count pass is optional): merging changes
//! the order of equally hot hotspots, so the starting point is part of the result.

use fragrace_emu::{
    Buf, Device, ExecConfig, FragmentKernel, FragmentState, Framebuffer, PassReport,
};

use super::array::{ArrayResolve, FragmentArrays, Layout};
use super::checks::{
    capture_checks, count_store_check, ranges_check, stored_once_check, CaptureOrder,
};
use crate::algo::{AlgoError, AlgoResult, Capture, Check, Deferred, Frame, Params};
use crate::common::{self, capture_state, geometry_pass, pixels};
use crate::resolve::{self, Composite};

/// The device, the framebuffer and the inputs of one A-buffer run.
pub(super) struct AbRun<'a> {
    pub device: Device,
    pub frame: Frame<'a>,
    pub params: &'a Params,
    pub exec: &'a ExecConfig,
    /// Pixels of the frame.
    pub n: usize,
    /// Every pass's framebuffer; target 0 is the resolve's (geometry passes write none).
    fb: Framebuffer,
    /// Bytes this frame uses that an earlier frame of the same draw kept for it instead of
    /// allocating them on the device (`ll`'s kept counts): storage all the same.
    pub kept_bytes: u64,
    /// Whose order the capture is in ([`CaptureOrder::Resolve`] unless the algorithm says
    /// otherwise): which of the family's checks apply.
    pub order: CaptureOrder,
}

impl<'a> AbRun<'a> {
    pub(super) fn new(
        frame: &Frame<'a>,
        params: &'a Params,
        exec: &'a ExecConfig,
    ) -> Result<AbRun<'a>, AlgoError> {
        Ok(AbRun {
            // The resolve skips the pixels no geometry reached (`with_untouched_output`).
            device: common::fresh(exec).with_coverage(fragrace_emu::Coverage::Tracked),
            frame: *frame,
            params,
            exec,
            n: pixels(frame),
            fb: resolve::framebuffer(frame)?,
            kept_bytes: 0,
            order: CaptureOrder::Resolve,
        })
    }

    /// One geometry pass of the frame with `kernel`, every fragment through.
    pub(super) fn capture<K: FragmentKernel>(
        &mut self,
        kernel: &K,
    ) -> Result<PassReport, AlgoError> {
        geometry_pass(
            &self.device,
            &mut self.fb,
            &self.frame,
            &capture_state(),
            kernel,
            self.exec,
        )
    }

    /// One full-screen pass with `kernel`, writing no target (the scans and allocations
    /// between the geometry passes).
    pub(super) fn fullscreen<K: FragmentKernel>(
        &mut self,
        kernel: &K,
    ) -> Result<PassReport, AlgoError> {
        Ok(self
            .device
            .fullscreen(&mut self.fb, &FragmentState::new(), kernel, self.exec)?)
    }

    /// The full-screen resolve with `kernel`, into the resolve target.
    pub(super) fn resolve<K: FragmentKernel>(
        &mut self,
        kernel: &K,
    ) -> Result<PassReport, AlgoError> {
        resolve::pass(&self.device, &mut self.fb, kernel, self.exec)
    }

    /// The store pass with `store`, then the resolve with `resolve` (tile by tile when the
    /// resolve declares by-region reads and the executor can), both merged into
    /// `report`; returns the fragments the store pass generated (what the algorithm's
    /// "every fragment stored" check accounts for).
    pub(super) fn store_and_resolve<S: FragmentKernel, R: FragmentKernel>(
        &mut self,
        report: &mut PassReport,
        store: &S,
        resolve: &R,
    ) -> Result<u64, AlgoError> {
        // A resolve that reads by region runs tile by tile with the store pass where the
        // executor can (`Device::draw_then_fullscreen`).
        let draw = fragrace_emu::Draw::new(self.frame.mesh, self.frame.view_proj);
        let (store_report, resolve_report) = self.device.draw_then_fullscreen(
            &mut self.fb,
            &draw,
            &capture_state(),
            store,
            &resolve::state(),
            resolve,
            self.exec,
        )?;
        report.merge(&store_report);
        report.merge(&resolve_report);
        Ok(store_report.stats.fragments_generated)
    }

    /// [`AbRun::finish`] with the readbacks left out of the frame: the result carries them
    /// as [`Deferred`] work, which reads the image back, calls `work` on the device (the
    /// buffers' readback and walk: the capture, then the algorithm's `own` and `later`
    /// checks) and assembles the checks in [`AbRun::finish`]'s order.
    pub(super) fn finish_deferred(
        self,
        report: PassReport,
        dropped: u64,
        work: impl FnOnce(&Device) -> Result<Readback, AlgoError> + Send + 'static,
    ) -> AlgoResult {
        let storage_bytes =
            self.device.memory.bytes() + self.kept_bytes + self.n as u64 * resolve::TARGET_BYTES;
        let AbRun {
            device,
            params,
            fb,
            order,
            ..
        } = self;
        let params = params.clone();
        let deferred = Deferred::new(move |r: &mut AlgoResult| {
            let Readback {
                capture,
                own,
                later,
            } = work(&device)?;
            let image = resolve::read_image(&fb);
            let mut checks = own;
            checks.extend(capture_checks(&capture, order, &image, &params, &r.report));
            checks.extend(later);
            r.checks.extend(checks);
            r.capture = Some(capture);
            r.image = Some(image);
            Ok(())
        });
        AlgoResult {
            storage_bytes,
            report,
            dropped,
            deferred: Some(deferred),
            ..Default::default()
        }
    }

    /// Assembles the result: the resolve image read back, the checks (`own`, then the
    /// family's [`capture_checks`], then `later`: the algorithm's checks that exist only for
    /// some parameters), and the storage of every buffer plus the resolve target.
    pub(super) fn finish(
        self,
        capture: Capture,
        report: PassReport,
        dropped: u64,
        own: Vec<Check>,
        later: impl IntoIterator<Item = Check>,
    ) -> AlgoResult {
        let image = resolve::read_image(&self.fb);
        let mut checks = own;
        checks.extend(capture_checks(
            &capture,
            self.order,
            &image,
            self.params,
            &report,
        ));
        checks.extend(later);
        AlgoResult {
            capture: Some(capture),
            image: Some(image),
            storage_bytes: self.device.memory.bytes()
                + self.kept_bytes
                + self.n as u64 * resolve::TARGET_BYTES,
            report,
            checks,
            dropped,
            ..Default::default()
        }
    }
}

/// What the deferred readback of [`AbRun::finish_deferred`] found: the capture, the
/// algorithm's own checks (before the family's) and its later ones (after them).
pub(super) struct Readback {
    pub capture: Capture,
    pub own: Vec<Check>,
    pub later: Vec<Check>,
}

/// A count-scan-store A-buffer once its scan has run: the buffers its store pass and resolve
/// share (`counts`, `fill` and `overflow` of [`super::dfb::claim_slot`], the fragment arrays),
/// where the scan put each pixel's range, and the scan's total.
pub(super) struct Counted {
    pub counts: Buf<u32>,
    pub fill: Buf<u32>,
    pub overflow: Buf<u32>,
    pub layout: Layout,
    pub arrays: FragmentArrays,
    pub total: u32,
}

impl Counted {
    /// Runs the store pass `store` (writing into `arrays`) and the resolve, and assembles the
    /// result with the checks every count-scan-store A-buffer owes, in this order: the store
    /// pass filled what the count pass counted, the covered pixels' counted ranges tile
    /// `[0, total)`, the algorithm's `own` checks, every generated fragment stored once.
    pub(super) fn store_and_finish<S: FragmentKernel>(
        &self,
        mut run: AbRun<'_>,
        mut report: PassReport,
        store: &S,
        own: impl IntoIterator<Item = Check>,
    ) -> Result<AlgoResult, AlgoError> {
        let resolve = ArrayResolve {
            layout: self.layout,
            lens: self.fill,
            limit: Some(self.counts),
            arrays: self.arrays,
            composite: Composite::of(run.params),
        };
        let generated = run.store_and_resolve(&mut report, store, &resolve)?;

        let memory = &run.device.memory;
        let counts = memory.read(self.counts)?;
        let fill = memory.read(self.fill)?;
        let dropped = memory.read(self.overflow)?[0] as u64;
        let starts = self.layout.starts(memory, counts.len())?;
        let counted: Vec<(u32, u32)> = (0..counts.len())
            .filter(|&p| counts[p] > 0)
            .map(|p| (starts[p], counts[p]))
            .collect();
        let capture = resolve.capture(&run.device, &run.frame)?;
        let mut checks = vec![
            count_store_check(&counts, &fill),
            ranges_check(&counted, self.total),
        ];
        checks.extend(own);
        let stored = capture.frags.len() as u64;
        checks.push(stored_once_check(stored, dropped, generated));
        Ok(run.finish(capture, report, dropped, checks, []))
    }
}
