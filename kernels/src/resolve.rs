//! The resolve pass that ends every buffer-based algorithm (depth-fighting paper, section 2:
//! "an additional fullscreen post-processing pass to sort the captured fragments"): one
//! invocation per pixel writes the composite of what its pixel kept to an RGBA32F target, and
//! the host reads that target back as the result image.
//!
//! The A-buffers, the k-buffers, the k+-buffer, SRAB and WBOIT differ only in the resolve
//! *kernel*; the target, its fixed-function state, the pass and the readback are the same for
//! all of them, and so is the target's share of `AlgoResult::storage_bytes`. They live here,
//! once, so that every algorithm's image and storage figure are produced the same way.

use fragrace_emu::{
    Device, ExecConfig, Format, Fragment, FragmentKernel, FragmentState, Framebuffer, PassReport,
    SampleCount, TargetState,
};

use crate::algo::{AlgoError, CapturedFrag, Frame, Params};
use crate::common::{self, composite, composite_frags, prim_rgb};

/// Bytes per pixel of the resolve target (one RGBA32F texel).
pub const TARGET_BYTES: u64 = 16;

/// A single-sample framebuffer whose target 0 is the resolve's RGBA32F composite. The
/// A-buffers also run their geometry passes on it (with no target written).
pub fn framebuffer(frame: &Frame<'_>) -> Result<Framebuffer, AlgoError> {
    common::framebuffer(frame, SampleCount::X1, &[Format::RGBA32F])
}

/// Fixed-function state of a resolve pass: write target 0, no tests, no blending.
pub fn state() -> FragmentState {
    let mut s = FragmentState::new();
    s.targets = vec![TargetState::new(Format::RGBA32F)];
    s
}

/// Runs the full-screen resolve `kernel` into target 0 of `fb`.
pub fn pass<K: FragmentKernel>(
    device: &Device,
    fb: &mut Framebuffer,
    kernel: &K,
    exec: &ExecConfig,
) -> Result<PassReport, AlgoError> {
    Ok(device.fullscreen(fb, &state(), kernel, exec)?)
}

/// Reads the resolve target back as the result image (RGBA, row-major, top row first).
pub fn read_image(fb: &Framebuffer) -> Vec<[f32; 4]> {
    fb.image(0)
        .texels
        .iter()
        .map(|t| t.map(f32::from_bits))
        .collect()
}

/// The composite a resolve kernel applies: every fragment at the constant opacity
/// `params.alpha`, front to back over `params.background` (as the llvmpipe peer does).
#[derive(Clone, Copy, Debug)]
pub struct Composite {
    pub alpha: f32,
    pub background: [f32; 3],
}

impl Composite {
    pub fn of(params: &Params) -> Composite {
        Composite {
            alpha: params.alpha,
            background: params.background,
        }
    }

    /// The bits the composite of no fragment (the background) writes to target 0: what a
    /// resolve declares it outputs at pixels no geometry reached
    /// ([`KernelInfo::with_untouched_output`](fragrace_emu::KernelInfo::with_untouched_output)),
    /// where its buffers hold nothing. The oracle checks every empty pixel's image against
    /// it.
    pub fn background_bits(&self) -> [u32; 4] {
        composite_frags(&[], self.alpha, self.background).map(f32::to_bits)
    }

    /// Writes the composite of `frags` (already in front-to-back order) to target 0.
    #[inline]
    pub fn output(&self, f: &impl Fragment, frags: &[CapturedFrag]) {
        f.output(0, composite_frags(frags, self.alpha, self.background));
    }

    /// [`Composite::output`] of fragments given as sort keys ([`crate::common::sort_key`],
    /// already sorted): the same colours (a key's low word is its primitive) in the same
    /// order, so the same bits.
    #[inline]
    pub fn output_keys(&self, f: &impl Fragment, keys: &[u64]) {
        let colors = keys.iter().map(|&k| prim_rgb(k as u32));
        f.output(0, composite(colors, self.alpha, self.background));
    }
}
