//! The array A-buffers' fragment storage (FAB, SB, DFB): two flat arrays, depth and
//! primitive, in which every pixel owns one contiguous range, and the resolve and readback
//! that walk those ranges.
//!
//! The three differ only in where a pixel's range starts ([`Layout`]) and how long it may be;
//! the arrays ([`FragmentArrays`]), the write of one fragment ([`store_fragment`]), the
//! resolve (sort the range in place, composite it) and the readback (the resolve's ranges to
//! a [`Capture`]) are the same, so they are written once here.

use fragrace_emu::{Buf, Device, Fragment, FragmentKernel, KernelInfo, Memory};

use crate::algo::{AlgoError, Capture, CapturedFrag, Frame};
use crate::common::sort_fragments;
use crate::resolve::Composite;

/// The fragment arrays: depth and primitive of fragment slot `i` at index `i` of each.
#[derive(Clone, Copy)]
pub(super) struct FragmentArrays {
    pub depth: Buf<f32>,
    pub prim: Buf<u32>,
}

impl FragmentArrays {
    /// Allocates `prefix-depth` and `prefix-prim` with `slots` entries each (at least one: a
    /// device buffer is never empty, even when no fragment was counted).
    pub(super) fn new(
        device: &mut Device,
        prefix: &str,
        slots: u64,
    ) -> Result<FragmentArrays, AlgoError> {
        Ok(FragmentArrays {
            depth: device.buffer::<f32>(&format!("{prefix}-depth"), slots.max(1))?,
            prim: device.buffer::<u32>(&format!("{prefix}-prim"), slots.max(1))?,
        })
    }
}

/// Writes the invoking fragment into `slot` of the arrays, depth then primitive: the write
/// that ends every array A-buffer's store pass once it holds a slot (FAB and SB:
/// depth-fighting paper section 2, Fig. 3(a) and (c); DFB: z-thickness paper section 4.3),
/// one copy so that the three passes make the same accesses.
pub(super) async fn store_fragment(f: &impl Fragment, depth: Buf<f32>, prim: Buf<u32>, slot: u32) {
    f.store(depth, slot, f.depth()).await;
    f.store(prim, slot, f.primitive_id()).await;
}

/// Where pixel `p`'s fragments live in the fragment arrays.
#[derive(Clone, Copy)]
pub(super) enum Layout {
    /// FAB: `[p * cap, p * cap + min(len, cap))`.
    Fixed { cap: u32 },
    /// DFB: `[offsets[p], offsets[p] + len)`.
    Offsets { offsets: Buf<u32> },
    /// SB: `[group_base[p % groups] + offsets[p], ... + len)` (covered pixels only).
    Grouped {
        offsets: Buf<u32>,
        group_base: Buf<u32>,
        groups: u32,
    },
}

impl Layout {
    async fn base(&self, f: &impl Fragment, p: u32) -> u32 {
        match *self {
            Layout::Fixed { cap } => p.wrapping_mul(cap),
            Layout::Offsets { offsets } => f.load(offsets, p).await,
            Layout::Grouped {
                offsets,
                group_base,
                groups,
            } => f
                .load(group_base, p % groups)
                .await
                .wrapping_add(f.load(offsets, p).await),
        }
    }
    /// [`Layout::base`] on the host, for each of `n` pixels (same buffers, same arithmetic).
    pub(super) fn starts(&self, memory: &Memory, n: usize) -> Result<Vec<u32>, AlgoError> {
        Ok(match *self {
            Layout::Fixed { cap } => (0..n as u32).map(|p| p.wrapping_mul(cap)).collect(),
            Layout::Offsets { offsets } => memory.read(offsets)?,
            Layout::Grouped {
                offsets,
                group_base,
                groups,
            } => {
                let (offsets, bases) = (memory.read(offsets)?, memory.read(group_base)?);
                (0..n)
                    .map(|p| bases[p % groups as usize].wrapping_add(offsets[p]))
                    .collect()
            }
        })
    }
    fn cap(&self) -> u32 {
        match *self {
            Layout::Fixed { cap } => cap,
            _ => u32::MAX,
        }
    }
}

/// The resolve pass of the array A-buffers (FAB, SB, DFB): one invocation per pixel loads its
/// range, sorts it (`sort_fragments`: insertion sort under 16, shell sort above, z-thickness
/// paper 5.1.2), writes it back sorted (so the readback is in resolve order) and outputs the
/// front-to-back composite. Each invocation touches only its own range: hazard-free.
pub(super) struct ArrayResolve {
    pub layout: Layout,
    /// Fragments stored per pixel (clamped to the layout's capacity).
    pub lens: Buf<u32>,
    /// Per-pixel upper bound on `lens` (the counted range), if the layout has no fixed capacity.
    pub limit: Option<Buf<u32>>,
    pub arrays: FragmentArrays,
    pub composite: Composite,
}

impl ArrayResolve {
    /// Reads the arrays back as a capture, each pixel's range as the resolve took it (same
    /// start, same clamped length; a range past the arrays' end reads as empty), so the
    /// readback is in resolve order and no algorithm restates where its ranges are.
    pub(super) fn capture(&self, device: &Device, frame: &Frame<'_>) -> Result<Capture, AlgoError> {
        let memory = &device.memory;
        let lens = memory.read(self.lens)?;
        let limit = self.limit.map(|limit| memory.read(limit)).transpose()?;
        let starts = self.layout.starts(memory, lens.len())?;
        let depth = memory.read(self.arrays.depth)?;
        let prim = memory.read(self.arrays.prim)?;
        let lists = (0..lens.len()).map(|p| {
            let len = lens[p].min(self.layout.cap());
            let l = limit.as_ref().map_or(len, |limit| len.min(limit[p])) as usize;
            let b = starts[p] as usize;
            if l == 0 || b + l > depth.len() {
                return Vec::new();
            }
            depth[b..b + l]
                .iter()
                .zip(&prim[b..b + l])
                .map(|(&depth, &prim)| CapturedFrag { depth, prim })
                .collect()
        });
        Ok(Capture::from_lists(frame.width, frame.height, lists))
    }
}

impl FragmentKernel for ArrayResolve {
    fn info(&self) -> KernelInfo {
        // A pixel no fragment reached stored none (its length is 0): it writes the
        // background.
        KernelInfo::new("abuffer-array-resolve")
            .with_untouched_output(self.composite.background_bits())
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let mut n = f.load(self.lens, p).await.min(self.layout.cap());
        if let Some(limit) = self.limit {
            n = n.min(f.load(limit, p).await);
        }
        let mut frags = Vec::with_capacity(n as usize);
        if n > 0 {
            let FragmentArrays { depth, prim } = self.arrays;
            let base = self.layout.base(&f, p).await;
            for i in 0..n {
                let depth = f.load(depth, base.wrapping_add(i)).await;
                let prim = f.load(prim, base.wrapping_add(i)).await;
                frags.push(CapturedFrag { depth, prim });
            }
            sort_fragments(&mut frags);
            for (i, fr) in frags.iter().enumerate() {
                f.store(depth, base.wrapping_add(i as u32), fr.depth).await;
                f.store(prim, base.wrapping_add(i as u32), fr.prim).await;
            }
        }
        self.composite.output(&f, &frags);
    }
}
