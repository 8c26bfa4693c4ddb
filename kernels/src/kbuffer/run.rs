//! One run of a k-buffer ([`KbRun`]): capture pass, full-screen resolve, readback and
//! result, shared by every k-buffer of this folder that keeps `(depth, primitive)` slots.

use fragrace_emu::{
    Buf, Device, ExecConfig, Fragment, FragmentKernel, Framebuffer, KernelInfo, PassReport,
    SampleCount,
};

use super::slots::{k_of, Slots, MAX_K};
use crate::algo::{AlgoError, AlgoResult, Capture, CapturedFrag, Check, Deferred, Frame, Params};
use crate::common::{self, capture_state, framebuffer, geometry_pass, pixels, sort_fragments};
use crate::occupancy::Culling;
use crate::resolve::{self, Composite};

/// The full-screen resolve every buffer-based method needs (depth-fighting paper, section 2:
/// "an additional fullscreen post-processing pass to sort the captured fragments"; `oit.py`'s
/// `FS_KBUF_RESOLVE`): read the pixel's slots, sort, composite front to back.
struct Resolve {
    slots: Slots,
    k: u32,
    composite: Composite,
}

impl FragmentKernel for Resolve {
    fn info(&self) -> KernelInfo {
        // A pixel no fragment reached has every slot empty: it writes the background.
        KernelInfo::new("kb-resolve").with_untouched_output(self.composite.background_bits())
    }
    async fn shade(&self, f: impl Fragment) {
        let base = f.pixel_index() * self.k;
        let mut frags = [CapturedFrag {
            depth: 0.0,
            prim: 0,
        }; MAX_K as usize];
        let mut n = 0;
        for i in 0..self.k {
            if let Some(c) = self.slots.load(f, base + i).await {
                frags[n] = c;
                n += 1;
            }
        }
        sort_fragments(&mut frags[..n]);
        self.composite.output(&f, &frags[..n]);
    }
}

/// One run of a k-buffer: the device, the frame, the parameters and the executor, and the
/// steps every k-buffer of this folder shares (capture pass, resolve, readback, result). The
/// A-buffers' counterpart is `abuffer::run::AbRun`.
pub(super) struct KbRun<'a> {
    pub device: Device,
    pub frame: Frame<'a>,
    pub params: &'a Params,
    pub exec: &'a ExecConfig,
    pub k: u32,
    pub n: usize,
    /// The capture passes' framebuffer (its depth buffer holds the culling bound).
    fb: Option<Framebuffer>,
    /// Occupancy culling, when the parameters ask for it.
    culling: Option<Culling>,
}

impl<'a> KbRun<'a> {
    pub(super) fn new(
        frame: &Frame<'a>,
        params: &'a Params,
        exec: &'a ExecConfig,
    ) -> Result<KbRun<'a>, AlgoError> {
        Ok(KbRun {
            // The resolve skips the pixels no geometry reached (`with_untouched_output`).
            device: common::fresh(exec).with_coverage(fragrace_emu::Coverage::Tracked),
            frame: *frame,
            params,
            exec,
            k: k_of(params)?,
            n: pixels(frame),
            fb: None,
            culling: None,
        })
    }

    /// One capture pass of the frame with `kernel`, every fragment through (no targets), or,
    /// with occupancy culling, every fragment up to its pixel's bound: the first capture
    /// runs the culling stage. The report is the capture pass's alone (the stage's passes
    /// join the result in [`KbRun::finish`]), so the algorithm's checks see its own pass.
    pub(super) fn capture<K: FragmentKernel>(
        &mut self,
        kernel: &K,
    ) -> Result<PassReport, AlgoError> {
        let fb = match &mut self.fb {
            Some(fb) => fb,
            None => {
                let mut fb = framebuffer(&self.frame, SampleCount::X1, &[])?;
                self.culling = Culling::prepare(
                    &mut self.device,
                    &mut fb,
                    &self.frame,
                    self.params,
                    self.exec,
                )?;
                self.fb.insert(fb)
            }
        };
        let state = match self.culling {
            Some(_) => Culling::peel_state(&capture_state()),
            None => capture_state(),
        };
        let report = geometry_pass(&self.device, fb, &self.frame, &state, kernel, self.exec)?;
        if let Some(c) = &mut self.culling {
            c.add_peel(&report);
        }
        Ok(report)
    }

    /// The sum of a per-pixel counter buffer (the instrumentation counts of the invariants).
    pub(super) fn total(&self, counter: Buf<u32>) -> Result<u64, AlgoError> {
        counter_total(&self.device, counter)
    }

    /// [`KbRun::finish`] with the readbacks left out of the frame: the resolve runs now,
    /// and the result carries as [`Deferred`] work the image's readback, the slots' (read
    /// once), the algorithm's `own` checks on them (with the device for its other buffers)
    /// and the capture.
    pub(super) fn finish_deferred(
        self,
        slots: Slots,
        mut report: PassReport,
        dropped: u64,
        target_bytes: u64,
        own: impl FnOnce(&Device, &[Vec<Option<CapturedFrag>>]) -> Result<Vec<Check>, AlgoError>
            + Send
            + 'static,
    ) -> Result<AlgoResult, AlgoError> {
        let mut fb = resolve::framebuffer(&self.frame)?;
        let kernel = Resolve {
            slots,
            k: self.k,
            composite: Composite::of(self.params),
        };
        report.merge(&resolve::pass(&self.device, &mut fb, &kernel, self.exec)?);
        let culling = self.culling.map(|c| {
            let (stage, summary) = c.finish();
            report.merge(&stage);
            summary
        });
        let depth_bytes = if culling.is_some() { 4 } else { 0 };
        let storage_bytes = self.device.memory.bytes()
            + self.n as u64 * (target_bytes + depth_bytes + resolve::TARGET_BYTES);
        let (device, k, width, height) = (self.device, self.k, self.frame.width, self.frame.height);
        let deferred = Deferred::new(move |r: &mut AlgoResult| {
            let raw = slots.read(&device, k)?;
            r.checks.extend(own(&device, &raw)?);
            r.image = Some(resolve::read_image(&fb));
            let lists = raw.into_iter().map(|l| {
                let mut v: Vec<CapturedFrag> = l.into_iter().flatten().collect();
                sort_fragments(&mut v);
                v
            });
            r.capture = Some(Capture::from_lists(width, height, lists));
            Ok(())
        });
        Ok(AlgoResult {
            report,
            dropped,
            storage_bytes,
            culling,
            deferred: Some(deferred),
            ..Default::default()
        })
    }

    /// Resolves `slots` with the full-screen kernel (the image), reads them back (the
    /// capture: what the buffers hold, sorted front to back) and assembles the result.
    /// `target_bytes` are the per-pixel bytes of render targets of earlier passes.
    pub(super) fn finish(
        self,
        slots: Slots,
        mut report: PassReport,
        checks: Vec<Check>,
        dropped: u64,
        target_bytes: u64,
    ) -> Result<AlgoResult, AlgoError> {
        let mut fb = resolve::framebuffer(&self.frame)?;
        let kernel = Resolve {
            slots,
            k: self.k,
            composite: Composite::of(self.params),
        };
        report.merge(&resolve::pass(&self.device, &mut fb, &kernel, self.exec)?);
        let image = resolve::read_image(&fb);
        // The culling stage's depth buffer (4 bytes a pixel) is storage too.
        let culling = self.culling.map(|c| {
            let (stage, summary) = c.finish();
            report.merge(&stage);
            summary
        });
        let depth_bytes = if culling.is_some() { 4 } else { 0 };
        let lists = slots.read(&self.device, self.k)?.into_iter().map(|l| {
            let mut v: Vec<CapturedFrag> = l.into_iter().flatten().collect();
            sort_fragments(&mut v);
            v
        });
        let capture = Capture::from_lists(self.frame.width, self.frame.height, lists);
        Ok(AlgoResult {
            capture: Some(capture),
            image: Some(image),
            report,
            checks,
            dropped,
            storage_bytes: self.device.memory.bytes()
                + self.n as u64 * (target_bytes + depth_bytes + resolve::TARGET_BYTES),
            culling,
            ..Default::default()
        })
    }
}

/// The sum of a per-pixel counter buffer of `device` (the instrumentation counts of the
/// invariants), also from a frame's deferred checks.
pub(super) fn counter_total(device: &Device, counter: Buf<u32>) -> Result<u64, AlgoError> {
    Ok(device.memory.read(counter)?.iter().map(|&c| c as u64).sum())
}
