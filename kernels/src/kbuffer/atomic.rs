//! The atomic-min k-buffers: each slot is updated only by `atomicMin`, so no fragment is ever
//! lost to a race (the "atomic operations" k-buffer variants \[MCTB13\] of the occupancy paper,
//! section 1, and the known 64-bit key hazards of docs/hazards.md; the llvmpipe peer's `kbuf-atomic`).
//!
//! **The insertion chain.** A fragment carries its key `v` down the pixel's k slots:
//! `old = atomicMin(slot[i], v); if old == EMPTY: done; v = max(old, v)`. Each step keeps the
//! smaller of (slot, carried) in the slot and carries the larger on, so the multiset
//! {slots} + {values being carried} never changes, each slot only decreases, and a carried
//! value only moves to higher slots. When every fragment has finished, the slots hold the k
//! smallest keys in ascending order (a value dropped off the end was larger than k others)
//! under every interleaving.
//!
//! - `kb-atomic32`: 32-bit keys are the depth's f32 bits (order-preserving for depth >= 0,
//!   see [`super::slots::depth_key`]); a second geometry pass attaches primitives: each
//!   fragment whose key is among the k claims, by compare-exchange, the first unclaimed slot
//!   holding its key. Equal depths are kept as separate slots by the chain (the carried
//!   value equals the old one and moves on), so `m` coplanar fragments with `c <= m` slots of
//!   their depth claim exactly `c` slots, one each: the depth multiset is exact and which
//!   coplanar fragment got which slot is the only racy part (known hazard, docs/hazards.md: "equal depths
//!   deduplicate to one slot and the colour pass then races on it" is the bug this avoids).
//! - `kb-atomic64`: one pass on 64-bit keys `depth bits << 32 | primitive id`; keys are unique
//!   per pixel, so the kept set is exactly the k nearest in the truth's order.

use fragrace_emu::{Buf, Device, ExecConfig, Fragment, FragmentKernel, KernelInfo, Word};

use super::checks::Shape;
use super::run::KbRun;
use super::slots::{depth_key, pack64, Slots};
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, CapturedFrag, Check,
    Frame, HazardClass, Params,
};
use crate::common::EMPTY;

pub(super) fn algorithms() -> Vec<Box<dyn Algorithm>> {
    vec![Box::new(KbAtomic32), Box::new(KbAtomic64)]
}

/// Per-pixel fragment counts and the count of negative depths: what the invariants need
/// besides the slots (instrumentation, not part of the algorithm).
#[derive(Clone, Copy)]
pub struct Census {
    /// Fragments per pixel (atomic add).
    pub count: Buf<u32>,
    /// Fragments with a negative depth, whose bits would break the key order.
    pub negative: Buf<u32>,
}

impl Census {
    fn new(run: &mut KbRun<'_>) -> Result<Census, AlgoError> {
        Ok(Census {
            count: run.device.buffer::<u32>("kb-count", run.n as u64)?,
            negative: run.device.buffer::<u32>("kb-negative-depths", 1)?,
        })
    }

    async fn record(&self, f: impl Fragment) {
        f.atomic_add(self.count, f.pixel_index(), 1).await;
        let z = f.depth();
        if z < 0.0 || z.is_nan() {
            f.atomic_add(self.negative, 0, 1).await;
        }
    }

    /// The checks on the slots read back (`raw`) and the census's buffers. `by_prim`: the
    /// slots are ordered by `(depth, primitive)` (64-bit keys), not by depth alone.
    fn checks(
        &self,
        device: &Device,
        raw: &[Vec<Option<CapturedFrag>>],
        by_prim: bool,
        width: u32,
    ) -> Result<Vec<Check>, AlgoError> {
        let counts = device.memory.read(self.count)?;
        let negative = device.memory.read(self.negative)?[0];
        let shape = Shape::of(raw, by_prim, Some(&counts));
        Ok(vec![
            // The design rule: "atomic-min k-buffer: final slots are the k smallest keys under
            // every interleaving". That they are the k smallest of the truth is the oracle's
            // job; here: sorted, and exactly min(k, n) of them.
            shape.check(width, true),
            Check::new(
                "depths non-negative (the unsigned order of the keys is the depth order)",
                negative == 0,
                format!("{negative} fragments with a negative or NaN depth"),
            ),
        ])
    }
}

/// The atomic-min insertion chain of `v` into the k slots at `base` (`oit.py`'s
/// `FS_KBUF_ATOMIC_DEPTH`, on 32- or 64-bit words); `empty` is the key of an empty slot,
/// the largest of its width.
async fn chain<T: Word + Ord>(
    f: impl Fragment,
    key: Buf<T>,
    base: u32,
    k: u32,
    mut v: T,
    empty: T,
) {
    for i in 0..k {
        let old = f.atomic_min(key, base + i, v).await;
        if old == empty {
            return;
        }
        v = v.max(old);
    }
}

/// `kb-atomic32`, pass 1: depth keys.
pub struct Depth32 {
    pub key: Buf<u32>,
    pub k: u32,
    pub census: Census,
}

impl FragmentKernel for Depth32 {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("kb-atomic32-depth").with_pixel_array(self.key, self.k)
    }
    async fn shade(&self, f: impl Fragment) {
        self.census.record(f).await;
        chain(
            f,
            self.key,
            f.pixel_index() * self.k,
            self.k,
            depth_key(f.depth()),
            EMPTY,
        )
        .await;
    }
}

/// `kb-atomic32`, pass 2: each fragment among the k claims one slot of its depth
/// (`oit.py`'s `FS_KBUF_ATOMIC_COLOR`, claiming with the primitive id instead of the colour
/// so the capture can name it). The keys are read-only in this pass, so plain loads of them
/// do not race.
pub struct Claim32 {
    pub key: Buf<u32>,
    pub prim: Buf<u32>,
    pub k: u32,
    /// Fragments among the k nearest depths that found no slot (coplanar fragments beyond
    /// the slots of their depth; informational).
    pub unclaimed: Buf<u32>,
}

impl FragmentKernel for Claim32 {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("kb-atomic32-claim").with_pixel_array(self.key, self.k)
    }
    async fn shade(&self, f: impl Fragment) {
        let base = f.pixel_index() * self.k;
        let v = depth_key(f.depth());
        if v > f.load(self.key, base + self.k - 1).await {
            return;
        }
        for i in 0..self.k {
            let kv = f.load(self.key, base + i).await;
            if kv > v {
                // Slots are sorted: no slot of this depth is left unclaimed.
                break;
            }
            if kv == v
                && f.atomic_compare_exchange(self.prim, base + i, EMPTY, f.primitive_id())
                    .await
                    .is_ok()
            {
                return;
            }
        }
        f.atomic_add(self.unclaimed, 0, 1).await;
    }
}

/// `kb-atomic64`: one pass on packed keys.
pub struct Store64 {
    pub key: Buf<u64>,
    pub k: u32,
    pub census: Census,
}

impl FragmentKernel for Store64 {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("kb-atomic64-store").with_pixel_array(self.key, self.k)
    }
    async fn shade(&self, f: impl Fragment) {
        self.census.record(f).await;
        chain(
            f,
            self.key,
            f.pixel_index() * self.k,
            self.k,
            pack64(f.depth(), f.primitive_id()),
            u64::MAX,
        )
        .await;
    }
}

/// `kb-atomic32`: see the module documentation.
pub struct KbAtomic32;

impl Algorithm for KbAtomic32 {
    /// Its capture passes run through `KbRun::capture`, which puts them behind occupancy
    /// culling when asked.
    fn takes_occupancy(&self) -> bool {
        true
    }
    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "kb-atomic32",
            family: "k-buffer",
            summary: "atomic-min insertion chain on 32-bit depth keys, then a second pass where each of the k \
                      claims a slot of its depth by compare-exchange",
            source: "atomic k-buffer variants [MCTB13] (occupancy paper, section 1); known hazards (docs/hazards.md); llvmpipe peer \
                     `kbuf-atomic`",
            passes: "2 geometry + 1 full-screen (resolve)",
            memory: "8 k + 4 bytes: k keys + k primitive ids (Table 1, KB: 2K + 2 words) + the fragment count \
                     of the invariant; + 16-byte resolve target",
            hazard: HazardClass::HazardFree,
            capacity: Capacity::KNearest,
        }
    }


    /// The capture passes and the resolve; the slots are read back and checked afterwards
    /// ([`AlgoResult::deferred`]).
    fn run_frame(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        let mut run = KbRun::new(frame, params, exec)?;
        let len = run.n as u64 * run.k as u64;
        let key = run.device.buffer::<u32>("kb-key", len)?;
        let prim = run.device.buffer::<u32>("kb-prim", len)?;
        let unclaimed = run.device.buffer::<u32>("kb-unclaimed", 1)?;
        run.device.memory.fill(key, EMPTY)?;
        run.device.memory.fill(prim, EMPTY)?;
        let census = Census::new(&mut run)?;
        let k = run.k;
        let mut report = run.capture(&Depth32 { key, k, census })?;
        report.merge(&run.capture(&Claim32 {
            key,
            prim,
            k,
            unclaimed,
        })?);
        let slots = Slots::Key32 { key, prim };
        let width = frame.width;
        run.finish_deferred(slots, report, 0, 0, move |device, raw| {
            let mut checks = census.checks(device, raw, false, width)?;
            let keys = device.memory.read(key)?;
            let prims = device.memory.read(prim)?;
            let mismatched = keys
                .iter()
                .zip(&prims)
                .filter(|(&k, &p)| (k == EMPTY) != (p == EMPTY))
                .count();
            checks.push(Check::new(
                "every key slot claimed by exactly one fragment of its depth, no empty slot claimed",
                mismatched == 0,
                format!("{mismatched} slots claimed wrongly"),
            ));
            let left = device.memory.read(unclaimed)?[0];
            checks.push(Check::new(
                "coplanar fragments beyond the slots of their depth (informational)",
                true,
                format!("{left} fragments at a kept depth found every slot of that depth claimed"),
            ));
            Ok(checks)
        })
    }
}

/// `kb-atomic64`: see the module documentation.
pub struct KbAtomic64;

impl Algorithm for KbAtomic64 {
    /// Its capture passes run through `KbRun::capture`, which puts them behind occupancy
    /// culling when asked.
    fn takes_occupancy(&self) -> bool {
        true
    }
    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "kb-atomic64",
            family: "k-buffer",
            summary: "atomic-min insertion chain on 64-bit keys (depth bits << 32 | primitive id), one pass",
            source: "atomic k-buffer variants [MCTB13] (occupancy paper, section 1); 64-bit keys (docs/hazards.md)",
            passes: "1 geometry + 1 full-screen (resolve)",
            memory: "8 k + 4 bytes: k 64-bit keys (Table 1, KB: 2K + 2 words, packed) + the fragment count of the \
                     invariant; + 16-byte resolve target",
            hazard: HazardClass::HazardFree,
            capacity: Capacity::KNearest,
        }
    }


    /// The capture passes and the resolve; the slots are read back and checked afterwards
    /// ([`AlgoResult::deferred`]).
    fn run_frame(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        let mut run = KbRun::new(frame, params, exec)?;
        let key = run
            .device
            .buffer::<u64>("kb-key64", run.n as u64 * run.k as u64)?;
        run.device.memory.fill(key, u64::MAX)?;
        let census = Census::new(&mut run)?;
        let report = run.capture(&Store64 {
            key,
            k: run.k,
            census,
        })?;
        let slots = Slots::Key64 { key };
        let width = frame.width;
        run.finish_deferred(slots, report, 0, 0, move |device, raw| {
            census.checks(device, raw, true, width)
        })
    }
}

#[cfg(test)]
mod tests {
    use fragrace_emu::ExecConfig;

    use super::*;
    use crate::testing::*;

    #[test]
    fn atomic32_exact_under_every_executor() {
        assert_exact_everywhere(&KbAtomic32, &Params::default(), 3);
    }

    #[test]
    fn atomic64_exact_under_every_executor() {
        assert_exact_everywhere(&KbAtomic64, &Params::default(), 3);
    }

    #[test]
    fn small_and_large_k() {
        let mesh = quads(16);
        let frame = frame(&mesh, 16);
        for k in [1, 2, 3, 17, 32] {
            let params = Params {
                k,
                ..Params::default()
            };
            for exec in [
                ExecConfig::ordered(),
                scheduled(fragrace_emu::Policy::Random, k as u64),
            ] {
                for algo in [&KbAtomic32 as &dyn Algorithm, &KbAtomic64] {
                    let (r, m) = run(algo, &frame, &params, &exec);
                    assert_eq!(
                        m.error_pixels,
                        0,
                        "{} k = {k}: first error {:?}",
                        algo.info().name,
                        m.first_error
                    );
                    assert_checks(&r, algo.info().name);
                }
            }
        }
    }

    #[test]
    fn coplanar_fragments_each_get_their_own_slot() {
        // Quad 0 and its duplicate: every pixel of quad 0 has two fragments at one depth, kept
        // as two slots, each claimed by a different primitive.
        let mesh = quads(16);
        let frame = frame(&mesh, 16);
        let (r, m) = run(
            &KbAtomic32,
            &frame,
            &Params::default(),
            &ExecConfig::ordered(),
        );
        assert_eq!(m.error_pixels, 0);
        assert!(m.coplanarity > 0.0, "the scene has coplanar fragments");
        let c = r.capture.unwrap();
        let doubled = (0..c.pixels())
            .filter(|&p| {
                c.pixel(p)
                    .windows(2)
                    .any(|w| w[0].depth == w[1].depth && w[0].prim != w[1].prim)
            })
            .count();
        assert!(
            doubled > 0,
            "coplanar pairs are kept as two slots with two primitives"
        );
    }
}
