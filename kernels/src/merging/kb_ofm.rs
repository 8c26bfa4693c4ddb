//! `kb-ofm`: the plain read-modify-write k-buffer (Bavoil et al. 2007, `kb-rmw`) with
//! order-independent fragment merging and no synchronization, for the hazard comparison of
//! Kim & Kye, "Z-Thickness Blending: Effective Fragment Merging for Multi-Fragment
//! Rendering", section 4.2 ("it suffers from data races during the store pass as it performs
//! read-modify-write operations of fragments").
//!
//! Each pixel owns k records kept sorted by depth. A fragment, given its z-thickness, loads
//! all k, merges by OFM with every record its band overlaps (the mix operator, section
//! 3.3.2), inserts the result in depth order if there is room or it is nearer than the
//! farthest (which falls out: no tail, the overflow is dropped, as the k-buffers that
//! "discard the overflowing fragments", section 2), and stores all k back. Run one fragment
//! at a time it keeps the k nearest merged bands; two fragments of a pixel in flight together
//! lose one's update.

use fragrace_emu::{Buf, Coverage, ExecConfig, Fragment, FragmentKernel, KernelInfo};

use super::ofm::ofm;
use super::record::{composite, ZFrag, WORDS};
use super::skb::{k_of, MAX_K};
use super::thickness::ZModel;
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Check, Deferred, Frame, HazardClass,
    Params,
};
use crate::common::{self, capture_state, framebuffer, geometry_pass, pixels};
use crate::resolve;

/// `kb-ofm`.
pub struct KbOfm;

/// Words of a pixel's k records.
const MAX_WORDS: usize = (MAX_K * WORDS) as usize;

/// The store pass: load the k records, merge, insert, store the k back (plain accesses).
struct Store {
    k: u32,
    /// k records of `WORDS` words per pixel, sorted by depth, empty ones (n = 0) last.
    records: Buf<f32>,
    model: ZModel,
}

impl FragmentKernel for Store {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("kb-ofm-store")
    }
    async fn shade(&self, f: impl Fragment) {
        let k = self.k as usize;
        let base = f.pixel_index() * self.k * WORDS;
        let mut g = self.model.fragment(f.depth(), f.primitive_id());
        let mut words = [0.0f32; MAX_WORDS];
        let words = &mut words[..k * WORDS as usize];
        f.load_record(self.records, base, words).await;
        let mut kept = [ZFrag::EMPTY; MAX_K as usize];
        let mut n = 0;
        for w in words.chunks(WORDS as usize) {
            let r = ZFrag::from_words(w);
            if r.is_empty() {
                continue;
            }
            if r.overlaps(&g) {
                g = ofm(&r, &g);
            } else {
                kept[n] = r;
                n += 1;
            }
        }
        // Sorted insertion; the farthest falls out of a full buffer.
        let mut j = n.min(k - 1);
        if n == k && g.z >= kept[k - 1].z {
            return;
        }
        while j > 0 && g.z < kept[j - 1].z {
            kept[j] = kept[j - 1];
            j -= 1;
        }
        kept[j] = g;
        n = (n + 1).min(k);
        for (i, w) in words.chunks_mut(WORDS as usize).enumerate() {
            let r = if i < n { kept[i] } else { ZFrag::EMPTY };
            w.copy_from_slice(&r.to_words());
        }
        f.store_record(self.records, base, words).await;
    }
}

/// The resolve pass: the non-empty records in depth order, composited front to back.
struct Resolve {
    k: u32,
    records: Buf<f32>,
    background: [f32; 3],
}

impl FragmentKernel for Resolve {
    fn info(&self) -> KernelInfo {
        // At a pixel no geometry reached every record is empty (zeroed buffer): the
        // composite of nothing.
        KernelInfo::new("kb-ofm-resolve")
            .with_untouched_output(composite(&[], self.background).map(f32::to_bits))
    }
    async fn shade(&self, f: impl Fragment) {
        let base = f.pixel_index() * self.k * WORDS;
        let mut words = [0.0f32; MAX_WORDS];
        let words = &mut words[..(self.k * WORDS) as usize];
        f.load_record(self.records, base, words).await;
        let mut frags = [ZFrag::EMPTY; MAX_K as usize];
        let mut n = 0;
        for w in words.chunks(WORDS as usize) {
            let r = ZFrag::from_words(w);
            if !r.is_empty() {
                frags[n] = r;
                n += 1;
            }
        }
        frags[..n].sort_by(|a, b| a.z.total_cmp(&b.z));
        f.output(0, composite(&frags[..n], self.background));
    }
}

impl Algorithm for KbOfm {
    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "kb-ofm",
            family: "merging",
            summary: "plain read-modify-write k-buffer with order-independent fragment merging \
                      (OFM, mix operator), overflow dropped, no synchronization: races by design",
            source:
                "Kim & Kye, Z-Thickness Blending: Effective Fragment Merging for Multi-Fragment \
                     Rendering, CGF 2021: sec. 3.2.2, 3.3.2, 4.2 (the k-buffer's data races); \
                     k-buffer of Bavoil et al. 2007",
            passes: "1 geometry + 1 full-screen",
            memory: "32 k bytes (k records of z, t, RGBA, A_sum and a merged count, 8 words each)",
            hazard: HazardClass::HazardProne,
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
        // Zeroed: a record with nothing merged (n = 0) is empty.
        let records = device.buffer::<f32>("kb-ofm-records", n * u64::from(k * WORDS))?;
        let store = Store { k, records, model };
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
            k,
            records,
            background: params.background,
        };
        report.merge(&resolve::pass(&device, &mut fb, &kernel, exec)?);
        let storage_bytes = device.memory.bytes() + n * resolve::TARGET_BYTES;
        // The records are read back and checked after the frame ([`AlgoResult::deferred`]).
        let deferred = Deferred::new(move |r: &mut AlgoResult| {
            let image = resolve::read_image(&fb);
            let words = device.memory.read(records)?;
            let held: f64 = words
                .chunks(WORDS as usize)
                .map(|w| f64::from(ZFrag::from_words(w).n))
                .sum();
            let generated = stats.fragments_generated;
            let checks = vec![
                Check::all_shaded(&stats, r.report.faults.len()),
                Check::new(
                    "fragments held by the records (informational: overflow and lost updates drop them)",
                    true,
                    format!("{held} of {generated}"),
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
    vec![Box::new(KbOfm)]
}
