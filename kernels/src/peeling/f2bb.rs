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
//! - **F2B-KB-ATOMIC** (`f2b-kb-atomic`): the same search as Algorithm 3 writes it, with the
//!   legend's atomic: slot `i` is claimed by an atomic compare-exchange of its depth word from
//!   empty to the fragment's depth, and only the winner writes the slot's primitive. This is
//!   the reading under which the paper's "RMWH-free" holds: no two fragments share a slot,
//!   under every executor (hazard-free; what does not fit `K` is counted, as F2B-FAB).
//!   Registered next to `f2b-kb` so that both readings can be compared.
//!
//! The slots ([`Slots`]) are shared with DUAL-B (`super::dualb`), which keeps a row per
//! pixel and direction.
//!
//! **Invariants (checked on every run).** Slots are filled from the first with no gap, every
//! kept fragment is at its layer's depth and once per pixel; F2B-FAB and F2B-KB-ATOMIC: kept +
//! dropped = the fragments the capture passes let through.

use fragrace_emu::{Buf, Device, Fragment, FragmentKernel, KernelInfo, PassReport};

use super::f2bll::LayerPasses;
use super::Peeled;
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, CapturedFrag, Check, Frame, HazardClass,
    Params,
};
use crate::common::EMPTY;

/// Slots per pixel and layer (the paper's K without attribute packing, Table 1).
pub const SLOTS: u32 = 8;

/// Rows of `SLOTS` `(depth bits, primitive)` pairs, depth `EMPTY` when free: one row per
/// pixel (F2B-B), or per pixel and direction (DUAL-B: front rows, then back rows).
#[derive(Clone, Copy)]
pub(super) struct Slots {
    depth: Buf<u32>,
    prim: Buf<u32>,
    /// FAB: one counter per row.
    counters: Buf<u32>,
    /// One word: fragments that found no slot.
    dropped: Buf<u32>,
    rows: u32,
}

/// How a fragment claims a slot of its row (Algorithm 3).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Allocation {
    /// FAB: an atomic per-row counter hands out the slots.
    Counter,
    /// KB: the first empty slot, found and filled with plain loads and stores.
    Search,
    /// KB as Algorithm 3's legend writes it ("← denotes an atomic memory operation"): the
    /// first empty slot, claimed with an atomic compare-exchange on its depth word.
    AtomicSearch,
}

/// What the host found in the slots after a capture pass.
#[derive(Default)]
pub(super) struct SlotTally {
    /// Fragments kept.
    pub kept: u64,
    /// Rows with a used slot after a free one.
    pub gaps: u64,
    /// Fragments whose depth is not their layer's.
    pub off_layer: u64,
    /// A primitive kept twice in one row.
    pub twice: u64,
}

impl SlotTally {
    /// The slots' check ("slots fill from the first, hold fragments of their layer, each
    /// once").
    pub fn check(&self) -> Check {
        Check::new(
            "slots fill from the first, hold fragments of their layer, each once",
            self.gaps == 0 && self.off_layer == 0 && self.twice == 0,
            format!(
                "{} rows with a gap, {} fragments off the layer, {} repeats",
                self.gaps, self.off_layer, self.twice
            ),
        )
    }
}

impl Slots {
    /// `rows` rows of [`SLOTS`] slots, with per-row counters when `alloc` needs them.
    pub fn new(
        device: &mut Device,
        prefix: &str,
        rows: u64,
        alloc: Allocation,
    ) -> Result<Slots, AlgoError> {
        let words = rows * SLOTS as u64;
        Ok(Slots {
            depth: device.buffer::<u32>(&format!("{prefix}-depth"), words)?,
            prim: device.buffer::<u32>(&format!("{prefix}-prim"), words)?,
            counters: device.buffer::<u32>(
                &format!("{prefix}-counters"),
                if alloc == Allocation::Counter {
                    rows
                } else {
                    1
                },
            )?,
            dropped: device.buffer::<u32>(&format!("{prefix}-dropped"), 1)?,
            rows: rows as u32,
        })
    }

    /// Empties every slot (before a capture pass).
    pub fn clear(&self, device: &Device) -> Result<(), AlgoError> {
        device.memory.fill(self.depth, EMPTY)?;
        device.memory.fill(self.prim, EMPTY)?;
        device.memory.fill(self.counters, 0)?;
        Ok(())
    }

    /// Algorithm 3: stores the fragment into a free slot of `row`, or counts it dropped.
    pub async fn store(&self, f: &impl Fragment, alloc: Allocation, row: u32) {
        let base = row * SLOTS;
        let (z, id) = (f.depth().to_bits(), f.primitive_id());
        match alloc {
            Allocation::Counter => {
                let i = f.atomic_add(self.counters, row, 1).await;
                if i < SLOTS {
                    f.store(self.depth, base + i, z).await;
                    f.store(self.prim, base + i, id).await;
                    return;
                }
            }
            Allocation::Search => {
                for i in 0..SLOTS {
                    if f.load(self.depth, base + i).await == EMPTY {
                        f.store(self.depth, base + i, z).await;
                        f.store(self.prim, base + i, id).await;
                        return;
                    }
                }
            }
            Allocation::AtomicSearch => {
                for i in 0..SLOTS {
                    if f.atomic_compare_exchange(self.depth, base + i, EMPTY, z)
                        .await
                        .is_ok()
                    {
                        // The slot is this fragment's alone: nobody else writes its id.
                        f.store(self.prim, base + i, id).await;
                        return;
                    }
                }
            }
        }
        f.atomic_add(self.dropped, 0, 1).await;
    }

    /// Fragments that found no slot, so far.
    pub fn dropped(&self, device: &Device) -> Result<u64, AlgoError> {
        Ok(u64::from(device.memory.read(self.dropped)?[0]))
    }

    /// Reads every row back: `take(row, fragments)` gets each row's fragments sorted by
    /// primitive (all at one depth), which must be `layer(row)` (`None`: the row has no
    /// layer and must be empty).
    pub fn read(
        &self,
        device: &Device,
        tally: &mut SlotTally,
        layer: impl Fn(usize) -> Option<f32>,
        mut take: impl FnMut(usize, Vec<CapturedFrag>),
    ) -> Result<(), AlgoError> {
        let depth = device.memory.read(self.depth)?;
        let prim = device.memory.read(self.prim)?;
        let k = SLOTS as usize;
        for row in 0..self.rows as usize {
            let at = row * k;
            let slots = &depth[at..at + k];
            let used = slots.iter().take_while(|&&d| d != EMPTY).count();
            if slots[used..].iter().any(|&d| d != EMPTY) {
                tally.gaps += 1;
            }
            if used == 0 {
                continue;
            }
            let mut frags: Vec<CapturedFrag> = (0..used)
                .map(|i| CapturedFrag::from_bits(depth[at + i], prim[at + i]))
                .collect();
            frags.sort_by_key(|f| f.prim);
            let d = layer(row);
            tally.off_layer += frags.iter().filter(|f| Some(f.depth) != d).count() as u64;
            tally.twice += frags.windows(2).filter(|w| w[0].prim == w[1].prim).count() as u64;
            tally.kept += used as u64;
            take(row, frags);
        }
        Ok(())
    }
}

/// The capture kernel of F2B-B: every fragment at the layer into its pixel's row.
struct Capture {
    s: Slots,
    alloc: Allocation,
    name: &'static str,
}

impl FragmentKernel for Capture {
    fn info(&self) -> KernelInfo {
        KernelInfo::new(self.name)
    }
    async fn shade(&self, f: impl Fragment) {
        self.s.store(&f, self.alloc, f.pixel_index()).await;
    }
}

/// `f2b-fab` (`Allocation::Counter`), `f2b-kb` (`Allocation::Search`) or `f2b-kb-atomic`
/// (`Allocation::AtomicSearch`).
pub struct F2bB(Allocation);

impl F2bB {
    pub const fn fab() -> F2bB {
        F2bB(Allocation::Counter)
    }
    pub const fn kb() -> F2bB {
        F2bB(Allocation::Search)
    }
    pub const fn kb_atomic() -> F2bB {
        F2bB(Allocation::AtomicSearch)
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
            Allocation::AtomicSearch => AlgoInfo {
                name: "f2b-kb-atomic",
                summary: "F2B-KB as Algorithm 3 writes it: the first empty of K = 8 slots claimed with an atomic \
                          compare-exchange (\"<- denotes an atomic memory operation\"), so coplanar fragments in \
                          flight together never share a slot; more than K at one layer are lost (counted)",
                ..common
            },
        }
    }

    fn takes_geometry_culling(&self) -> bool {
        true
    }

    fn run_frame(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &fragrace_emu::ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        let mut peeled = Peeled::new(frame, params)?;
        let mut device = crate::common::fresh(exec);
        let n = peeled.lists.len() as u64;
        let s = Slots::new(&mut device, "f2b-b", n, self.0)?;
        let name = match self.0 {
            Allocation::Counter => "f2b-fab-capture",
            Allocation::Search => "f2b-kb-capture",
            Allocation::AtomicSearch => "f2b-kb-atomic-capture",
        };
        let kernel = Capture {
            s,
            alloc: self.0,
            name,
        };
        let mut layers = LayerPasses::new(&peeled, frame)?;
        let mut report = PassReport::default();
        let mut let_through = 0u64;
        let mut tally = SlotTally::default();
        while peeled.iterations < peeled.k {
            s.clear(&device)?;
            if layers.next_layer(&device, exec, &mut report)?.is_none() {
                break;
            }
            let pass = layers.capture(&device, &kernel, exec, &mut report)?;
            peeled.iterations += 1;
            let_through += pass.stats.samples_passed;
            let Some(layer) = layers.layer() else {
                break;
            };
            let lists = &mut peeled.lists;
            s.read(
                &device,
                &mut tally,
                |p| Some(super::texel_f32(layer, p)[0]),
                |p, frags| lists[p].extend(frags),
            )?;
            layers.end_iteration(&device, exec, &mut report)?;
        }
        let dropped = s.dropped(&device)?;
        let kept = tally.kept;
        let mut checks = vec![tally.check()];
        if self.0 == Allocation::Search {
            checks.push(Check::new(
                "fragments overwritten in a slot by a racing one (informational)",
                true,
                format!(
                    "{} of {let_through} at the layers: {kept} kept, {dropped} found no slot",
                    let_through.saturating_sub(kept + dropped)
                ),
            ));
        } else {
            checks.push(Check::new(
                "every fragment at a layer is kept or counted as dropped",
                kept + dropped == let_through,
                format!("{kept} kept + {dropped} dropped of {let_through} at the layers"),
            ));
            checks.push(super::conservation(
                layers.exhausted,
                kept + dropped,
                layers.generated,
            ));
        }
        let bytes = device.memory.bytes();
        let mut result = peeled.finish(report, checks, bytes, 12);
        result.dropped = dropped;
        result.geometry_culling = layers.culling();
        Ok(result)
    }
}


/// The algorithms of this file, for its family's registry line.
pub(super) fn algorithms() -> Vec<Box<dyn crate::algo::Algorithm>> {
    vec![
        Box::new(F2bB::fab()),
        Box::new(F2bB::kb()),
        Box::new(F2bB::kb_atomic()),
    ]
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

    #[test]
    fn kb_atomic_is_exact_under_every_executor_while_layers_fit() {
        assert_exact_everywhere(&F2bB::kb_atomic(), &Params::default(), 1);
    }

    #[test]
    fn kb_atomic_never_loses_racing_coplanar_fragments() {
        // Where `f2b-kb` loses updates (the test above), the atomic claim loses none.
        let mesh = crate::testing::coplanar_stack(6);
        let f = frame(&mesh, 8);
        let params = Params::default();
        for seed in 0..3 {
            let (r, m) = run(
                &F2bB::kb_atomic(),
                &f,
                &params,
                &scheduled(Policy::Random, seed),
            );
            assert_eq!(r.report.hazards.total(), 0, "seed {seed}");
            assert_eq!(m.error_pixels, 0, "seed {seed}: {:?}", r.checks);
            assert_eq!(r.dropped, 0);
        }
        // 11 coplanar fragments, 8 slots: 3 counted per pixel, as f2b-fab.
        let mesh = crate::testing::coplanar_stack(11);
        let f = frame(&mesh, 8);
        let (r, m) = run(
            &F2bB::kb_atomic(),
            &f,
            &params,
            &scheduled(Policy::Random, 0),
        );
        assert_eq!(r.dropped, 3 * m.covered_pixels);
        assert_eq!(m.captured, 8 * m.covered_pixels);
    }
}
