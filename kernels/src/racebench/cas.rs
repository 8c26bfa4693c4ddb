//! Compare-exchange loops: a per-pixel free list of scratch nodes (a Treiber stack: pop by
//! compare-exchange of the head from a node to its successor, push back by
//! compare-exchange) with the ABA window of an untagged head, and with a tagged head; a
//! float maximum by one compare-exchange whose failure is ignored, and by a retry loop.

use fragrace_emu::{Buf, Device, Fragment, FragmentKernel, KernelInfo, Memory};

use super::run::{buffer, read, same_as};
use super::{case, Case, Fragments, Kind, Label, Limitation, Meta, Spec, Violation, Words};

pub(super) fn cases() -> Vec<Box<dyn Case>> {
    vec![
        case::<FreeListAba>(),
        case::<FreeListTagged>(),
        case::<MaxOneShotCas>(),
        case::<MaxCasLoop>(),
    ]
}

const FAMILY: &str = "cas";
/// Scratch nodes per pixel.
const POOL: u32 = 4;
/// The end of the free list (an index, in the low 16 bits of a tagged head).
const END: u32 = 0xffff;
const IDX: u32 = 0xffff;

/// The buffers of a free-list kernel.
#[derive(Clone, Copy)]
pub struct FreeList {
    /// Per pixel: the free list's head (tag << 16 | index when tagged).
    head: Buf<u32>,
    next: Buf<u32>,
    /// Per node: 1 while a fragment holds it.
    held: Buf<u32>,
    /// Per pixel: pops that returned a node someone else held.
    double: Buf<u32>,
    tagged: bool,
}

impl FreeList {
    fn new(dev: &mut Device, pixels: u32, tagged: bool) -> FreeList {
        let fl = FreeList {
            head: buffer(dev, "fl_head", pixels, 0),
            next: buffer(dev, "fl_next", pixels * POOL, 0),
            held: buffer(dev, "fl_held", pixels * POOL, 0),
            double: buffer(dev, "double_pop", pixels, 0),
            tagged,
        };
        let links: Vec<u32> = (0..pixels * POOL)
            .map(|i| {
                if i % POOL == POOL - 1 {
                    END
                } else {
                    i % POOL + 1
                }
            })
            .collect();
        dev.memory
            .write(fl.next, 0, &links)
            .expect("a small buffer");
        fl
    }

    /// The head word that points at `idx` after `old` (tagged: the tag advances).
    fn swing(&self, old: u32, idx: u32) -> u32 {
        if self.tagged {
            ((old >> 16).wrapping_add(1) << 16) | idx
        } else {
            idx
        }
    }

    async fn pop(&self, f: &impl Fragment) -> Option<u32> {
        let p = f.pixel_index();
        let mut h = f.atomic_load(self.head, p).await;
        loop {
            if h & IDX == END {
                return None;
            }
            // The ABA window: between this load and the compare-exchange, the node can
            // be popped, its successor popped, and the node pushed back.
            let nxt = f.atomic_load(self.next, p * POOL + (h & IDX)).await;
            match f
                .atomic_compare_exchange(self.head, p, h, self.swing(h, nxt))
                .await
            {
                Ok(_) => break,
                Err(now) => h = now,
            }
        }
        let n = h & IDX;
        if f.atomic_exchange(self.held, p * POOL + n, 1).await != 0 {
            f.atomic_add(self.double, p, 1).await;
        }
        Some(n)
    }

    async fn push(&self, f: &impl Fragment, n: u32) {
        let p = f.pixel_index();
        f.atomic_store(self.held, p * POOL + n, 0).await;
        let mut h = f.atomic_load(self.head, p).await;
        loop {
            f.atomic_store(self.next, p * POOL + n, h & IDX).await;
            match f
                .atomic_compare_exchange(self.head, p, h, self.swing(h, n))
                .await
            {
                Ok(_) => break,
                Err(now) => h = now,
            }
        }
    }

    /// Each fragment borrows two scratch nodes and gives them back, the first first (so
    /// that the head is the first node again while the second is still held: the A of
    /// ABA).
    async fn shade(&self, f: &impl Fragment) {
        let a = self.pop(f).await;
        let b = self.pop(f).await;
        if let Some(a) = a {
            self.push(f, a).await;
        }
        if let Some(b) = b {
            self.push(f, b).await;
        }
    }

    /// No node was held twice, and every node is back on its pixel's list once.
    fn check(&self, mem: &Memory, fr: &Fragments) -> Result<(), Violation> {
        let (head, next, double) = (
            read(mem, self.head),
            read(mem, self.next),
            read(mem, self.double),
        );
        for p in 0..fr.pixels() {
            if double[p as usize] > 0 {
                return Err(Violation::at(
                    format!("pixel {p}: {} nodes popped while held", double[p as usize]),
                    "fl_head",
                    p,
                ));
            }
            let mut seen = [false; POOL as usize];
            let mut cur = head[p as usize] & IDX;
            let mut n = 0;
            while cur != END {
                if cur >= POOL || seen[cur as usize] {
                    return Err(Violation::at(
                        format!("pixel {p}: free list broken at node {cur}"),
                        "fl_next",
                        p * POOL,
                    ));
                }
                seen[cur as usize] = true;
                n += 1;
                cur = next[(p * POOL + cur) as usize];
            }
            if n != POOL {
                return Err(Violation::at(
                    format!("pixel {p}: {n} of {POOL} nodes back on the free list"),
                    "fl_head",
                    p,
                ));
            }
        }
        Ok(())
    }
}

/// The free list with an untagged head: ABA.
pub struct FreeListAba(FreeList);

impl FragmentKernel for FreeListAba {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("cas-aba-freelist")
    }
    async fn shade(&self, f: impl Fragment) {
        self.0.shade(&f).await;
    }
}

impl Spec for FreeListAba {
    type K = Self;
    const META: Meta = Meta {
        name: "cas-aba-freelist",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("fl_head"), Words::all("fl_next")],
        kinds: &[Kind::LostUpdate],
        pair: Some("cas-tagged-freelist"),
        limitation: None,
        what: "per-pixel free list popped by compare-exchange of an untagged head (ABA)",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        FreeListAba(FreeList::new(dev, pixels, false))
    }
    fn check(k: &Self, mem: &Memory, _: &Memory, fr: &Fragments) -> Result<(), Violation> {
        k.0.check(mem, fr)
    }
}

/// The free list with a tagged head (a counter beside the index): no ABA.
pub struct FreeListTagged(FreeList);

impl FragmentKernel for FreeListTagged {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("cas-tagged-freelist")
    }
    async fn shade(&self, f: impl Fragment) {
        self.0.shade(&f).await;
    }
}

impl Spec for FreeListTagged {
    type K = Self;
    const META: Meta = Meta {
        name: "cas-tagged-freelist",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("cas-aba-freelist"),
        limitation: None,
        what: "per-pixel free list popped by compare-exchange of a tagged head",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        FreeListTagged(FreeList::new(dev, pixels, true))
    }
    fn check(k: &Self, mem: &Memory, _: &Memory, fr: &Fragments) -> Result<(), Violation> {
        k.0.check(mem, fr)
    }
}

/// Farthest depth by one compare-exchange from the loaded value, its failure ignored.
pub struct MaxOneShotCas {
    zmax: Buf<f32>,
}

impl FragmentKernel for MaxOneShotCas {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("cas-oneshot-max")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let old = f.atomic_load(self.zmax, p).await;
        if f.depth() > old {
            // (The failure is ignored: that is the bug.)
            let _ = f
                .atomic_compare_exchange(self.zmax, p, old, f.depth())
                .await;
        }
    }
}

impl Spec for MaxOneShotCas {
    type K = Self;
    const META: Meta = Meta {
        name: "cas-oneshot-max",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("zmax")],
        kinds: &[Kind::LostUpdate],
        pair: Some("cas-loop-max"),
        limitation: Some(Limitation::AtomicsOnly),
        what: "float maximum by one compare-exchange whose failure is ignored",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        MaxOneShotCas {
            zmax: buffer(dev, "zmax", pixels, 0.0),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.zmax, "farthest depth")
    }
}

/// Farthest depth by a compare-exchange loop (where no float atomicMax exists).
pub struct MaxCasLoop {
    zmax: Buf<f32>,
}

impl FragmentKernel for MaxCasLoop {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("cas-loop-max")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let z = f.depth();
        let mut old = f.atomic_load(self.zmax, p).await;
        while z > old {
            match f.atomic_compare_exchange(self.zmax, p, old, z).await {
                Ok(_) => break,
                Err(now) => old = now,
            }
        }
    }
}

impl Spec for MaxCasLoop {
    type K = Self;
    const META: Meta = Meta {
        name: "cas-loop-max",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("cas-oneshot-max"),
        limitation: None,
        what: "float maximum by a compare-exchange retry loop",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        MaxCasLoop {
            zmax: buffer(dev, "zmax", pixels, 0.0),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.zmax, "farthest depth")
    }
}
