//! The memory operations a kernel performs, and their semantics on 32- and 64-bit atomic
//! words: the real atomic instruction ([`apply32`], [`apply64`]) and the same operation as a
//! pure function ([`op32`], [`op64`]) for the single-threaded scheduled executor.

use super::word::{Word, WordKind};
use crate::sync::{AtomicU32, AtomicU64, Ordering};

/// The kind of a memory operation, for statistics and hazard detection.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
pub enum OpKind {
    Load,
    Store,
    AtomicLoad,
    AtomicStore,
    Add,
    Sub,
    Min,
    Max,
    And,
    Or,
    Xor,
    Exchange,
    CompareExchange,
}

impl OpKind {
    pub const ALL: [OpKind; 13] = [
        OpKind::Load,
        OpKind::Store,
        OpKind::AtomicLoad,
        OpKind::AtomicStore,
        OpKind::Add,
        OpKind::Sub,
        OpKind::Min,
        OpKind::Max,
        OpKind::And,
        OpKind::Or,
        OpKind::Xor,
        OpKind::Exchange,
        OpKind::CompareExchange,
    ];
    /// Plain (non-atomic) access.
    pub fn is_plain(self) -> bool {
        matches!(self, OpKind::Load | OpKind::Store)
    }
    /// May change memory.
    pub fn is_write(self) -> bool {
        !matches!(self, OpKind::Load | OpKind::AtomicLoad)
    }
    pub fn name(self) -> &'static str {
        match self {
            OpKind::Load => "load",
            OpKind::Store => "store",
            OpKind::AtomicLoad => "atomic_load",
            OpKind::AtomicStore => "atomic_store",
            OpKind::Add => "add",
            OpKind::Sub => "sub",
            OpKind::Min => "min",
            OpKind::Max => "max",
            OpKind::And => "and",
            OpKind::Or => "or",
            OpKind::Xor => "xor",
            OpKind::Exchange => "exchange",
            OpKind::CompareExchange => "compare_exchange",
        }
    }
}

/// Order-preserving key of an f32 (total order: -NaN < -inf < ... < -0 < +0 < ... < +inf < NaN).
pub fn f32_order_key(v: f32) -> u32 {
    let b = v.to_bits();
    if b & 0x8000_0000 != 0 {
        !b
    } else {
        b | 0x8000_0000
    }
}

/// Compares two words of type `T` as `T` values (f32 through [`f32_order_key`]).
#[inline]
fn less<T: Word>(a: u64, b: u64) -> bool {
    match T::KIND {
        WordKind::I32 => (a as u32 as i32) < (b as u32 as i32),
        WordKind::F32 => {
            f32_order_key(f32::from_bits(a as u32)) < f32_order_key(f32::from_bits(b as u32))
        }
        _ => a < b,
    }
}

/// One operation with its operands (raw bits).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum MemOp {
    Load,
    Store(u64),
    AtomicLoad,
    AtomicStore(u64),
    Add(u64),
    Sub(u64),
    Min(u64),
    Max(u64),
    And(u64),
    Or(u64),
    Xor(u64),
    Exchange(u64),
    /// (expected, new): returns the previous value; success iff it equals `expected`.
    CompareExchange(u64, u64),
}

impl MemOp {
    pub(crate) fn kind(self) -> OpKind {
        match self {
            MemOp::Load => OpKind::Load,
            MemOp::Store(_) => OpKind::Store,
            MemOp::AtomicLoad => OpKind::AtomicLoad,
            MemOp::AtomicStore(_) => OpKind::AtomicStore,
            MemOp::Add(_) => OpKind::Add,
            MemOp::Sub(_) => OpKind::Sub,
            MemOp::Min(_) => OpKind::Min,
            MemOp::Max(_) => OpKind::Max,
            MemOp::And(_) => OpKind::And,
            MemOp::Or(_) => OpKind::Or,
            MemOp::Xor(_) => OpKind::Xor,
            MemOp::Exchange(_) => OpKind::Exchange,
            MemOp::CompareExchange(..) => OpKind::CompareExchange,
        }
    }
}

pub(crate) enum WordRef<'a> {
    W32(&'a AtomicU32),
    W64(&'a AtomicU64),
}

impl WordRef<'_> {
    pub(super) fn load<T: Word>(&self) -> T {
        T::from_bits(match self {
            WordRef::W32(a) => a.load(Ordering::Relaxed) as u64,
            WordRef::W64(a) => a.load(Ordering::Relaxed),
        })
    }

    pub(super) fn store(&self, v: u64) {
        match self {
            WordRef::W32(a) => a.store(v as u32, Ordering::Relaxed),
            WordRef::W64(a) => a.store(v, Ordering::Relaxed),
        }
    }
}

/// Load ordering matching a read-modify-write ordering (loads cannot be Release).
fn load_order(ord: Ordering) -> Ordering {
    match ord {
        Ordering::Release => Ordering::Relaxed,
        Ordering::AcqRel => Ordering::Acquire,
        o => o,
    }
}

fn store_order(ord: Ordering) -> Ordering {
    match ord {
        Ordering::Acquire => Ordering::Relaxed,
        Ordering::AcqRel => Ordering::Release,
        o => o,
    }
}

#[inline(always)]
pub(super) fn apply32<T: Word>(a: &AtomicU32, op: MemOp, ord: Ordering) -> u32 {
    match op {
        MemOp::Load => a.load(Ordering::Relaxed),
        MemOp::Store(v) => {
            a.store(v as u32, Ordering::Relaxed);
            0
        }
        MemOp::AtomicLoad => a.load(load_order(ord)),
        MemOp::AtomicStore(v) => {
            a.store(v as u32, store_order(ord));
            0
        }
        MemOp::Add(v) => match T::KIND {
            WordKind::F32 => rmw32(a, ord, |old| {
                (f32::from_bits(old) + f32::from_bits(v as u32)).to_bits()
            }),
            _ => a.fetch_add(v as u32, ord),
        },
        MemOp::Sub(v) => match T::KIND {
            WordKind::F32 => rmw32(a, ord, |old| {
                (f32::from_bits(old) - f32::from_bits(v as u32)).to_bits()
            }),
            _ => a.fetch_sub(v as u32, ord),
        },
        MemOp::Min(v) => match T::KIND {
            WordKind::U32 => a.fetch_min(v as u32, ord),
            _ => rmw32(a, ord, |old| {
                if less::<T>(v, old as u64) {
                    v as u32
                } else {
                    old
                }
            }),
        },
        MemOp::Max(v) => match T::KIND {
            WordKind::U32 => a.fetch_max(v as u32, ord),
            _ => rmw32(a, ord, |old| {
                if less::<T>(old as u64, v) {
                    v as u32
                } else {
                    old
                }
            }),
        },
        MemOp::And(v) => a.fetch_and(v as u32, ord),
        MemOp::Or(v) => a.fetch_or(v as u32, ord),
        MemOp::Xor(v) => a.fetch_xor(v as u32, ord),
        MemOp::Exchange(v) => a.swap(v as u32, ord),
        MemOp::CompareExchange(e, n) => {
            match a.compare_exchange(e as u32, n as u32, ord, load_order(ord)) {
                Ok(v) | Err(v) => v,
            }
        }
    }
}

/// [`apply32`] on a word no other thread accesses while the operation runs (a slot of a
/// pixel's own array in a tile one worker owns: `KernelInfo::with_own_pixel_array`): the
/// same result as a plain load and store, with no locked instruction. Not atomic: a
/// concurrent access from another thread would lose an update.
#[inline(always)]
pub(super) fn apply32_owned<T: Word>(a: &AtomicU32, op: MemOp) -> u32 {
    let (ret, new) = op32::<T>(a.load(Ordering::Relaxed), op);
    if let Some(v) = new {
        a.store(v, Ordering::Relaxed);
    }
    ret
}

/// [`apply32_owned`] for 64-bit words: [`apply64`] on a word only this thread accesses.
#[inline(always)]
pub(super) fn apply64_owned(a: &AtomicU64, op: MemOp) -> u64 {
    let (ret, new) = op64(a.load(Ordering::Relaxed), op);
    if let Some(v) = new {
        a.store(v, Ordering::Relaxed);
    }
    ret
}

/// One operation on a 32-bit word holding `old`, as a pure function: (the value returned to
/// the kernel, the new value if the word is written). The semantics of [`apply32`].
#[inline]
pub(super) fn op32<T: Word>(old: u32, op: MemOp) -> (u32, Option<u32>) {
    let f = f32::from_bits;
    let new = match op {
        MemOp::Load | MemOp::AtomicLoad => return (old, None),
        MemOp::Store(v) | MemOp::AtomicStore(v) => return (0, Some(v as u32)),
        MemOp::Add(v) => match T::KIND {
            WordKind::F32 => (f(old) + f(v as u32)).to_bits(),
            _ => old.wrapping_add(v as u32),
        },
        MemOp::Sub(v) => match T::KIND {
            WordKind::F32 => (f(old) - f(v as u32)).to_bits(),
            _ => old.wrapping_sub(v as u32),
        },
        MemOp::Min(v) => match T::KIND {
            WordKind::U32 => old.min(v as u32),
            _ if less::<T>(v, old as u64) => v as u32,
            _ => old,
        },
        MemOp::Max(v) => match T::KIND {
            WordKind::U32 => old.max(v as u32),
            _ if less::<T>(old as u64, v) => v as u32,
            _ => old,
        },
        MemOp::And(v) => old & v as u32,
        MemOp::Or(v) => old | v as u32,
        MemOp::Xor(v) => old ^ v as u32,
        MemOp::Exchange(v) => v as u32,
        MemOp::CompareExchange(e, n) if old == e as u32 => n as u32,
        MemOp::CompareExchange(..) => return (old, None),
    };
    (old, Some(new))
}

/// [`op32`] for 64-bit words (unsigned): the semantics of [`apply64`].
#[inline]
pub(super) fn op64(old: u64, op: MemOp) -> (u64, Option<u64>) {
    let new = match op {
        MemOp::Load | MemOp::AtomicLoad => return (old, None),
        MemOp::Store(v) | MemOp::AtomicStore(v) => return (0, Some(v)),
        MemOp::Add(v) => old.wrapping_add(v),
        MemOp::Sub(v) => old.wrapping_sub(v),
        MemOp::Min(v) => old.min(v),
        MemOp::Max(v) => old.max(v),
        MemOp::And(v) => old & v,
        MemOp::Or(v) => old | v,
        MemOp::Xor(v) => old ^ v,
        MemOp::Exchange(v) => v,
        MemOp::CompareExchange(e, n) if old == e => n,
        MemOp::CompareExchange(..) => return (old, None),
    };
    (old, Some(new))
}

/// A read-modify-write through a compare-exchange loop (one atomic step for the kernel).
#[inline]
fn rmw32(a: &AtomicU32, ord: Ordering, f: impl Fn(u32) -> u32) -> u32 {
    let mut old = a.load(Ordering::Relaxed);
    loop {
        match a.compare_exchange_weak(old, f(old), ord, Ordering::Relaxed) {
            Ok(v) => return v,
            Err(v) => old = v,
        }
    }
}

#[inline]
pub(super) fn apply64(a: &AtomicU64, op: MemOp, ord: Ordering) -> u64 {
    match op {
        MemOp::Load => a.load(Ordering::Relaxed),
        MemOp::Store(v) => {
            a.store(v, Ordering::Relaxed);
            0
        }
        MemOp::AtomicLoad => a.load(load_order(ord)),
        MemOp::AtomicStore(v) => {
            a.store(v, store_order(ord));
            0
        }
        MemOp::Add(v) => a.fetch_add(v, ord),
        MemOp::Sub(v) => a.fetch_sub(v, ord),
        MemOp::Min(v) => a.fetch_min(v, ord),
        MemOp::Max(v) => a.fetch_max(v, ord),
        MemOp::And(v) => a.fetch_and(v, ord),
        MemOp::Or(v) => a.fetch_or(v, ord),
        MemOp::Xor(v) => a.fetch_xor(v, ord),
        MemOp::Exchange(v) => a.swap(v, ord),
        MemOp::CompareExchange(e, n) => match a.compare_exchange(e, n, ord, load_order(ord)) {
            Ok(v) | Err(v) => v,
        },
    }
}
