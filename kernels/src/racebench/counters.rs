//! Counters and reductions per pixel: a fragment counter (plain, atomic, with its result
//! misused, reset in the same pass), nearest and farthest depth by load + store or by an
//! atomic, an occupancy bitmask set by plain OR or atomic OR (the occupancy maps of
//! "Efficient Multi-Fragment Rendering with Occupancy Maps", section 3), a per-pixel
//! material histogram, and the weighted sum of weighted blended OIT ("Weighted Blended
//! Order-Independent Transparency", section 3) in fixed point.

use fragrace_emu::{Buf, Device, Fragment, FragmentKernel, KernelInfo, Memory};

use super::run::{buffer, read, same_as};
use super::{case, Case, Fragments, Kind, Label, Meta, Spec, Violation, Words};

pub(super) fn cases() -> Vec<Box<dyn Case>> {
    vec![
        case::<CounterPlain>(),
        case::<CounterAtomic>(),
        case::<CounterResultMisused>(),
        case::<CounterResultUsed>(),
        case::<CounterResetSamePass>(),
        case::<MinLoadStore>(),
        case::<MinAtomic>(),
        case::<MaxLoadStore>(),
        case::<MaxAtomic>(),
        case::<OccupancyPlainOr>(),
        case::<OccupancyAtomicOr>(),
        case::<HistogramPlain>(),
        case::<HistogramAtomic>(),
        case::<WeightedSumPlain>(),
        case::<WeightedSumAtomic>(),
    ]
}

const FAMILY: &str = "counters";
const LOST: &[Kind] = &[Kind::LostUpdate, Kind::Race];

/// A per-pixel counter: `count[p] += 1` by plain load and store.
pub struct CounterPlain {
    count: Buf<u32>,
}

impl FragmentKernel for CounterPlain {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("counter-plain")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let n = f.load(self.count, p).await;
        f.store(self.count, p, n + 1).await;
    }
}

impl Spec for CounterPlain {
    type K = Self;
    const META: Meta = Meta {
        name: "counter-plain",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("count")],
        kinds: LOST,
        pair: Some("counter-atomic"),
        limitation: None,
        what: "per-pixel fragment counter incremented by plain load and store",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        CounterPlain {
            count: buffer(dev, "count", pixels, 0),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.count, "fragment count")
    }
}

/// The same counter with `atomicAdd`.
pub struct CounterAtomic {
    count: Buf<u32>,
}

impl FragmentKernel for CounterAtomic {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("counter-atomic")
    }
    async fn shade(&self, f: impl Fragment) {
        f.atomic_add(self.count, f.pixel_index(), 1).await;
    }
}

impl Spec for CounterAtomic {
    type K = Self;
    const META: Meta = Meta {
        name: "counter-atomic",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("counter-plain"),
        limitation: None,
        what: "per-pixel fragment counter incremented by atomicAdd",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        CounterAtomic {
            count: buffer(dev, "count", pixels, 0),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.count, "fragment count")
    }
}

/// Slots per pixel of the append kernels (the scene has five fragments per pixel).
const SLOTS: u32 = 5;

/// Appends the fragment's primitive (+1) to its pixel's slots at index `i`.
async fn append(f: &impl Fragment, slots: Buf<u32>, i: u32) {
    let p = f.pixel_index();
    f.store(slots, p * SLOTS + i.min(SLOTS - 1), f.primitive_id() + 1)
        .await;
}

/// Every pixel's slots must hold its fragments' primitives (+1), each once.
fn appended(slots: &[u32], frags: &Fragments, name: &str) -> Result<(), Violation> {
    for p in 0..frags.pixels() {
        let mut want: Vec<u32> = frags.of_pixel(p).map(|f| f.primitive_id + 1).collect();
        let n = want.len();
        let base = (p * SLOTS) as usize;
        let mut got: Vec<u32> = slots[base..base + n].to_vec();
        want.sort_unstable();
        got.sort_unstable();
        if got != want {
            return Err(Violation::at(
                format!("pixel {p}: slots hold {got:?}, fragments {want:?}"),
                name,
                p * SLOTS,
            ));
        }
    }
    Ok(())
}

/// An append whose slot index is read back from the counter after the `atomicAdd`,
/// instead of taken from its result: two fragments can read the same count.
pub struct CounterResultMisused {
    count: Buf<u32>,
    slots: Buf<u32>,
}

impl FragmentKernel for CounterResultMisused {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("counter-result-misused")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        f.atomic_add(self.count, p, 1).await;
        let i = f.atomic_load(self.count, p).await - 1;
        append(&f, self.slots, i).await;
    }
}

impl Spec for CounterResultMisused {
    type K = Self;
    const META: Meta = Meta {
        name: "counter-result-misused",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("slots")],
        kinds: &[Kind::Race],
        pair: Some("counter-result-used"),
        limitation: None,
        what: "append slot read back from the counter after atomicAdd, not its return value",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        CounterResultMisused {
            count: buffer(dev, "count", pixels, 0),
            slots: buffer(dev, "slots", pixels * SLOTS, 0),
        }
    }
    fn check(k: &Self, mem: &Memory, _: &Memory, fr: &Fragments) -> Result<(), Violation> {
        appended(&read(mem, k.slots), fr, "slots")
    }
}

/// The append with the slot index `atomicAdd` returned.
pub struct CounterResultUsed {
    count: Buf<u32>,
    slots: Buf<u32>,
}

impl FragmentKernel for CounterResultUsed {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("counter-result-used")
    }
    async fn shade(&self, f: impl Fragment) {
        let i = f.atomic_add(self.count, f.pixel_index(), 1).await;
        append(&f, self.slots, i).await;
    }
}

impl Spec for CounterResultUsed {
    type K = Self;
    const META: Meta = Meta {
        name: "counter-result-used",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("counter-result-misused"),
        limitation: None,
        what: "append slot taken from atomicAdd's return value",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        CounterResultUsed {
            count: buffer(dev, "count", pixels, 0),
            slots: buffer(dev, "slots", pixels * SLOTS, 0),
        }
    }
    fn check(k: &Self, mem: &Memory, _: &Memory, fr: &Fragments) -> Result<(), Violation> {
        appended(&read(mem, k.slots), fr, "slots")
    }
}

/// A counter left over from the last frame (7), cleared by the pixel's first primitive in
/// the same pass that counts: a fragment that counts before the clear is lost.
pub struct CounterResetSamePass {
    count: Buf<u32>,
}

impl FragmentKernel for CounterResetSamePass {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("counter-reset-same-pass")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        if f.primitive_id() == 0 {
            f.store(self.count, p, 0).await;
        }
        f.atomic_add(self.count, p, 1).await;
    }
}

impl Spec for CounterResetSamePass {
    type K = Self;
    const META: Meta = Meta {
        name: "counter-reset-same-pass",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("count")],
        kinds: &[Kind::Race],
        pair: None,
        limitation: None,
        what: "counter cleared by a plain store in the same pass that atomically counts",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        CounterResetSamePass {
            count: buffer(dev, "count", pixels, 7),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.count, "fragment count")
    }
}

/// Nearest depth per pixel by plain load, compare, store.
pub struct MinLoadStore {
    zmin: Buf<f32>,
}

impl FragmentKernel for MinLoadStore {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("min-load-store")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let z = f.load(self.zmin, p).await;
        if f.depth() < z {
            f.store(self.zmin, p, f.depth()).await;
        }
    }
}

impl Spec for MinLoadStore {
    type K = Self;
    const META: Meta = Meta {
        name: "min-load-store",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("zmin")],
        kinds: LOST,
        pair: Some("min-atomic"),
        limitation: None,
        what: "nearest depth by plain load, compare and store",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        MinLoadStore {
            zmin: buffer(dev, "zmin", pixels, f32::INFINITY),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.zmin, "nearest depth")
    }
}

/// Nearest depth per pixel by `atomicMin`.
pub struct MinAtomic {
    zmin: Buf<f32>,
}

impl FragmentKernel for MinAtomic {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("min-atomic")
    }
    async fn shade(&self, f: impl Fragment) {
        f.atomic_min(self.zmin, f.pixel_index(), f.depth()).await;
    }
}

impl Spec for MinAtomic {
    type K = Self;
    const META: Meta = Meta {
        name: "min-atomic",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("min-load-store"),
        limitation: None,
        what: "nearest depth by atomicMin",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        MinAtomic {
            zmin: buffer(dev, "zmin", pixels, f32::INFINITY),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.zmin, "nearest depth")
    }
}

/// Farthest primitive id per pixel (the back layer of dual depth peeling's max) by plain
/// load, compare, store.
pub struct MaxLoadStore {
    zmax: Buf<f32>,
}

impl FragmentKernel for MaxLoadStore {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("max-load-store")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let z = f.load(self.zmax, p).await;
        if f.depth() > z {
            f.store(self.zmax, p, f.depth()).await;
        }
    }
}

impl Spec for MaxLoadStore {
    type K = Self;
    const META: Meta = Meta {
        name: "max-load-store",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("zmax")],
        kinds: LOST,
        pair: Some("max-atomic"),
        limitation: None,
        what: "farthest depth by plain load, compare and store",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        MaxLoadStore {
            zmax: buffer(dev, "zmax", pixels, 0.0),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.zmax, "farthest depth")
    }
}

/// Farthest depth per pixel by `atomicMax`.
pub struct MaxAtomic {
    zmax: Buf<f32>,
}

impl FragmentKernel for MaxAtomic {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("max-atomic")
    }
    async fn shade(&self, f: impl Fragment) {
        f.atomic_max(self.zmax, f.pixel_index(), f.depth()).await;
    }
}

impl Spec for MaxAtomic {
    type K = Self;
    const META: Meta = Meta {
        name: "max-atomic",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("max-load-store"),
        limitation: None,
        what: "farthest depth by atomicMax",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        MaxAtomic {
            zmax: buffer(dev, "zmax", pixels, 0.0),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.zmax, "farthest depth")
    }
}

/// The occupancy bit of a fragment: one of 32 depth slices (its primitive spreads the
/// bits, so that the fragments of a pixel set different bits).
fn occupancy_bit(f: &impl Fragment) -> u32 {
    let slice = (f.depth() * 32.0) as u32 ^ (f.primitive_id() * 7);
    1 << (slice % 32)
}

/// An occupancy bitmask per pixel set by plain load, OR, store.
pub struct OccupancyPlainOr {
    occ: Buf<u32>,
}

impl FragmentKernel for OccupancyPlainOr {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("occupancy-plain-or")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let m = f.load(self.occ, p).await;
        f.store(self.occ, p, m | occupancy_bit(&f)).await;
    }
}

impl Spec for OccupancyPlainOr {
    type K = Self;
    const META: Meta = Meta {
        name: "occupancy-plain-or",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("occ")],
        kinds: LOST,
        pair: Some("occupancy-atomic-or"),
        limitation: None,
        what: "occupancy bit of a depth slice set by plain OR",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        OccupancyPlainOr {
            occ: buffer(dev, "occ", pixels, 0),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.occ, "occupancy bits")
    }
}

/// The occupancy bit set by `atomicOr`.
pub struct OccupancyAtomicOr {
    occ: Buf<u32>,
}

impl FragmentKernel for OccupancyAtomicOr {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("occupancy-atomic-or")
    }
    async fn shade(&self, f: impl Fragment) {
        f.atomic_or(self.occ, f.pixel_index(), occupancy_bit(&f))
            .await;
    }
}

impl Spec for OccupancyAtomicOr {
    type K = Self;
    const META: Meta = Meta {
        name: "occupancy-atomic-or",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("occupancy-plain-or"),
        limitation: None,
        what: "occupancy bit of a depth slice set by atomicOr",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        OccupancyAtomicOr {
            occ: buffer(dev, "occ", pixels, 0),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.occ, "occupancy bits")
    }
}

/// Bins of the material histogram (material = primitive id mod 2).
const BINS: u32 = 2;

/// A per-pixel material histogram by plain increments.
pub struct HistogramPlain {
    hist: Buf<u32>,
}

impl FragmentKernel for HistogramPlain {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("histogram-plain")
    }
    async fn shade(&self, f: impl Fragment) {
        let i = f.pixel_index() * BINS + f.primitive_id() % BINS;
        let n = f.load(self.hist, i).await;
        f.store(self.hist, i, n + 1).await;
    }
}

impl Spec for HistogramPlain {
    type K = Self;
    const META: Meta = Meta {
        name: "histogram-plain",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("hist")],
        kinds: LOST,
        pair: Some("histogram-atomic"),
        limitation: None,
        what: "per-pixel material histogram bin incremented by plain load and store",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        HistogramPlain {
            hist: buffer(dev, "hist", pixels * BINS, 0),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.hist, "histogram")
    }
}

/// The histogram by `atomicAdd`.
pub struct HistogramAtomic {
    hist: Buf<u32>,
}

impl FragmentKernel for HistogramAtomic {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("histogram-atomic")
    }
    async fn shade(&self, f: impl Fragment) {
        let i = f.pixel_index() * BINS + f.primitive_id() % BINS;
        f.atomic_add(self.hist, i, 1).await;
    }
}

impl Spec for HistogramAtomic {
    type K = Self;
    const META: Meta = Meta {
        name: "histogram-atomic",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("histogram-plain"),
        limitation: None,
        what: "per-pixel material histogram bin incremented by atomicAdd",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        HistogramAtomic {
            hist: buffer(dev, "hist", pixels * BINS, 0),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.hist, "histogram")
    }
}

/// The weight of a fragment in weighted blended OIT, in 1/1024 fixed point (integer sums
/// are exact in any order, so the race-free version has one right answer).
fn weight(f: &impl Fragment) -> u32 {
    let w = (1.0 - f.depth()).clamp(0.01, 1.0);
    (w * w * 1024.0) as u32 + 1
}

/// Weighted blended OIT's accumulation (`sum += w`) by plain load and store.
pub struct WeightedSumPlain {
    accum: Buf<u32>,
}

impl FragmentKernel for WeightedSumPlain {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("wboit-sum-plain")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let s = f.load(self.accum, p).await;
        f.store(self.accum, p, s + weight(&f)).await;
    }
}

impl Spec for WeightedSumPlain {
    type K = Self;
    const META: Meta = Meta {
        name: "wboit-sum-plain",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("accum")],
        kinds: LOST,
        pair: Some("wboit-sum-atomic"),
        limitation: None,
        what: "weighted blended OIT accumulation by plain load, add and store",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        WeightedSumPlain {
            accum: buffer(dev, "accum", pixels, 0),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.accum, "weighted sum")
    }
}

/// The accumulation by `atomicAdd`, in fixed point.
pub struct WeightedSumAtomic {
    accum: Buf<u32>,
}

impl FragmentKernel for WeightedSumAtomic {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("wboit-sum-atomic")
    }
    async fn shade(&self, f: impl Fragment) {
        f.atomic_add(self.accum, f.pixel_index(), weight(&f)).await;
    }
}

impl Spec for WeightedSumAtomic {
    type K = Self;
    const META: Meta = Meta {
        name: "wboit-sum-atomic",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("wboit-sum-plain"),
        limitation: None,
        what: "weighted blended OIT accumulation by atomicAdd in fixed point",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        WeightedSumAtomic {
            accum: buffer(dev, "accum", pixels, 0),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.accum, "weighted sum")
    }
}
