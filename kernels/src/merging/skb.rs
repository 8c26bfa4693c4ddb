//! `skb-ofm` and `skb-ofm-unordered`: the static k+-buffer with order-independent fragment
//! merging in its store pass (Kim & Kye, "Z-Thickness Blending: Effective Fragment Merging
//! for Multi-Fragment Rendering", section 4.2, "Bounded memory usage approach", section
//! 4.1.2, "Tail-handling", and section 5.1, SKB+OFM).
//!
//! Per pixel: k core records (unsorted, a count, and the max array of the k+-buffer
//! \[VPF15\]: the slot of the farthest core record) and one tail record. A fragment, given its
//! z-thickness, is merged by OFM with every core record its band overlaps (the core records
//! are pairwise disjoint, so one sweep finds them all), then:
//!
//! - behind or into the tail's band: mixed into the tail;
//! - room in the core: appended;
//! - core full, the fragment behind the farthest core record (the max array's): mixed into
//!   the tail;
//! - core full, the fragment nearer: the farthest record is mixed into the tail and the
//!   fragment takes its slot (the k+-buffer's replacement of the maximum).
//!
//! The tail is merged with the mix operator, as the store pass must (section 4.1.2), so the
//! core is always in front of the tail and its records pairwise disjoint. The resolve sorts
//! the core and composites it, then the tail, front to back; it merges nothing more (section
//! 4.1.1: "there is no need to consider fragment merging in the resolve pass").
//!
//! - `skb-ofm`: the store pass inside an ordered pixel interlock (the paper's
//!   rasterizer-ordered views). Entry is in primitive order per pixel, so the image is the
//!   same bits under every executor.
//! - `skb-ofm-unordered`: the same store with no synchronization, what the paper says
//!   happens without pixel synchronization: its read-modify-write of the records races.

use fragrace_emu::{
    Buf, Coverage, ExecConfig, Fragment, FragmentKernel, InterlockMode, KernelInfo,
};

use super::ofm::ofm;
use super::record::{composite, ZFrag, WORDS};
use super::thickness::ZModel;
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Check, Deferred, Frame, HazardClass,
    Params,
};
use crate::common::{self, capture_state, framebuffer, geometry_pass, pixels};
use crate::resolve;

/// Largest k: a kernel keeps its pixel's records in a local array (registers on a GPU).
pub const MAX_K: u32 = 32;

/// `params.k`, checked against `1..=MAX_K`.
pub(super) fn k_of(params: &Params) -> Result<u32, AlgoError> {
    if params.k == 0 || params.k > MAX_K {
        return Err(AlgoError::Invalid(format!(
            "k = {} is invalid for the merging k-buffers: k must be in 1..={MAX_K}",
            params.k
        )));
    }
    Ok(params.k)
}

/// How the store pass is synchronized.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sync {
    /// Ordered pixel interlock around the read-modify-write.
    OrderedInterlock,
    /// Unordered pixel interlock: mutual exclusion, entry in whatever order the executor
    /// produced. Not registered: the test of OFM's order independence runs it (the merged
    /// records are the same whatever the order; their visibilities up to rounding, as long
    /// as no record goes to the tail).
    UnorderedInterlock,
    /// None: the read-modify-write races.
    Unsynchronized,
}

/// `skb-ofm` (`Sync::OrderedInterlock`) or `skb-ofm-unordered` (`Sync::Unsynchronized`).
pub struct SkbOfm(pub Sync);

/// The per-pixel buffers.
#[derive(Clone, Copy)]
struct Buffers {
    k: u32,
    /// k records of `WORDS` words per pixel.
    core: Buf<f32>,
    /// One record per pixel.
    tail: Buf<f32>,
    count: Buf<u32>,
    /// The max array: the slot of the farthest core record.
    max_pos: Buf<u32>,
}

impl Buffers {
    fn slot(&self, p: u32, i: u32) -> u32 {
        (p * self.k + i) * WORDS
    }

    async fn load(&self, f: &impl Fragment, buf: Buf<f32>, at: u32) -> ZFrag {
        let mut w = [0.0f32; WORDS as usize];
        f.load_record(buf, at, &mut w).await;
        ZFrag::from_words(&w)
    }
}

/// The farthest of `core` (slot index).
fn farthest(core: &[ZFrag]) -> usize {
    (1..core.len()).fold(0, |m, i| if core[i].z > core[m].z { i } else { m })
}

/// The store pass.
struct Store {
    sync: Sync,
    b: Buffers,
    model: ZModel,
}

impl FragmentKernel for Store {
    fn info(&self) -> KernelInfo {
        let info = KernelInfo::new(match self.sync {
            Sync::OrderedInterlock => "skb-ofm-store",
            Sync::UnorderedInterlock => "skb-ofm-mutex-store",
            Sync::Unsynchronized => "skb-ofm-unordered-store",
        });
        match self.sync {
            Sync::OrderedInterlock => info.with_interlock(InterlockMode::ORDERED),
            Sync::UnorderedInterlock => info.with_interlock(InterlockMode::UNORDERED),
            Sync::Unsynchronized => info,
        }
    }

    async fn shade(&self, f: impl Fragment) {
        let (b, p) = (self.b, f.pixel_index());
        let mut g = self.model.fragment(f.depth(), f.primitive_id());
        let locked = self.sync != Sync::Unsynchronized;
        if locked {
            f.interlock_begin().await;
        }
        let before = f.load(b.count, p).await.min(b.k) as usize;
        let mut core = [ZFrag::EMPTY; MAX_K as usize];
        for (i, c) in core.iter_mut().enumerate().take(before) {
            *c = b.load(&f, b.core, b.slot(p, i as u32)).await;
        }
        // OFM with every overlapping core record (moved out; the last takes its slot).
        let (mut n, mut dirty, mut i) = (before, 0u64, 0);
        while i < n {
            if core[i].overlaps(&g) {
                g = ofm(&core[i], &g);
                n -= 1;
                core[i] = core[n];
                dirty |= 1 << i;
            } else {
                i += 1;
            }
        }
        let tail = b.load(&f, b.tail, p * WORDS).await;
        let to_tail = if !tail.is_empty() && g.z > tail.front() {
            Some(g)
        } else if n < b.k as usize {
            core[n] = g;
            dirty |= 1 << n;
            n += 1;
            None
        } else {
            // The max array names the farthest record, unless merging moved records.
            let m = if n == before {
                (f.load(b.max_pos, p).await as usize).min(n - 1)
            } else {
                farthest(&core[..n])
            };
            if g.z >= core[m].z {
                Some(g)
            } else {
                let evicted = core[m];
                core[m] = g;
                dirty |= 1 << m;
                Some(evicted)
            }
        };
        if let Some(x) = to_tail {
            let t = if tail.is_empty() { x } else { ofm(&tail, &x) };
            f.store_record(b.tail, p * WORDS, &t.to_words()).await;
        }
        for (i, c) in core.iter().enumerate().take(n) {
            if dirty & (1 << i) != 0 {
                f.store_record(b.core, b.slot(p, i as u32), &c.to_words())
                    .await;
            }
        }
        if n != before {
            f.store(b.count, p, n as u32).await;
        }
        if dirty != 0 {
            f.store(b.max_pos, p, farthest(&core[..n]) as u32).await;
        }
        if locked {
            f.interlock_end().await;
        }
    }
}

/// The resolve pass: the core sorted, then the tail, composited front to back.
struct Resolve {
    b: Buffers,
    background: [f32; 3],
}

impl FragmentKernel for Resolve {
    fn info(&self) -> KernelInfo {
        // At a pixel no geometry reached, the count is 0 and the tail empty (zeroed
        // buffers): the composite of nothing.
        KernelInfo::new("skb-ofm-resolve")
            .with_untouched_output(composite(&[], self.background).map(f32::to_bits))
    }
    async fn shade(&self, f: impl Fragment) {
        let (b, p) = (self.b, f.pixel_index());
        let n = f.load(b.count, p).await.min(b.k) as usize;
        let mut frags = [ZFrag::EMPTY; MAX_K as usize + 1];
        for (i, c) in frags.iter_mut().enumerate().take(n) {
            *c = b.load(&f, b.core, b.slot(p, i as u32)).await;
        }
        frags[..n].sort_by(|x, y| x.z.total_cmp(&y.z));
        let tail = b.load(&f, b.tail, p * WORDS).await;
        let mut len = n;
        if !tail.is_empty() {
            frags[len] = tail;
            len += 1;
        }
        f.output(0, composite(&frags[..len], self.background));
    }
}

impl Algorithm for SkbOfm {
    fn info(&self) -> AlgoInfo {
        let (name, summary, hazard) = match self.0 {
            Sync::OrderedInterlock => (
                "skb-ofm",
                "static k+-buffer + order-independent fragment merging: each fragment merged by OFM \
                 (mix operator) with the core records it overlaps, max array, tail record mixed \
                 with what falls behind, under ordered pixel interlock",
                HazardClass::NeedsInterlock,
            ),
            Sync::UnorderedInterlock => (
                "skb-ofm-mutex",
                "skb-ofm under unordered pixel interlock: mutual exclusion, any entry order",
                HazardClass::NeedsInterlock,
            ),
            Sync::Unsynchronized => (
                "skb-ofm-unordered",
                "skb-ofm without pixel synchronization: the records' read-modify-write races",
                HazardClass::HazardProne,
            ),
        };
        AlgoInfo {
            name,
            family: "merging",
            summary,
            source:
                "Kim & Kye, Z-Thickness Blending: Effective Fragment Merging for Multi-Fragment \
                     Rendering, CGF 2021: sec. 3.2.2, 3.3.2, 4.1.2, 4.2 (SKB+OFM); k+-buffer of \
                     Vasilakis et al. [VPF15]",
            passes: "1 geometry + 1 full-screen",
            memory: "32 (k + 1) + 8 bytes (k core records and a tail of z, t, RGBA, A_sum and a \
                     merged count, 8 words each; count, max position)",
            hazard,
            capacity: Capacity::Image,
        }
    }

    fn run_frame(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        let k = k_of(params)?;
        let model = ZModel::of(frame, params)?;
        let n = pixels(frame) as u64;
        // The resolve skips the pixels no geometry reached (`with_untouched_output`).
        let mut device = common::fresh(exec).with_coverage(Coverage::Tracked);
        let core = device.buffer::<f32>("skb-ofm-core", n * u64::from(k * WORDS))?;
        let tail = device.buffer::<f32>("skb-ofm-tail", n * u64::from(WORDS))?;
        // Zeroed: a record with nothing merged (n = 0) is empty.
        let count = device.buffer::<u32>("skb-ofm-count", n)?;
        let max_pos = device.buffer::<u32>("skb-ofm-max-pos", n)?;
        let b = Buffers {
            k,
            core,
            tail,
            count,
            max_pos,
        };
        let store = Store {
            sync: self.0,
            b,
            model,
        };
        let mut capture_fb = framebuffer(frame, fragrace_emu::SampleCount::X1, &[])?;
        let mut report = geometry_pass(
            &device,
            &mut capture_fb,
            frame,
            &capture_state(),
            &store,
            exec,
        )?;
        let stats = report.stats.clone();
        let mut fb = resolve::framebuffer(frame)?;
        let kernel = Resolve {
            b,
            background: params.background,
        };
        report.merge(&resolve::pass(&device, &mut fb, &kernel, exec)?);
        let storage_bytes = device.memory.bytes() + n * resolve::TARGET_BYTES;
        let sync = self.0;
        // The records are read back and checked after the frame ([`AlgoResult::deferred`]).
        let deferred = Deferred::new(move |r: &mut AlgoResult| {
            let image = resolve::read_image(&fb);

            let memory = &device.memory;
            let (core, tail) = (memory.read(core)?, memory.read(tail)?);
            let (count, max_pos) = (memory.read(count)?, memory.read(max_pos)?);
            let record = |p: usize, i: usize| {
                let w = (p * k as usize + i) * WORDS as usize;
                ZFrag::from_words(&core[w..w + WORDS as usize])
            };
            let mut kept = 0.0f64;
            let mut shape_bad = None;
            for p in 0..n as usize {
                let c = (count[p] as usize).min(k as usize);
                let recs: Vec<ZFrag> = (0..c).map(|i| record(p, i)).collect();
                let t = ZFrag::from_words(&tail[p * WORDS as usize..(p + 1) * WORDS as usize]);
                kept += recs.iter().map(|r| f64::from(r.n)).sum::<f64>() + f64::from(t.n);
                let disjoint = recs
                    .iter()
                    .enumerate()
                    .all(|(i, a)| recs[i + 1..].iter().all(|b| !a.overlaps(b)));
                let before_tail = t.is_empty() || recs.iter().all(|r| r.z <= t.front());
                let max_ok = c == 0 || recs[max_pos[p] as usize % c].z == recs[farthest(&recs)].z;
                if shape_bad.is_none()
                    && !(count[p] as usize <= k as usize && disjoint && before_tail && max_ok)
                {
                    shape_bad = Some(format!(
                        "pixel {p}: count {}, disjoint {disjoint}, core before tail {before_tail}, max position right {max_ok}",
                        count[p]
                    ));
                }
            }
            let generated = stats.fragments_generated;
            let synced = sync != Sync::Unsynchronized;
            let label = |name: &str| {
                if synced {
                    name.to_string()
                } else {
                    format!("{name} (informational: no synchronization)")
                }
            };
            let checks = vec![
                Check::all_shaded(&stats, r.report.faults.len()),
                Check::new(
                    label("every fragment merged into exactly one record (core or tail)"),
                    !synced || kept == generated as f64,
                    format!("records hold {kept} fragments, generated {generated}"),
                ),
                Check::new(
                    label("core: at most k records, pairwise disjoint, in front of the tail, max array right"),
                    !synced || shape_bad.is_none(),
                    shape_bad.unwrap_or_else(|| format!("{n} pixels")),
                ),
                Check::image_finite(&image),
            ];
            r.image = Some(image);
            r.checks.extend(checks);
            Ok(())
        });
        Ok(AlgoResult {
            storage_bytes,
            report,
            deferred: Some(deferred),
            ..Default::default()
        })
    }
}

/// The algorithms of this file, for its family's registry line.
pub(super) fn algorithms() -> Vec<Box<dyn crate::algo::Algorithm>> {
    vec![Box::new(SkbOfm(Sync::OrderedInterlock)), Box::new(SkbOfm(Sync::Unsynchronized))]
}
