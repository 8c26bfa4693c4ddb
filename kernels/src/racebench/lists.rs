//! Per-pixel linked lists ("Real-time concurrent linked list construction on the GPU",
//! section 3): a node from a global counter, its payload written, the pixel's head swapped
//! to it. Pushed with no reader in the pass (the algorithm as published), and with an
//! in-pass reader that looks at the node at the head (as single-pass variants that cull or
//! merge against the list do): then the node must be complete before it is published.
//! Variants: published before its payload is written, linked after it is published, and
//! pushed by a compare-exchange loop that writes everything first.

use fragrace_emu::{Buf, Device, Fragment, FragmentKernel, KernelInfo, Memory};

use super::run::{buffer, read};
use super::{case, Case, Fragments, Kind, Label, Meta, Spec, Violation, Words};

pub(super) fn cases() -> Vec<Box<dyn Case>> {
    vec![
        case::<ListNoReader>(),
        case::<ListPublishBeforeWrite>(),
        case::<ListLinkAfterPublish>(),
        case::<ListCasPush>(),
    ]
}

const FAMILY: &str = "lists";
/// Words per node: depth bits, primitive, next.
const NODE: u32 = 3;
const DEPTH: u32 = 0;
const NEXT: u32 = 2;
/// The end of a list.
const END: u32 = u32::MAX;
/// A node word nobody has written yet.
const UNWRITTEN: u32 = 0xdead_beef;

/// The buffers of a list kernel.
#[derive(Clone, Copy)]
pub struct ListBufs {
    counter: Buf<u32>,
    heads: Buf<u32>,
    nodes: Buf<u32>,
    /// Per pixel: incomplete nodes an in-pass reader saw.
    half: Buf<u32>,
}

impl ListBufs {
    fn new(dev: &mut Device, pixels: u32) -> ListBufs {
        // Five fragments per pixel in the scene.
        let nodes = 5 * pixels;
        ListBufs {
            counter: buffer(dev, "counter", 1, 0),
            heads: buffer(dev, "heads", pixels, END),
            nodes: buffer(dev, "nodes", nodes * NODE, UNWRITTEN),
            half: buffer(dev, "half_written", pixels, 0),
        }
    }

    /// Every pixel's list holds its fragments once each, and no reader saw a half-written
    /// node.
    fn check(&self, mem: &Memory, fr: &Fragments) -> Result<(), Violation> {
        let (heads, nodes, half) = (
            read(mem, self.heads),
            read(mem, self.nodes),
            read(mem, self.half),
        );
        let count = nodes.len() as u32 / NODE;
        for p in 0..fr.pixels() {
            if half[p as usize] > 0 {
                return Err(Violation::at(
                    format!(
                        "pixel {p}: a reader saw {} half-written nodes",
                        half[p as usize]
                    ),
                    "nodes",
                    heads[p as usize].min(count - 1) * NODE,
                ));
            }
            let mut got = Vec::new();
            let mut cur = heads[p as usize];
            while cur != END {
                if cur >= count || got.len() > count as usize {
                    return Err(Violation::at(
                        format!("pixel {p}: broken link {cur}"),
                        "heads",
                        p,
                    ));
                }
                let n = (cur * NODE) as usize;
                got.push((nodes[n + DEPTH as usize], nodes[n + 1]));
                cur = nodes[n + NEXT as usize];
            }
            let mut want: Vec<(u32, u32)> = fr
                .of_pixel(p)
                .map(|f| (f.depth.to_bits(), f.primitive_id))
                .collect();
            got.sort_unstable();
            want.sort_unstable();
            if got != want {
                return Err(Violation::at(
                    format!("pixel {p}: list {got:?}, fragments {want:?}"),
                    "heads",
                    p,
                ));
            }
        }
        Ok(())
    }
}

/// The in-pass reader: loads the node now at the head (atomically) and its depth (plain
/// or coherent); an unwritten depth is a half-written node.
async fn read_head(f: &impl Fragment, b: ListBufs, coherent: bool, field: u32) {
    let p = f.pixel_index();
    let h = f.atomic_load(b.heads, p).await;
    if h == END {
        return;
    }
    let w = if coherent {
        f.atomic_load(b.nodes, h * NODE + field).await
    } else {
        f.load(b.nodes, h * NODE + field).await
    };
    if w == UNWRITTEN {
        f.atomic_add(b.half, p, 1).await;
    }
}

macro_rules! list_spec {
    ($ty:ident, $meta:expr) => {
        impl Spec for $ty {
            type K = Self;
            const META: Meta = $meta;
            fn build(dev: &mut Device, pixels: u32) -> Self {
                $ty(ListBufs::new(dev, pixels))
            }
            fn check(k: &Self, mem: &Memory, _: &Memory, fr: &Fragments) -> Result<(), Violation> {
                k.0.check(mem, fr)
            }
        }
    };
}

/// The published push: node from the counter, payload, head exchange, link. No in-pass
/// reader: only the node's owner touches it in this pass.
pub struct ListNoReader(ListBufs);

impl FragmentKernel for ListNoReader {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("ll-no-reader")
    }
    async fn shade(&self, f: impl Fragment) {
        let b = self.0;
        let n = f.atomic_add(b.counter, 0, 1).await;
        f.store(b.nodes, n * NODE + DEPTH, f.depth().to_bits())
            .await;
        f.store(b.nodes, n * NODE + 1, f.primitive_id()).await;
        let next = f.atomic_exchange(b.heads, f.pixel_index(), n).await;
        f.store(b.nodes, n * NODE + NEXT, next).await;
    }
}

list_spec!(
    ListNoReader,
    Meta {
        name: "ll-no-reader",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("ll-link-after-publish"),
        limitation: None,
        what: "per-pixel linked-list push as published (payload, head exchange, link), \
               no in-pass reader",
    }
);

/// Publishes the node (head exchange) before writing its payload; an in-pass reader can
/// see the payload unwritten.
pub struct ListPublishBeforeWrite(ListBufs);

impl FragmentKernel for ListPublishBeforeWrite {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("ll-publish-before-write")
    }
    async fn shade(&self, f: impl Fragment) {
        let b = self.0;
        let n = f.atomic_add(b.counter, 0, 1).await;
        let next = f.atomic_exchange(b.heads, f.pixel_index(), n).await;
        f.atomic_store(b.nodes, n * NODE + NEXT, next).await;
        f.store(b.nodes, n * NODE + DEPTH, f.depth().to_bits())
            .await;
        f.store(b.nodes, n * NODE + 1, f.primitive_id()).await;
        read_head(&f, b, false, DEPTH).await;
    }
}

list_spec!(
    ListPublishBeforeWrite,
    Meta {
        name: "ll-publish-before-write",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::slots("nodes", NODE, &[0, 1])],
        kinds: &[Kind::Race],
        pair: Some("ll-cas-push"),
        limitation: None,
        what: "linked-list push that publishes the node before writing its payload, with an \
               in-pass reader",
    }
);

/// The published push (link written after the head exchange) with an in-pass reader that
/// follows the head node's link.
pub struct ListLinkAfterPublish(ListBufs);

impl FragmentKernel for ListLinkAfterPublish {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("ll-link-after-publish")
    }
    async fn shade(&self, f: impl Fragment) {
        let b = self.0;
        let n = f.atomic_add(b.counter, 0, 1).await;
        f.atomic_store(b.nodes, n * NODE + DEPTH, f.depth().to_bits())
            .await;
        f.atomic_store(b.nodes, n * NODE + 1, f.primitive_id())
            .await;
        let next = f.atomic_exchange(b.heads, f.pixel_index(), n).await;
        f.store(b.nodes, n * NODE + NEXT, next).await;
        read_head(&f, b, false, NEXT).await;
    }
}

list_spec!(
    ListLinkAfterPublish,
    Meta {
        name: "ll-link-after-publish",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::slots("nodes", NODE, &[NEXT])],
        kinds: &[Kind::Race],
        pair: Some("ll-no-reader"),
        limitation: None,
        what: "linked-list push that writes the link after publishing the node, with an \
               in-pass reader of the link",
    }
);

/// Push by compare-exchange loop: the node (payload and link) is complete before the
/// head points at it; coherent accesses throughout, and an in-pass reader.
pub struct ListCasPush(ListBufs);

impl FragmentKernel for ListCasPush {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("ll-cas-push")
    }
    async fn shade(&self, f: impl Fragment) {
        let b = self.0;
        let p = f.pixel_index();
        let n = f.atomic_add(b.counter, 0, 1).await;
        f.atomic_store(b.nodes, n * NODE + DEPTH, f.depth().to_bits())
            .await;
        f.atomic_store(b.nodes, n * NODE + 1, f.primitive_id())
            .await;
        let mut head = f.atomic_load(b.heads, p).await;
        loop {
            f.atomic_store(b.nodes, n * NODE + NEXT, head).await;
            match f.atomic_compare_exchange(b.heads, p, head, n).await {
                Ok(_) => break,
                Err(now) => head = now,
            }
        }
        read_head(&f, b, true, DEPTH).await;
        read_head(&f, b, true, NEXT).await;
    }
}

list_spec!(
    ListCasPush,
    Meta {
        name: "ll-cas-push",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("ll-publish-before-write"),
        limitation: None,
        what: "linked-list push by compare-exchange loop, node complete before it is \
               published, coherent in-pass reader",
    }
);
