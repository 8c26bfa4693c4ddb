//! The slots of the k-buffers that keep `(depth, primitive)` pairs: their layout in memory
//! ([`SplitSlots`], packed 64-bit keys, [`Slots`]), their order ([`key_less`]), the sorted
//! read-modify-write insertion ([`rmw_insert`]) and the limits on k.

use fragrace_emu::{Buf, Device, Fragment};

use crate::algo::{AlgoError, CapturedFrag, Params};
use crate::common::EMPTY;

/// Largest k the k-buffers accept: a kernel keeps its pixel's slots in fixed local arrays,
/// as a shader keeps them in registers (the seeds use k <= 32 with packing, Table 1).
pub(super) const MAX_K: u32 = 64;

/// `params.k`, checked against `1..=MAX_K`.
pub(super) fn k_of(params: &Params) -> Result<u32, AlgoError> {
    if params.k == 0 || params.k > MAX_K {
        Err(AlgoError::Invalid(format!(
            "k = {} is outside 1..={MAX_K}",
            params.k
        )))
    } else {
        Ok(params.k)
    }
}

/// The order of k-buffer slots: depth, then primitive id (the truth's order). Breaking
/// ties by primitive (rather than by arrival, as Bavoil's depth-only compare does) makes the
/// kept set of a serial run independent of arrival order even with coplanar fragments
/// (depth-fighting paper, section 1), and it is what lets `kb-multipass` resume exactly
/// behind a certified fragment.
pub(super) fn key_less(ad: f32, ap: u32, bd: f32, bp: u32) -> bool {
    ad < bd || (ad == bd && ap < bp)
}

/// k depth slots and k primitive slots per pixel, pixel `p`'s at `p * k ..`.
#[derive(Clone, Copy, Debug)]
pub struct SplitSlots {
    pub depth: Buf<f32>,
    pub prim: Buf<u32>,
}

impl SplitSlots {
    /// Allocates and clears (`+inf` / `EMPTY`) the slots of `pixels` pixels.
    pub fn new(device: &mut Device, pixels: usize, k: u32) -> Result<SplitSlots, AlgoError> {
        let len = pixels as u64 * k as u64;
        let depth = device.buffer::<f32>("kb-depth", len)?;
        let prim = device.buffer::<u32>("kb-prim", len)?;
        device.memory.fill(depth, f32::INFINITY)?;
        device.memory.fill(prim, EMPTY)?;
        Ok(SplitSlots { depth, prim })
    }
}

/// Bavoil's insertion on the `cap` slots at `base`, with plain accesses only: load them all
/// (two multi-word records, so the detector reports a load torn by another fragment's
/// store), sorted insertion if `(z, prim)` is nearer than the farthest (which falls out),
/// store them all back. Returns whether it inserted. Correct only if no other fragment of the
/// pixel touches the slots meanwhile (a serial run, a lock, or pixel interlock).
pub(super) async fn rmw_insert(
    f: impl Fragment,
    kb: SplitSlots,
    base: u32,
    cap: usize,
    z: f32,
    prim: u32,
) -> bool {
    let mut d = [f32::INFINITY; MAX_K as usize];
    let mut c = [EMPTY; MAX_K as usize];
    let cap = cap.clamp(1, MAX_K as usize);
    f.load_record(kb.depth, base, &mut d[..cap]).await;
    f.load_record(kb.prim, base, &mut c[..cap]).await;
    if !key_less(z, prim, d[cap - 1], c[cap - 1]) {
        return false;
    }
    let mut j = cap - 1;
    while j > 0 && key_less(z, prim, d[j - 1], c[j - 1]) {
        d[j] = d[j - 1];
        c[j] = c[j - 1];
        j -= 1;
    }
    d[j] = z;
    c[j] = prim;
    f.store_record(kb.depth, base, &d[..cap]).await;
    f.store_record(kb.prim, base, &c[..cap]).await;
    true
}

/// Where a k-buffer keeps its k slots per pixel, for the shared resolve and readback.
#[derive(Clone, Copy, Debug)]
pub(super) enum Slots {
    /// Depth (`+inf` = empty) and primitive id, in two buffers.
    Split(SplitSlots),
    /// 32-bit keys (f32 depth bits, `EMPTY` = empty) and the primitive id that claimed each.
    Key32 { key: Buf<u32>, prim: Buf<u32> },
    /// 64-bit keys `depth bits << 32 | primitive id` (`u64::MAX` = empty).
    Key64 { key: Buf<u64> },
}

impl Slots {
    /// Slot `i` as a kernel reads it (plain loads); `None` when empty.
    pub(super) async fn load(&self, f: impl Fragment, i: u32) -> Option<CapturedFrag> {
        match *self {
            Slots::Split(s) => {
                let depth = f.load(s.depth, i).await;
                let prim = f.load(s.prim, i).await;
                (depth != f32::INFINITY).then_some(CapturedFrag { depth, prim })
            }
            Slots::Key32 { key, prim } => {
                let k = f.load(key, i).await;
                let prim = f.load(prim, i).await;
                (k != EMPTY).then_some(CapturedFrag::from_bits(k, prim))
            }
            Slots::Key64 { key } => {
                let k = f.load(key, i).await;
                (k != u64::MAX).then(|| unpack64(k))
            }
        }
    }

    /// Every slot, read back on the host, per pixel in slot order.
    pub(super) fn read(
        &self,
        device: &Device,
        k: u32,
    ) -> Result<Vec<Vec<Option<CapturedFrag>>>, AlgoError> {
        let flat: Vec<Option<CapturedFrag>> = match *self {
            Slots::Split(s) => {
                let d = device.memory.read(s.depth)?;
                let p = device.memory.read(s.prim)?;
                d.iter()
                    .zip(&p)
                    .map(|(&depth, &prim)| {
                        (depth != f32::INFINITY).then_some(CapturedFrag { depth, prim })
                    })
                    .collect()
            }
            Slots::Key32 { key, prim } => {
                let d = device.memory.read(key)?;
                let p = device.memory.read(prim)?;
                d.iter()
                    .zip(&p)
                    .map(|(&k, &prim)| (k != EMPTY).then_some(CapturedFrag::from_bits(k, prim)))
                    .collect()
            }
            Slots::Key64 { key } => device
                .memory
                .read(key)?
                .into_iter()
                .map(|k| (k != u64::MAX).then(|| unpack64(k)))
                .collect(),
        };
        Ok(flat.chunks(k as usize).map(<[_]>::to_vec).collect())
    }
}

/// The 64-bit key of a fragment: depth bits in the high word (order-preserving for
/// depth >= 0), primitive id in the low word (unique per pixel, so keys never tie).
pub(super) fn pack64(depth: f32, prim: u32) -> u64 {
    ((depth_key(depth) as u64) << 32) | prim as u64
}

pub(super) fn unpack64(k: u64) -> CapturedFrag {
    CapturedFrag::from_bits((k >> 32) as u32, k as u32)
}

/// The f32 bits of a depth as an unsigned key. For depth >= 0 the unsigned order of the bits
/// is the float order (IEEE 754 sign-magnitude with a biased exponent), which is what lets
/// `atomicMin` on uint order depths (known hazard, docs/hazards.md: "keys compared as uint assume depth >= 0").
/// `-0.0` is canonicalised to `+0.0` (its bits would sort last); it compares equal to `+0.0`
/// for the oracle. Negative depths cannot come out of the [0, 1] window transform; the
/// atomic k-buffers count any that do and fail a check.
pub(super) fn depth_key(depth: f32) -> u32 {
    (depth + 0.0).to_bits()
}
