//! k-slot arrays and multi-word records per pixel: the k-buffer insertion of "Multi-Layer
//! Depth Peeling via Fragment Sort" / Bavoil et al.'s k-buffer ("Multi-fragment effects on
//! the GPU using the k-buffer", section 3) as a plain read-modify-write, inside pixel
//! interlock, with the slots read before the interlock, and as the atomic-min chain of
//! "Multi-layer depth peeling" style k-buffers; a nearest-fragment record (depth,
//! primitive) written without a lock (torn), with only its depth word inside the interlock,
//! with all of it inside, packed into one 64-bit atomic, and split into two 32-bit atomics.

use fragrace_emu::{Buf, Device, Fragment, FragmentKernel, InterlockMode, KernelInfo, Memory};

use super::run::{buffer, read, same_as};
use super::{case, Case, Fragments, Kind, Label, Limitation, Meta, Spec, Violation, Words};

pub(super) fn cases() -> Vec<Box<dyn Case>> {
    vec![
        case::<KSlotRmw>(),
        case::<KSlotInterlock>(),
        case::<KSlotAtomicChain>(),
        case::<KSlotReadOutsideInterlock>(),
        case::<RecordTorn>(),
        case::<RecordPartialInterlock>(),
        case::<RecordInterlock>(),
        case::<RecordPacked64>(),
        case::<KeySplit32>(),
    ]
}

const FAMILY: &str = "records";
/// Slots per pixel of the k-buffers.
const K: u32 = 3;

/// Bavoil's insertion: walk the k sorted slots, swapping the carried depth into place.
/// Plain loads and stores; the caller decides what protects them.
async fn insert(f: &impl Fragment, slots: Buf<f32>) {
    let base = f.pixel_index() * K;
    let mut z = f.depth();
    for i in 0..K {
        let s = f.load(slots, base + i).await;
        if z < s {
            f.store(slots, base + i, z).await;
            z = s;
        }
    }
}

fn kslots(dev: &mut Device, pixels: u32) -> Buf<f32> {
    buffer(dev, "kslots", pixels * K, f32::INFINITY)
}

/// The k-buffer insertion by plain read-modify-write, unprotected.
pub struct KSlotRmw {
    slots: Buf<f32>,
}

impl FragmentKernel for KSlotRmw {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("kslot-rmw")
    }
    async fn shade(&self, f: impl Fragment) {
        insert(&f, self.slots).await;
    }
}

impl Spec for KSlotRmw {
    type K = Self;
    const META: Meta = Meta {
        name: "kslot-rmw",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("kslots")],
        kinds: &[Kind::LostUpdate, Kind::Race],
        pair: Some("kslot-interlock"),
        limitation: None,
        what: "k-buffer insertion into k sorted slots by plain read-modify-write",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        KSlotRmw {
            slots: kslots(dev, pixels),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.slots, "k nearest depths")
    }
}

/// The insertion inside ordered pixel interlock.
pub struct KSlotInterlock {
    slots: Buf<f32>,
}

impl FragmentKernel for KSlotInterlock {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("kslot-interlock").with_interlock(InterlockMode::ORDERED)
    }
    async fn shade(&self, f: impl Fragment) {
        f.interlock_begin().await;
        insert(&f, self.slots).await;
        f.interlock_end().await;
    }
}

impl Spec for KSlotInterlock {
    type K = Self;
    const META: Meta = Meta {
        name: "kslot-interlock",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("kslot-rmw"),
        limitation: None,
        what: "k-buffer insertion inside ordered pixel interlock",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        KSlotInterlock {
            slots: kslots(dev, pixels),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.slots, "k nearest depths")
    }
}

/// The k-buffer as a chain of `atomicMin`: each slot keeps the smaller value, the larger
/// one moves on to the next slot.
pub struct KSlotAtomicChain {
    slots: Buf<f32>,
}

impl FragmentKernel for KSlotAtomicChain {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("kslot-atomic-chain")
    }
    async fn shade(&self, f: impl Fragment) {
        let base = f.pixel_index() * K;
        let mut z = f.depth();
        for i in 0..K {
            let old = f.atomic_min(self.slots, base + i, z).await;
            z = z.max(old);
            if z == f32::INFINITY {
                break;
            }
        }
    }
}

impl Spec for KSlotAtomicChain {
    type K = Self;
    const META: Meta = Meta {
        name: "kslot-atomic-chain",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("kslot-rmw"),
        limitation: None,
        what: "k-buffer insertion as a chain of atomicMin, the displaced depth carried on",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        KSlotAtomicChain {
            slots: kslots(dev, pixels),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.slots, "k nearest depths")
    }
}

/// The slots read before entering the interlock, then sorted and written inside it: a
/// critical section that reads outside the interlock.
pub struct KSlotReadOutsideInterlock {
    slots: Buf<f32>,
}

impl FragmentKernel for KSlotReadOutsideInterlock {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("kslot-read-outside-interlock").with_interlock(InterlockMode::ORDERED)
    }
    async fn shade(&self, f: impl Fragment) {
        let base = f.pixel_index() * K;
        let mut s = [0.0f32; K as usize];
        for (i, v) in s.iter_mut().enumerate() {
            *v = f.load(self.slots, base + i as u32).await;
        }
        f.interlock_begin().await;
        let mut z = f.depth();
        for (i, v) in s.iter().enumerate() {
            if z < *v {
                f.store(self.slots, base + i as u32, z).await;
                z = *v;
            }
        }
        f.interlock_end().await;
    }
}

impl Spec for KSlotReadOutsideInterlock {
    type K = Self;
    const META: Meta = Meta {
        name: "kslot-read-outside-interlock",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("kslots")],
        kinds: &[Kind::LostUpdate, Kind::Race],
        pair: Some("kslot-interlock"),
        limitation: None,
        what: "k-buffer whose slots are read before the interlock and written inside it",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        KSlotReadOutsideInterlock {
            slots: kslots(dev, pixels),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.slots, "k nearest depths")
    }
}

/// Words of a nearest-fragment record: depth bits, primitive.
const REC: u32 = 2;

fn record(dev: &mut Device, pixels: u32) -> Buf<u32> {
    buffer(dev, "rec", pixels * REC, u32::MAX)
}

/// Every pixel's record must be (nearest depth, its primitive), as in the ordered run.
fn nearest(rec: Buf<u32>, mem: &Memory, r: &Memory) -> Result<(), Violation> {
    same_as(mem, r, rec, "nearest record (depth, primitive)")
}

/// The nearest-fragment record read with one load per word and written with one store per
/// word, without a lock: a reader can see the depth of one fragment and the primitive of
/// another.
pub struct RecordTorn {
    rec: Buf<u32>,
}

impl FragmentKernel for RecordTorn {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("record-torn")
    }
    async fn shade(&self, f: impl Fragment) {
        let base = f.pixel_index() * REC;
        let mut cur = [0u32; REC as usize];
        f.load_record(self.rec, base, &mut cur).await;
        let z = f.depth().to_bits();
        if z < cur[0] {
            f.store_record(self.rec, base, &[z, f.primitive_id()]).await;
        }
    }
}

impl Spec for RecordTorn {
    type K = Self;
    const META: Meta = Meta {
        name: "record-torn",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("rec")],
        kinds: &[Kind::Torn, Kind::Race, Kind::LostUpdate],
        pair: Some("record-interlock"),
        limitation: None,
        what: "two-word record (depth, primitive) read and written word by word without a lock",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        RecordTorn {
            rec: record(dev, pixels),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        nearest(k.rec, mem, r)
    }
}

/// The record's depth word updated inside the interlock, its primitive word after it.
pub struct RecordPartialInterlock {
    rec: Buf<u32>,
}

impl FragmentKernel for RecordPartialInterlock {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("record-partial-interlock").with_interlock(InterlockMode::ORDERED)
    }
    async fn shade(&self, f: impl Fragment) {
        let base = f.pixel_index() * REC;
        let z = f.depth().to_bits();
        f.interlock_begin().await;
        let d = f.load(self.rec, base).await;
        let nearer = z < d;
        if nearer {
            f.store(self.rec, base, z).await;
        }
        f.interlock_end().await;
        if nearer {
            f.store(self.rec, base + 1, f.primitive_id()).await;
        }
    }
}

impl Spec for RecordPartialInterlock {
    type K = Self;
    const META: Meta = Meta {
        name: "record-partial-interlock",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::slots("rec", REC, &[1])],
        kinds: &[Kind::Race],
        pair: Some("record-interlock"),
        limitation: None,
        what: "record whose depth word is written inside the interlock, its primitive word after",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        RecordPartialInterlock {
            rec: record(dev, pixels),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        nearest(k.rec, mem, r)
    }
}

/// The whole record read and written inside the interlock.
pub struct RecordInterlock {
    rec: Buf<u32>,
}

impl FragmentKernel for RecordInterlock {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("record-interlock").with_interlock(InterlockMode::ORDERED)
    }
    async fn shade(&self, f: impl Fragment) {
        let base = f.pixel_index() * REC;
        let mut cur = [0u32; REC as usize];
        f.interlock_begin().await;
        f.load_record(self.rec, base, &mut cur).await;
        let z = f.depth().to_bits();
        if z < cur[0] {
            f.store_record(self.rec, base, &[z, f.primitive_id()]).await;
        }
        f.interlock_end().await;
    }
}

impl Spec for RecordInterlock {
    type K = Self;
    const META: Meta = Meta {
        name: "record-interlock",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("record-torn"),
        limitation: None,
        what: "two-word record read and written inside ordered pixel interlock",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        RecordInterlock {
            rec: record(dev, pixels),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        nearest(k.rec, mem, r)
    }
}

/// The record packed into one 64-bit word (depth bits high, primitive low) and kept by
/// one `atomicMin`.
pub struct RecordPacked64 {
    key: Buf<u64>,
}

impl FragmentKernel for RecordPacked64 {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("record-packed-64")
    }
    async fn shade(&self, f: impl Fragment) {
        let key = (f.depth().to_bits() as u64) << 32 | f.primitive_id() as u64;
        f.atomic_min(self.key, f.pixel_index(), key).await;
    }
}

impl Spec for RecordPacked64 {
    type K = Self;
    const META: Meta = Meta {
        name: "record-packed-64",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("key-split-32"),
        limitation: None,
        what: "record packed into one 64-bit key (depth, primitive) kept by atomicMin",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        RecordPacked64 {
            key: buffer(dev, "key", pixels, u64::MAX),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.key, "nearest key")
    }
}

/// The 64-bit key split into two 32-bit atomics: `atomicMin` on the depth word, and the
/// winner then exchanges its primitive into the other word. Two winners in turn can leave
/// one's depth with the other's primitive.
pub struct KeySplit32 {
    hi: Buf<u32>,
    lo: Buf<u32>,
}

impl FragmentKernel for KeySplit32 {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("key-split-32")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let z = f.depth().to_bits();
        let old = f.atomic_min(self.hi, p, z).await;
        if z < old {
            f.atomic_exchange(self.lo, p, f.primitive_id()).await;
        }
    }
}

impl Spec for KeySplit32 {
    type K = Self;
    const META: Meta = Meta {
        name: "key-split-32",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("key_hi"), Words::all("key_lo")],
        kinds: &[Kind::Race],
        pair: Some("record-packed-64"),
        limitation: Some(Limitation::AtomicsOnly),
        what: "64-bit (depth, primitive) key split into two 32-bit atomics",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        KeySplit32 {
            hi: buffer(dev, "key_hi", pixels, u32::MAX),
            lo: buffer(dev, "key_lo", pixels, u32::MAX),
        }
    }
    fn check(k: &Self, mem: &Memory, _: &Memory, fr: &Fragments) -> Result<(), Violation> {
        let (hi, lo) = (read(mem, k.hi), read(mem, k.lo));
        for p in 0..fr.pixels() {
            let want = fr
                .of_pixel(p)
                .min_by(|a, b| a.depth.total_cmp(&b.depth))
                .map(|f| (f.depth.to_bits(), f.primitive_id));
            let got = (hi[p as usize], lo[p as usize]);
            if want.is_some_and(|w| w != got) {
                return Err(Violation::at(
                    format!("pixel {p}: key (depth bits, primitive) {got:?}, nearest {want:?}"),
                    "key_lo",
                    p,
                ));
            }
        }
        Ok(())
    }
}
