//! `f2b-fab` and `f2b-kb`: the depth-fighting paper's approximate coplanarity-aware peeling
//! with fixed-size per-pixel buffers (section 3.2.1, Algorithm 3 "F2B-B Depth Peeling").
//!
//! "We introduce a solution for combining FAB/KB with F2B and DUAL (F2B-B, DUAL-B) to
//! partially treat fragment coplanarity. The idea is to adapt the previously described core
//! methodology of linked lists by exploiting bounded buffer architectures for storage."
//! (3.2.1) Each iteration is F2B-LL's two passes ([`super::f2bll::LayerPasses`]: a depth pass
//! finds the next layer, a capture pass with the depth test `EQUAL` runs on its fragments),
//! with the layer's coplanar fragments stored into `K` = [`SLOTS`] slots per pixel (the
//! paper's `K = 8` without packing) instead of a list. The host takes the slots after each
//! capture pass (sorted by primitive, all at one depth) and clears them. A layer with more
//! than `K` coplanar fragments loses the rest: robustness `sum K / C(Z_i)` (Table 1).
//!
//! - **F2B-FAB**: "TMP.counter ← IN.counter+1; ... A[TMP.counter-1].color ← FR.color; //
//!   where ← denotes an atomic memory operation": a per-pixel atomic counter hands out the
//!   slots. Hazard-free; what does not fit is counted (`dropped`). (The paper wraps the
//!   counter to 0 at `A.length`, overwriting the first slots; this crate keeps the first `K`
//!   and counts the rest, so that the loss is counted exactly. Which `K` of a larger group
//!   survive depends on the order of the atomics, so the kept primitives, and the image,
//!   may differ between executors there; the kept depths and the count do not.)
//! - **F2B-KB**: "for i = 0 to A.length do if A\[i\] == 0 then A\[i\] ← FR.color; break". The
//!   paper's legend under Algorithm 3 says "← denotes an atomic memory operation", and it
//!   calls the approach RMWH-free ("there is no need for pre-sorting and post-sorting, since
//!   we peel fragments placed at same memory space (RMWH-free)"); yet it offers KB "when
//!   advanced APIs are not available" and notes "Performance is degraded when KB is used due
//!   to concurrent updates": a k-buffer on render targets (Bavoil's, `kb-rmw`) has no atomic
//!   slot search, only a read of the attachment and a write back. This crate implements that
//!   reading, the one without atomics: the slot search is a read-modify-write with plain
//!   loads and stores, and the updates race (an atomic compare-exchange per slot would make
//!   it hazard-free, as `f2b-fab` is). Two coplanar fragments of one pixel in
//!   flight together can both find slot `i` empty, and the second store wins: a lost update,
//!   a fragment gone without a trace. Hazard-prone: only coplanar fragments race (the rest
//!   never run the capture kernel together), so the hazard shows on coplanar scenes
//!   (`cubes`, `coplanar-stack`) and never on scenes without coplanarity.
//!
//! **Invariants (checked on every run).** Slots are filled from the first with no gap, every
//! kept fragment is at its layer's depth and once per pixel; F2B-FAB: kept + dropped = the
//! fragments the capture passes let through.

use fragrace_emu::{Buf, Fragment, FragmentKernel, KernelInfo, PassReport};

use super::f2bll::LayerPasses;
use super::Peeled;
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, CapturedFrag, Check, Frame, HazardClass,
    Params,
};
use crate::common::EMPTY;

/// Slots per pixel and layer (the paper's K without attribute packing, Table 1).
pub const SLOTS: u32 = 8;

/// The per-pixel slots: `SLOTS` `(depth bits, primitive)` pairs, depth `EMPTY` when free.
#[derive(Clone, Copy)]
struct Slots {
    depth: Buf<u32>,
    prim: Buf<u32>,
    /// F2B-FAB: per-pixel counters.
    counters: Buf<u32>,
    /// One word: fragments that found no slot.
    dropped: Buf<u32>,
}

/// F2B-FAB's capture: an atomic counter picks the slot.
struct FabCapture {
    s: Slots,
}

impl FragmentKernel for FabCapture {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("f2b-fab-capture")
    }
    async fn shade(&self, f: impl Fragment) {
        let s = &self.s;
        let p = f.pixel_index();
        let i = f.atomic_add(s.counters, p, 1).await;
        if i >= SLOTS {
            f.atomic_add(s.dropped, 0, 1).await;
            return;
        }
        let at = p * SLOTS + i;
        f.store(s.depth, at, f.depth().to_bits()).await;
        f.store(s.prim, at, f.primitive_id()).await;
    }
}

/// F2B-KB's capture: the first empty slot, found and filled with plain accesses.
struct KbCapture {
    s: Slots,
}

impl FragmentKernel for KbCapture {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("f2b-kb-capture")
    }
    async fn shade(&self, f: impl Fragment) {
        let s = &self.s;
        let base = f.pixel_index() * SLOTS;
        for i in 0..SLOTS {
            if f.load(s.depth, base + i).await == EMPTY {
                f.store(s.depth, base + i, f.depth().to_bits()).await;
                f.store(s.prim, base + i, f.primitive_id()).await;
                return;
            }
        }
        f.atomic_add(s.dropped, 0, 1).await;
    }
}

/// Which slot allocation.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Allocation {
    /// Atomic per-pixel counter (F2B-FAB).
    Counter,
    /// Plain read-modify-write search (F2B-KB).
    Search,
}

/// `f2b-fab` (`Allocation::Counter`) or `f2b-kb` (`Allocation::Search`).
pub struct F2bB(Allocation);

impl F2bB {
    pub const fn fab() -> F2bB {
        F2bB(Allocation::Counter)
    }
    pub const fn kb() -> F2bB {
        F2bB(Allocation::Search)
    }
}

impl Algorithm for F2bB {
    fn info(&self) -> AlgoInfo {
        let common = AlgoInfo {
            name: "f2b-fab",
            family: "depth peeling",
            summary: "",
            source: "depth-fighting paper, section 3.2.1 (F2B-B, Algorithm 3) and Table 1",
            passes: "2 geometry per iteration (at most k), halted by occlusion queries",
            memory: "12 + 8 K bytes (K = 8): depth buffer, R32F layer, the previous layer read-only; K slots of \
                     depth and primitive (Table 1, F2B-B: K + 4 words with a one-word colour per slot; two \
                     words here)",
            hazard: HazardClass::HazardFree,
            capacity: Capacity::KNearest,
        };
        match self.0 {
            Allocation::Counter => AlgoInfo {
                summary: "approximate coplanarity-aware front-to-back peeling: each layer's coplanar fragments into \
                          K = 8 slots per pixel handed out by an atomic counter; more than K at one layer are lost \
                          (counted)",
                memory: "16 + 8 K bytes (K = 8): depth buffer, R32F layer, the previous layer read-only, the \
                         counter; K slots of depth and primitive (Table 1, F2B-B: K + 4 words with a one-word \
                         colour per slot; two words here)",
                ..common
            },
            Allocation::Search => AlgoInfo {
                name: "f2b-kb",
                summary: "F2B-B with a k-buffer: each layer's coplanar fragments into the first empty of K = 8 slots, \
                          found with plain loads and stores; coplanar fragments in flight together race for a slot \
                          and overwrite each other",
                hazard: HazardClass::HazardProne,
                ..common
            },
        }
    }

    fn run(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &fragrace_emu::ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        let mut peeled = Peeled::new(frame, params)?;
        let mut device = crate::common::fresh(exec);
        let n = peeled.lists.len() as u64;
        let s = Slots {
            depth: device.buffer::<u32>("f2b-b-depth", n * SLOTS as u64)?,
            prim: device.buffer::<u32>("f2b-b-prim", n * SLOTS as u64)?,
            counters: device.buffer::<u32>(
                "f2b-b-counters",
                if self.0 == Allocation::Counter { n } else { 1 },
            )?,
            dropped: device.buffer::<u32>("f2b-b-dropped", 1)?,
        };
        let mut layers = LayerPasses::new(&peeled, frame)?;
        let mut report = PassReport::default();
        let (mut let_through, mut kept) = (0u64, 0u64);
        let (mut gaps, mut off_layer, mut twice) = (0u64, 0u64, 0u64);
        while peeled.iterations < peeled.k {
            device.memory.fill(s.depth, EMPTY)?;
            device.memory.fill(s.prim, EMPTY)?;
            device.memory.fill(s.counters, 0)?;
            if layers.next_layer(&device, exec, &mut report)?.is_none() {
                break;
            }
            let pass = match self.0 {
                Allocation::Counter => {
                    layers.capture(&device, &FabCapture { s }, exec, &mut report)?
                }
                Allocation::Search => {
                    layers.capture(&device, &KbCapture { s }, exec, &mut report)?
                }
            };
            peeled.iterations += 1;
            let_through += pass.stats.samples_passed;
            let depth = device.memory.read(s.depth)?;
            let prim = device.memory.read(s.prim)?;
            let Some(layer) = layers.layer() else {
                break;
            };
            for (p, list) in peeled.lists.iter_mut().enumerate() {
                let at = p * SLOTS as usize;
                let slots = &depth[at..at + SLOTS as usize];
                let used = slots.iter().take_while(|&&d| d != EMPTY).count();
                if slots[used..].iter().any(|&d| d != EMPTY) {
                    gaps += 1;
                }
                let mut layer_frags: Vec<CapturedFrag> = (0..used)
                    .map(|i| CapturedFrag::from_bits(depth[at + i], prim[at + i]))
                    .collect();
                layer_frags.sort_by_key(|f| f.prim);
                let d = super::texel_f32(layer, p)[0];
                off_layer += layer_frags.iter().filter(|f| f.depth != d).count() as u64;
                twice += layer_frags
                    .windows(2)
                    .filter(|w| w[0].prim == w[1].prim)
                    .count() as u64;
                kept += used as u64;
                list.extend(layer_frags);
            }
        }
        let dropped = u64::from(device.memory.read(s.dropped)?[0]);
        let mut checks = vec![Check::new(
            "slots fill from the first, hold fragments of their layer, each once",
            gaps == 0 && off_layer == 0 && twice == 0,
            format!(
                "{gaps} pixels with a gap, {off_layer} fragments off the layer, {twice} repeats"
            ),
        )];
        let accounted = kept + dropped == let_through;
        match self.0 {
            Allocation::Counter => {
                checks.push(Check::new(
                    "every fragment at a layer is kept or counted as dropped",
                    accounted,
                    format!("{kept} kept + {dropped} dropped of {let_through} at the layers"),
                ));
                checks.push(super::conservation(
                    layers.exhausted,
                    kept + dropped,
                    layers.generated,
                ));
            }
            Allocation::Search => checks.push(Check::new(
                "fragments overwritten in a slot by a racing one (informational)",
                true,
                format!(
                    "{} of {let_through} at the layers: {kept} kept, {dropped} found no slot",
                    let_through.saturating_sub(kept + dropped)
                ),
            )),
        }
        let bytes = device.memory.bytes();
        let mut result = peeled.finish(report, checks, bytes, 12);
        result.dropped = dropped;
        Ok(result)
    }
}


/// The algorithms of this file, for its family's registry line.
pub(super) fn algorithms() -> Vec<Box<dyn crate::algo::Algorithm>> {
    vec![Box::new(F2bB::fab()), Box::new(F2bB::kb())]
}

#[cfg(test)]
mod tests {
    use fragrace_emu::{ExecConfig, Policy};

    use super::*;
    use crate::testing::{assert_exact_everywhere, frame, run, scheduled};

    #[test]
    fn fab_is_exact_under_every_executor_while_layers_fit() {
        assert_exact_everywhere(&F2bB::fab(), &Params::default(), 1);
    }

    #[test]
    fn fab_keeps_k_slots_of_a_layer_and_counts_the_rest() {
        let mesh = crate::testing::coplanar_stack(11);
        let f = frame(&mesh, 8);
        let params = Params {
            k: 16,
            ..Params::default()
        };
        let (r, m) = run(&F2bB::fab(), &f, &params, &ExecConfig::parallel(2));
        for c in &r.checks {
            assert!(c.passed, "{}: {}", c.name, c.detail);
        }
        // 11 coplanar per covered pixel, 8 slots: 3 lost per pixel.
        assert_eq!(r.dropped, 3 * m.covered_pixels);
        assert_eq!(m.captured, 8 * m.covered_pixels);
    }

    #[test]
    fn kb_loses_racing_coplanar_fragments_and_the_detector_sees_it() {
        let mesh = crate::testing::coplanar_stack(6);
        let f = frame(&mesh, 8);
        let params = Params::default();
        let (r, m) = run(&F2bB::kb(), &f, &params, &ExecConfig::ordered());
        assert_eq!(m.error_pixels, 0, "one at a time, the slot search is exact");
        assert_eq!(r.report.hazards.total(), 0);
        let mut lost = 0;
        for seed in 0..3 {
            let (r, m) = run(&F2bB::kb(), &f, &params, &scheduled(Policy::Random, seed));
            assert!(r.report.hazards.lost_updates > 0, "seed {seed}");
            lost += m.error_pixels;
        }
        assert!(lost > 0, "racing coplanar fragments overwrite each other");
    }
}
