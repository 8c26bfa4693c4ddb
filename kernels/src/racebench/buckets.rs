//! Bucket depth peeling ("Efficient Depth Peeling via Bucket Sort", section 3): the depth
//! range of a pixel, known from an earlier pass, is cut into buckets, and each fragment
//! goes to the bucket its depth falls in. Stored with a plain store (two fragments of one
//! bucket collide: the paper's known conflict), kept by `atomicMin` (its fix); and the
//! bucket index computed from a range read in the same pass that computes it, against the
//! range from an earlier pass.

use fragrace_emu::{Buf, Device, Fragment, FragmentKernel, KernelInfo, Memory};

use super::run::{buffer, read, same_as};
use super::{case, Case, Fragments, Kind, Label, Meta, Spec, Violation, Words};

pub(super) fn cases() -> Vec<Box<dyn Case>> {
    vec![
        case::<BucketStorePlain>(),
        case::<BucketMinAtomic>(),
        case::<BucketIndexRacyRead>(),
        case::<BucketIndexPriorPass>(),
    ]
}

const FAMILY: &str = "buckets";
/// Buckets per pixel (two: the scene's five fragments always collide in one).
const B: u32 = 2;
/// The scene's depth range, as an earlier pass would have found it.
const RANGE: (f32, f32) = (0.55, 0.95);

/// The bucket of depth `z` in `[lo, hi]`.
fn bucket(z: f32, lo: f32, hi: f32) -> u32 {
    let t = (z - lo) / (hi - lo);
    if t.is_nan() || t <= 0.0 {
        0
    } else {
        ((t * B as f32) as u32).min(B - 1)
    }
}

/// The range buffers of an earlier pass (read-only here).
fn prior_range(dev: &mut Device, pixels: u32) -> (Buf<f32>, Buf<f32>) {
    (
        buffer(dev, "zlo", pixels, RANGE.0),
        buffer(dev, "zhi", pixels, RANGE.1),
    )
}

async fn bucket_of(f: &impl Fragment, lo: Buf<f32>, hi: Buf<f32>) -> u32 {
    let p = f.pixel_index();
    let (l, h) = (f.load(lo, p).await, f.load(hi, p).await);
    f.pixel_index() * B + bucket(f.depth(), l, h)
}

/// A fragment's depth stored into its bucket by a plain store.
pub struct BucketStorePlain {
    lo: Buf<f32>,
    hi: Buf<f32>,
    buckets: Buf<f32>,
}

impl FragmentKernel for BucketStorePlain {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("bucket-store-plain")
    }
    async fn shade(&self, f: impl Fragment) {
        let i = bucket_of(&f, self.lo, self.hi).await;
        f.store(self.buckets, i, f.depth()).await;
    }
}

impl Spec for BucketStorePlain {
    type K = Self;
    const META: Meta = Meta {
        name: "bucket-store-plain",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("buckets")],
        kinds: &[Kind::Race],
        pair: Some("bucket-min-atomic"),
        limitation: None,
        what: "bucket depth peeling: depth stored into its bucket by a plain store (collisions)",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        let (lo, hi) = prior_range(dev, pixels);
        BucketStorePlain {
            lo,
            hi,
            buckets: buffer(dev, "buckets", pixels * B, 0.0),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.buckets, "bucket contents")
    }
}

/// Each bucket keeps its nearest depth by `atomicMin`.
pub struct BucketMinAtomic {
    lo: Buf<f32>,
    hi: Buf<f32>,
    buckets: Buf<f32>,
}

impl FragmentKernel for BucketMinAtomic {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("bucket-min-atomic")
    }
    async fn shade(&self, f: impl Fragment) {
        let i = bucket_of(&f, self.lo, self.hi).await;
        f.atomic_min(self.buckets, i, f.depth()).await;
    }
}

impl Spec for BucketMinAtomic {
    type K = Self;
    const META: Meta = Meta {
        name: "bucket-min-atomic",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("bucket-store-plain"),
        limitation: None,
        what: "bucket depth peeling: each bucket keeps its nearest depth by atomicMin",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        let (lo, hi) = prior_range(dev, pixels);
        BucketMinAtomic {
            lo,
            hi,
            buckets: buffer(dev, "buckets", pixels * B, f32::INFINITY),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.buckets, "bucket contents")
    }
}

/// The depth range computed in this pass (`atomicMin`, `atomicMax`) and read back with
/// plain loads to pick the bucket: the index depends on which fragments got there first.
pub struct BucketIndexRacyRead {
    lo: Buf<f32>,
    hi: Buf<f32>,
    hist: Buf<u32>,
}

impl FragmentKernel for BucketIndexRacyRead {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("bucket-index-racy-read")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        f.atomic_min(self.lo, p, f.depth()).await;
        f.atomic_max(self.hi, p, f.depth()).await;
        let i = bucket_of(&f, self.lo, self.hi).await;
        f.atomic_add(self.hist, i, 1).await;
    }
}

impl Spec for BucketIndexRacyRead {
    type K = Self;
    const META: Meta = Meta {
        name: "bucket-index-racy-read",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("zlo"), Words::all("zhi")],
        kinds: &[Kind::Race],
        pair: Some("bucket-index-prior-pass"),
        limitation: None,
        what: "bucket index from a depth range read (plain) while the same pass computes it",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        BucketIndexRacyRead {
            lo: buffer(dev, "zlo", pixels, f32::INFINITY),
            hi: buffer(dev, "zhi", pixels, 0.0),
            hist: buffer(dev, "hist", pixels * B, 0),
        }
    }
    fn check(k: &Self, mem: &Memory, _: &Memory, fr: &Fragments) -> Result<(), Violation> {
        // Intended: every fragment bucketed in its pixel's final range.
        let hist = read(mem, k.hist);
        for p in 0..fr.pixels() {
            let z: Vec<f32> = fr.of_pixel(p).map(|f| f.depth).collect();
            let lo = z.iter().copied().fold(f32::INFINITY, f32::min);
            let hi = z.iter().copied().fold(0.0, f32::max);
            let mut want = [0u32; B as usize];
            for &d in &z {
                want[bucket(d, lo, hi) as usize] += 1;
            }
            let got = &hist[(p * B) as usize..((p + 1) * B) as usize];
            if got != want {
                return Err(Violation::at(
                    format!("pixel {p}: bucket counts {got:?}, in the final range {want:?}"),
                    "hist",
                    p * B,
                ));
            }
        }
        Ok(())
    }
}

/// The bucket index from the range of an earlier pass (read-only in this one).
pub struct BucketIndexPriorPass {
    lo: Buf<f32>,
    hi: Buf<f32>,
    hist: Buf<u32>,
}

impl FragmentKernel for BucketIndexPriorPass {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("bucket-index-prior-pass")
    }
    async fn shade(&self, f: impl Fragment) {
        let i = bucket_of(&f, self.lo, self.hi).await;
        f.atomic_add(self.hist, i, 1).await;
    }
}

impl Spec for BucketIndexPriorPass {
    type K = Self;
    const META: Meta = Meta {
        name: "bucket-index-prior-pass",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("bucket-index-racy-read"),
        limitation: None,
        what: "bucket index from the depth range an earlier pass computed",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        let (lo, hi) = prior_range(dev, pixels);
        BucketIndexPriorPass {
            lo,
            hi,
            hist: buffer(dev, "hist", pixels * B, 0),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.hist, "bucket counts")
    }
}
