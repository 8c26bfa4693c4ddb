//! Bucket depth peeling: a bucket sort of each pixel's fragments into a bucket array of 32
//! one-fragment buckets held in 8 RGBA32F render targets, written only by fixed-function
//! MAX blending (Liu, Huang, Liu, Wu, "Efficient Depth Peeling via Bucket Sort", HPG 2009).
//!
//! - `bdp` (section 3.2): the pixel's depth range is cut into 16 uniform sub-intervals, each
//!   with a min/max pair of buckets; one geometry pass;
//! - `bdp2` (section 3.2, "multi-pass approach"): a second geometry pass into a new bucket
//!   array keeps the second min/max of each sub-interval;
//! - `adp` (section 3.3 and Table 1): a 1024-bit depth histogram (logic OR into 8 RGBA32UI
//!   targets), its equalisation (a full-screen pass writing the upper bounds of the
//!   non-empty sub-intervals), and a second geometry pass routing each fragment to the
//!   bucket of its bound; batches of 32 for deeper pixels (last paragraph of section 3.3).
//!
//! **Depth range.** Every scheme starts from the per-pixel range `[zNear, zFar]` (section
//! 3.2: exact from the scene, or from "a bounding box or a much simplified visual hull"):
//! the occupancy stage's range pass ([`crate::occupancy::range::pass`], `--range
//! exact|bbox|hull`, [`crate::Params::range`]). It is one geometry pass (of the scene with
//! `exact`, of 12 triangles with `bbox`), counted in `geometry_passes`. A view where the
//! pass finds no depth at any pixel is refused with an error.
//!
//! **Collisions.** A bucket holds one fragment: when several are routed to one bucket, MAX
//! blending keeps the largest and the others are lost (section 3.2). Each scheme counts,
//! per pixel, the fragments it routed to a bucket (one atomic add each) and subtracts the
//! fragments its buckets hold ([`AlgoResult::collisions`], their sum in
//! [`AlgoResult::dropped`]). Collisions are deterministic, not races.
//!
//! **Hazards.** Every write of every pass commutes: MAX blending, logic OR, the range pass's
//! atomic min/max and the routed-fragment counters' atomic adds. Blending runs in API order
//! anyway; the rest gives the same bits in any order. So the output is bit-identical under
//! every executor and policy (test `tests/bucket.rs`): the schemes are free of RMW hazards,
//! as the paper says. Their errors are the collisions.
//!
//! **What is captured.** The buckets hold depths only (32 channels are 32 depths, eq. 1):
//! primitive ids are not kept (`u32::MAX`), so the oracle compares the depths of the `k`
//! nearest ([`Capacity::KNearest`]) and no composite image is produced. The paper's colour
//! mode (packed RGBA8 instead of depths, section 3.2) trades the depths for the colours.

crate::registry::family! {
    bdp,
    adp,
}

use fragrace_emu::{
    BlendEquation, BlendState, Buf, Device, ExecConfig, Format, Fragment, Image, LogicOp,
    PassReport, PassState, TargetState,
};

use crate::algo::{AlgoError, AlgoResult, Capture, CapturedFrag, Check, Frame, Params};
use crate::common::{capture_state, pixels};
use crate::occupancy::range;

pub use adp::Adp;
pub use bdp::{Bdp, Bdp2};

/// Render targets of a bucket array (or a histogram, or an equalised histogram): the 8
/// MRTs of section 3.1.
pub const TARGETS: usize = 8;
/// Buckets of one array: `K = N x B_m / B_d = 8 x 16 / 4` (section 3.1, eq. 1).
pub const BUCKETS: usize = 4 * TARGETS;

/// Bits of `1.0f32`: window depths lie in `[0, 1]`, whose bit patterns are `0..=ONE_BITS`.
const ONE_BITS: u32 = 0x3F80_0000;

/// A fragment's depth as its max bucket holds it: the depth itself (MAX keeps the farthest;
/// 0, the cleared value, is "empty", section 3.1).
#[inline(always)]
pub fn max_key(z: f32) -> f32 {
    // `+ 0.0` turns a -0.0 into +0.0, whose bits order with the positive floats.
    z.clamp(0.0, 1.0) + 0.0
}

/// A fragment's depth as its min bucket holds it: the paper's `1 - d_f`, taken on the bit
/// pattern (`ONE_BITS + 1 - bits(d)`) so that it inverts exactly (the float `1 - d` rounds
/// for `d < 1/2`, and the oracle compares exact depths). Decreasing in the depth, positive
/// for every depth of `[0, 1]`, so MAX keeps the nearest and 0 stays "empty".
#[inline(always)]
pub fn min_key(z: f32) -> f32 {
    f32::from_bits(ONE_BITS + 1 - max_key(z).to_bits())
}

/// The depth of a min bucket's key ([`min_key`]); `None` for an empty bucket.
pub fn from_min_key(key: f32) -> Option<f32> {
    (key.to_bits() != 0).then(|| f32::from_bits(ONE_BITS + 1 - key.to_bits()))
}

/// Writes `value` to bucket `b` of the array and 0 to the 31 others: with MAX blending the
/// others keep what they hold (section 3.1: "we implicitly update them simultaneously by the
/// default value 0").
#[inline(always)]
pub fn write_bucket(f: &impl Fragment, b: usize, value: f32) {
    for t in 0..TARGETS {
        let mut v = [0.0f32; 4];
        if b / 4 == t {
            v[b % 4] = value;
        }
        f.output(t, v);
    }
}

/// Writes the bits `mask` to word `w` of a 32-word array of RGBA32UI targets and 0 to the
/// others (logic OR keeps them).
#[inline(always)]
pub fn write_bits(f: &impl Fragment, w: usize, mask: u32) {
    for t in 0..TARGETS {
        let mut v = [0u32; 4];
        if w / 4 == t {
            v[w % 4] = mask;
        }
        f.output_u32(t, v);
    }
}

/// Word `i` of a pixel's 32-channel array from its 8 images, in bits.
#[inline(always)]
pub fn channel_of(images: &[Image], f: &impl Fragment, i: usize) -> u32 {
    f.texel(&images[i / 4], f.x(), f.y(), 0)[i % 4]
}

/// The 32 channels of pixel `p` (row-major) of 8 images, in bits (host side).
pub fn channels(images: &[Image], p: usize) -> [u32; BUCKETS] {
    std::array::from_fn(|i| images[i / 4].texels[p][i % 4])
}

/// State of a geometry pass writing a bucket array: no depth test, 8 RGBA32F targets with
/// MAX blending (section 3.1).
pub fn bucket_state() -> PassState {
    let max = TargetState {
        blend: Some(BlendState::equation(BlendEquation::Max)),
        ..TargetState::new(Format::RGBA32F)
    };
    let mut s = capture_state();
    s.fragment.targets = vec![max; TARGETS];
    s
}

/// State of the histogram pass: 8 RGBA32UI targets with logic OR (section 3.3).
pub fn histogram_state() -> PassState {
    let or = TargetState {
        logic_op: Some(LogicOp::Or),
        ..TargetState::new(Format::RGBA32UI)
    };
    let mut s = capture_state();
    s.fragment.targets = vec![or; TARGETS];
    s
}

/// The per-pixel depth range of a run.
pub struct DepthRange {
    /// `zNear` per pixel (`+inf` where the range pass drew nothing).
    pub near: Buf<f32>,
    /// `zFar` per pixel (`-inf` where the range pass drew nothing).
    pub far: Buf<f32>,
    /// Pixels with a range.
    pub covered: u64,
}

/// Runs the range pass ([`range::pass`] with [`Params::range`]) and refuses an empty view.
pub fn depth_range(
    device: &mut Device,
    frame: &Frame<'_>,
    params: &Params,
    exec: &ExecConfig,
) -> Result<(DepthRange, PassReport), AlgoError> {
    let (near, far, report) = range::pass(device, frame, params.range, exec)?;
    let (n, f) = (device.memory.read(near)?, device.memory.read(far)?);
    let covered = n.iter().zip(&f).filter(|(n, f)| n <= f).count() as u64;
    if covered == 0 {
        return Err(AlgoError::Invalid(format!(
            "the depth-range pass (--range {}) found no depth at any of the {} x {} pixels: \
             the view is empty, there is nothing to sort into buckets",
            params.range.name(),
            frame.width,
            frame.height
        )));
    }
    Ok((DepthRange { near, far, covered }, report))
}

/// Refuses `k` outside `1..=max` for a scheme that holds at most `max` fragments per pixel.
pub fn check_layers(name: &str, k: u32, max: u32, holds: &str) -> Result<(), AlgoError> {
    if k == 0 || k > max {
        return Err(AlgoError::Invalid(format!(
            "{name} keeps at most {max} layers per pixel ({holds}): k = {k} is outside 1..={max}"
        )));
    }
    Ok(())
}

/// What a bucket scheme read back: per pixel, the fragments its buckets held (in depth
/// order) and the fragments it routed to a bucket.
pub struct Sorted<'a> {
    pub frame: Frame<'a>,
    pub lists: Vec<Vec<CapturedFrag>>,
    pub routed: Vec<u32>,
}

impl<'a> Sorted<'a> {
    pub fn new(frame: &Frame<'a>) -> Sorted<'a> {
        Sorted {
            frame: *frame,
            lists: vec![Vec::new(); pixels(frame)],
            routed: vec![0; pixels(frame)],
        }
    }

    /// The capture (each list truncated to `k`), the collisions, and the checks every
    /// scheme satisfies: lists in depth order (eqs. 4 and 5 of section 3.2), and never more
    /// fragments held than routed. `storage_bytes`: buffers and targets.
    pub fn finish(
        self,
        k: u32,
        report: PassReport,
        mut checks: Vec<Check>,
        storage_bytes: u64,
    ) -> AlgoResult {
        let (mut unordered, mut overfull) = (0u64, 0u64);
        let mut collisions = Vec::with_capacity(self.lists.len());
        let lists: Vec<Vec<CapturedFrag>> = self
            .lists
            .into_iter()
            .zip(&self.routed)
            .map(|(mut l, &routed)| {
                unordered += l.windows(2).filter(|w| w[0].depth > w[1].depth).count() as u64;
                overfull += u64::from(l.len() as u64 > u64::from(routed));
                collisions.push(routed.saturating_sub(l.len() as u32));
                l.truncate(k as usize);
                l
            })
            .collect();
        let total: u64 = collisions.iter().map(|&c| u64::from(c)).sum();
        checks.push(Check::new(
            "buckets read out in depth order (section 3.2, eqs. 4 and 5)",
            unordered == 0,
            format!("{unordered} pairs out of order"),
        ));
        checks.push(Check::new(
            "no pixel holds more fragments than it routed to buckets",
            overfull == 0,
            format!(
                "{overfull} pixels over; {total} fragments lost to collisions, {} routed",
                self.routed.iter().map(|&r| u64::from(r)).sum::<u64>()
            ),
        ));
        AlgoResult {
            capture: Some(Capture::from_lists(
                self.frame.width,
                self.frame.height,
                lists,
            )),
            report,
            checks,
            dropped: total,
            storage_bytes,
            collisions: Some(collisions),
            ..Default::default()
        }
    }
}

/// A captured depth (ids are not kept by the bucket arrays).
pub fn frag(depth: f32) -> CapturedFrag {
    CapturedFrag {
        depth,
        prim: u32::MAX,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn min_keys_invert_exactly_and_order_backwards() {
        let zs = [
            0.0f32, 1e-30, 0.1, 0.3, 0.49999997, 0.5, 0.7, 0.99999994, 1.0,
        ];
        for w in zs.windows(2) {
            assert!(min_key(w[0]) > min_key(w[1]), "{w:?}");
            assert!(max_key(w[0]) < max_key(w[1]), "{w:?}");
        }
        for z in zs {
            assert_eq!(from_min_key(min_key(z)), Some(z));
            assert!(min_key(z) > 0.0);
        }
        assert_eq!(from_min_key(0.0), None);
        assert_eq!(max_key(-0.0).to_bits(), 0);
    }

    #[test]
    fn layers_beyond_the_array_are_refused_with_the_range() {
        let e = check_layers("bdp", 33, 32, "16 min/max pairs").unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("k = 33") && msg.contains("1..=32"), "{msg}");
        assert!(check_layers("bdp", 0, 32, "x").is_err());
        assert!(check_layers("bdp", 32, 32, "x").is_ok());
    }
}
