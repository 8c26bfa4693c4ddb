//! One run of an A-buffer: the scaffolding every algorithm of this family shares around its
//! own kernels.
//!
//! Every A-buffer runs on a fresh device, puts all its passes on one framebuffer whose only
//! target is the resolve's composite ([`crate::resolve`]), captures with the pass state that
//! lets every fragment through ([`capture_state`]), ends with a full-screen resolve, and
//! returns the capture, the image, the shared invariants ([`super::checks::capture_checks`])
//! after its own, and the storage of its buffers plus the resolve target. [`AbRun`] does
//! those steps once for all of them, so that an algorithm's `run` reads as its passes and
//! its own invariants only. (The k-buffers' counterpart is `kbuffer::rmw::KbRun`.)
//!
//! Each algorithm keeps its merged [`PassReport`] itself, starting it from its first pass
//! (or from an empty report, as `ll` does when its count pass is optional): merging changes
//! the order of equally hot hotspots, so the starting point is part of the result.

use fragrace_emu::{Device, ExecConfig, FragmentKernel, FragmentState, Framebuffer, PassReport};

use super::checks::capture_checks;
use crate::algo::{AlgoError, AlgoResult, Capture, Check, Frame, Params};
use crate::common::{self, capture_state, geometry_pass, pixels};
use crate::resolve;

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
}

impl<'a> AbRun<'a> {
    pub(super) fn new(
        frame: &Frame<'a>,
        params: &'a Params,
        exec: &'a ExecConfig,
    ) -> Result<AbRun<'a>, AlgoError> {
        Ok(AbRun {
            device: common::fresh(),
            frame: *frame,
            params,
            exec,
            n: pixels(frame),
            fb: resolve::framebuffer(frame)?,
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

    /// The store pass with `store`, then the resolve with `resolve`, both merged into
    /// `report`; returns the fragments the store pass generated (what the algorithm's
    /// "every fragment stored" check accounts for).
    pub(super) fn store_and_resolve<S: FragmentKernel, R: FragmentKernel>(
        &mut self,
        report: &mut PassReport,
        store: &S,
        resolve: &R,
    ) -> Result<u64, AlgoError> {
        let store_report = self.capture(store)?;
        report.merge(&store_report);
        report.merge(&self.resolve(resolve)?);
        Ok(store_report.stats.fragments_generated)
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
        checks.extend(capture_checks(&capture, &image, self.params, &report));
        checks.extend(later);
        AlgoResult {
            capture: Some(capture),
            image: Some(image),
            storage_bytes: self.device.memory.bytes() + self.n as u64 * resolve::TARGET_BYTES,
            report,
            checks,
            dropped,
            ..Default::default()
        }
    }
}
