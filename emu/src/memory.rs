//! Shared memory: storage buffers of 32-bit words (u32, i32, f32) and 64-bit words (u64),
//! addressed through typed handles, accessed by kernels only through [`crate::Frag`].
//!
//! Every word is an atomic from [`crate::sync`]: a kernel's *plain* load or store is a
//! relaxed atomic access (racy, as on a GPU, but never undefined behaviour) and its atomics
//! are real read-modify-write instructions. This module knows nothing of invocations,
//! schedules or hazards: it checks bounds and performs operations.

use std::cell::Cell;
use std::fmt;
use std::marker::PhantomData;

use crate::kernel::PixelArray;
use crate::sync::{AtomicU32, AtomicU64, Ordering};

/// Largest buffer, in words (4 GiB of 32-bit words would not be addressable by u32 indices).
pub const MAX_BUFFER_WORDS: u64 = 1 << 31;
/// Largest total storage of a device, in bytes.
pub const MAX_TOTAL_BYTES: u64 = 16 << 30;

/// A word type a buffer can hold.
pub trait Word:
    Copy + Unpin + PartialEq + fmt::Debug + Send + Sync + 'static + sealed::Sealed
{
    /// True for 64-bit words.
    const WIDE: bool;
    const NAME: &'static str;
    const KIND: WordKind;
    fn to_bits(self) -> u64;
    fn from_bits(bits: u64) -> Self;
}

/// The word types, for dispatch in generic code.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WordKind {
    U32,
    I32,
    F32,
    U64,
}

mod sealed {
    pub trait Sealed {}
    impl Sealed for u32 {}
    impl Sealed for i32 {}
    impl Sealed for f32 {}
    impl Sealed for u64 {}
}

impl Word for u32 {
    const WIDE: bool = false;
    const NAME: &'static str = "u32";
    const KIND: WordKind = WordKind::U32;
    fn to_bits(self) -> u64 {
        self as u64
    }
    fn from_bits(bits: u64) -> Self {
        bits as u32
    }
}
impl Word for i32 {
    const WIDE: bool = false;
    const NAME: &'static str = "i32";
    const KIND: WordKind = WordKind::I32;
    fn to_bits(self) -> u64 {
        self as u32 as u64
    }
    fn from_bits(bits: u64) -> Self {
        bits as u32 as i32
    }
}
impl Word for f32 {
    const WIDE: bool = false;
    const NAME: &'static str = "f32";
    const KIND: WordKind = WordKind::F32;
    fn to_bits(self) -> u64 {
        self.to_bits() as u64
    }
    fn from_bits(bits: u64) -> Self {
        f32::from_bits(bits as u32)
    }
}
impl Word for u64 {
    const WIDE: bool = true;
    const NAME: &'static str = "u64";
    const KIND: WordKind = WordKind::U64;
    fn to_bits(self) -> u64 {
        self
    }
    fn from_bits(bits: u64) -> Self {
        bits
    }
}

/// A typed handle to a buffer of a [`Memory`]. Cheap to copy into kernel structs.
pub struct Buf<T> {
    pub(crate) id: u32,
    pub(crate) len: u32,
    _t: PhantomData<fn() -> T>,
}

impl<T> Clone for Buf<T> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<T> Copy for Buf<T> {}
impl<T> fmt::Debug for Buf<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Buf#{}[{}]", self.id, self.len)
    }
}

impl<T: Word> Buf<T> {
    /// Number of words.
    pub fn len(&self) -> u32 {
        self.len
    }
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
    pub fn id(&self) -> u32 {
        self.id
    }
}

/// Where the slot of pixel (x, y) of a per-pixel array lies, for prefetches
/// ([`Memory::pixel_prefetcher`]).
pub(crate) struct PixelPrefetcher<'m> {
    base: *const u8,
    words: u64,
    word_bytes: usize,
    stride: u64,
    width: u64,
    _memory: PhantomData<&'m Memory>,
}

impl PixelPrefetcher<'_> {
    /// The address of the first word of pixel (x, y)'s slot; `None` past the buffer's end
    /// (a hint that does not fit the buffer is ignored, not followed).
    #[inline(always)]
    pub(crate) fn slot(&self, x: u32, y: u32) -> Option<*const u8> {
        // Neither wraps: `y * width + x` < 2^64 for 32-bit operands.
        let word = (y as u64 * self.width + x as u64).saturating_mul(self.stride);
        // In range, so the offset is within the allocation.
        (word < self.words).then(|| self.base.wrapping_add(word as usize * self.word_bytes))
    }

    /// Prefetches pixel (x, y)'s slot.
    #[inline(always)]
    pub(crate) fn pixel(&self, x: u32, y: u32) {
        if let Some(p) = self.slot(x, y) {
            crate::hint::prefetch(p);
        }
    }
}

/// A global word address: buffer id in the high 32 bits, word index in the low 32.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    Hash,
    PartialOrd,
    Ord,
    serde::Serialize,
    serde::Deserialize,
)]
pub struct Addr(pub u64);

impl Addr {
    pub fn new(buffer: u32, index: u32) -> Addr {
        Addr(((buffer as u64) << 32) | index as u64)
    }
    pub fn buffer(self) -> u32 {
        (self.0 >> 32) as u32
    }
    pub fn index(self) -> u32 {
        self.0 as u32
    }
}

/// Why a buffer cannot be created.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum MemoryError {
    #[error(
        "buffer `{name}`: {words} words is more than the {MAX_BUFFER_WORDS} a buffer may hold"
    )]
    BufferTooLarge { name: String, words: u64 },
    #[error(
        "buffer `{name}`: {bytes} bytes would bring device storage past {MAX_TOTAL_BYTES} bytes"
    )]
    OutOfMemory { name: String, bytes: u64 },
    #[error("buffer `{name}` holds {actual} words, but was used as {expected}")]
    WrongType {
        name: String,
        actual: &'static str,
        expected: &'static str,
    },
    #[error("buffer #{0} does not exist on this device")]
    NoSuchBuffer(u32),
    #[error("buffer `{0}` was moved out (Memory::take)")]
    Taken(String),
    #[error("write of {len} words at {offset} into buffer `{name}` of {words} words")]
    OutOfRange {
        name: String,
        offset: u64,
        len: u64,
        words: u32,
    },
}

enum Words {
    W32(Values<AtomicU32>),
    W64(Values<AtomicU64>),
}

/// Where a buffer's first word lies: a multiple of this many bytes (two cache lines, the
/// unit x86's adjacent-line prefetcher fetches).
///
/// Why: per-pixel arrays are addressed by pixel, and tiles (and the screen regions two
/// threads work on) start at pixel columns that are multiples of 8 or 16. `malloc` returns
/// large blocks 16 bytes past a page boundary, so a tile's rows shared their first and last
/// cache lines with the neighbouring tiles', and two threads adding into neighbouring tiles
/// took those lines from each other at every row: 8 % of the pure atomic adds of the
/// bunny at 2048x2048 on two threads (`bench --floor`), 2 % of a binned `count` pass
/// (docs/performance.md, "2026-11-27, night"). GPU APIs align storage buffers too
/// (Vulkan's `minStorageBufferOffsetAlignment`, up to 256 bytes).
pub const BUFFER_ALIGN: usize = 128;

struct Buffer {
    name: String,
    ty: &'static str,
    words: Words,
}

/// A buffer's contents: a `Vec` a little longer than the buffer, whose first `start`
/// elements are padding that puts the first word at a multiple of [`BUFFER_ALIGN`] bytes.
/// Derefs to the words, the padding hidden. `Memory` keeps its buffers' atomic words so
/// (allocated, reused and freed as any `Vec`), and [`Memory::take`] hands them to the host
/// as plain values in the same allocation, without a copy.
#[derive(Clone)]
pub struct Values<T> {
    all: Vec<T>,
    start: usize,
}

impl<T> std::ops::Deref for Values<T> {
    type Target = [T];
    #[inline(always)]
    fn deref(&self) -> &[T] {
        // `start <= all.len()` (set once, by the constructors).
        debug_assert!(self.start <= self.all.len());
        // SAFETY: `start` is at most the length (see above), so the range is in bounds.
        unsafe { self.all.get_unchecked(self.start..) }
    }
}

impl<'a, T> IntoIterator for &'a Values<T> {
    type Item = &'a T;
    type IntoIter = std::slice::Iter<'a, T>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

impl<T> From<Vec<T>> for Values<T> {
    fn from(all: Vec<T>) -> Self {
        Values { all, start: 0 }
    }
}

impl<T> Default for Values<T> {
    fn default() -> Self {
        Values::from(Vec::new())
    }
}

impl<T: PartialEq> PartialEq for Values<T> {
    fn eq(&self, other: &Self) -> bool {
        **self == **other
    }
}

impl<T: PartialEq> PartialEq<Vec<T>> for Values<T> {
    fn eq(&self, other: &Vec<T>) -> bool {
        **self == **other
    }
}

impl<T: std::fmt::Debug> std::fmt::Debug for Values<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        (**self).fmt(f)
    }
}

impl<T> Values<T> {
    /// The values as a `Vec` (a copy only if the buffer had padding before them).
    pub fn into_vec(mut self) -> Vec<T> {
        self.all.drain(..self.start);
        self.all
    }
}

/// The storage of a device: every buffer, by id.
#[derive(Default)]
pub struct Memory {
    buffers: Vec<Buffer>,
    bytes: u64,
    /// Threads that zero a large new buffer (0 or 1: the calling thread alone).
    clear_threads: usize,
}

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

impl Memory {
    pub fn new() -> Memory {
        Memory::default()
    }

    /// Storage whose large new buffers are zeroed by `threads` threads at once, as a GPU
    /// clears with all its cores: one core does not saturate the memory bandwidth (a
    /// 2048x2048 buffer of counts is 16 MiB).
    pub fn with_threads(threads: usize) -> Memory {
        Memory {
            clear_threads: threads,
            ..Memory::default()
        }
    }

    /// Creates a zero-filled buffer of `len` words of `T`.
    pub fn create<T: Word>(&mut self, name: &str, len: u64) -> Result<Buf<T>, MemoryError> {
        if len > MAX_BUFFER_WORDS {
            return Err(MemoryError::BufferTooLarge {
                name: name.into(),
                words: len,
            });
        }
        let bytes = len * if T::WIDE { 8 } else { 4 };
        if self.bytes + bytes > MAX_TOTAL_BYTES {
            return Err(MemoryError::OutOfMemory {
                name: name.into(),
                bytes,
            });
        }
        let threads = self.clear_threads;
        let words = if T::WIDE {
            Words::W64(zeroed_words(len as usize, threads))
        } else {
            Words::W32(zeroed_words(len as usize, threads))
        };
        self.bytes += bytes;
        let id = self.buffers.len() as u32;
        self.buffers.push(Buffer {
            name: name.into(),
            ty: T::NAME,
            words,
        });
        Ok(Buf {
            id,
            len: len as u32,
            _t: PhantomData,
        })
    }

    /// Total bytes of all buffers.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// Words in buffer `id` (0 if there is none).
    pub fn buffer_len(&self, id: u32) -> u32 {
        match self.buffers.get(id as usize).map(|b| &b.words) {
            Some(Words::W32(w)) => w.len() as u32,
            Some(Words::W64(w)) => w.len() as u32,
            None => 0,
        }
    }

    pub fn buffer_name(&self, id: u32) -> &str {
        self.buffers
            .get(id as usize)
            .map(|b| b.name.as_str())
            .unwrap_or("?")
    }

    /// Names and sizes (bytes) of all buffers.
    pub fn buffer_sizes(&self) -> Vec<(String, u64)> {
        self.buffers
            .iter()
            .map(|b| {
                let bytes = match &b.words {
                    Words::W32(w) => w.len() as u64 * 4,
                    Words::W64(w) => w.len() as u64 * 8,
                };
                (b.name.clone(), bytes)
            })
            .collect()
    }

    fn check<T: Word>(&self, buf: Buf<T>) -> Result<&Buffer, MemoryError> {
        let b = self
            .buffers
            .get(buf.id as usize)
            .ok_or(MemoryError::NoSuchBuffer(buf.id))?;
        if b.ty != T::NAME {
            return Err(MemoryError::WrongType {
                name: b.name.clone(),
                actual: b.ty,
                expected: T::NAME,
            });
        }
        let words = match &b.words {
            Words::W32(w) => w.len(),
            Words::W64(w) => w.len(),
        };
        if words < buf.len as usize {
            return Err(MemoryError::Taken(b.name.clone()));
        }
        Ok(b)
    }

    /// Copies the whole buffer out (host side; not a kernel access).
    pub fn read<T: Word>(&self, buf: Buf<T>) -> Result<Vec<T>, MemoryError> {
        let b = self.check(buf)?;
        Ok(match &b.words {
            Words::W32(w) => w
                .iter()
                .map(|a| T::from_bits(a.load(Ordering::Relaxed) as u64))
                .collect(),
            Words::W64(w) => w
                .iter()
                .map(|a| T::from_bits(a.load(Ordering::Relaxed)))
                .collect(),
        })
    }

    /// Moves a buffer's contents out (host side, after the passes that use it): the same
    /// values as [`Memory::read`] without a copy. The buffer is left empty, so a later
    /// access to it is out of range; the storage it held still counts in [`Memory::bytes`].
    pub fn take<T: Word>(&mut self, buf: Buf<T>) -> Result<Values<T>, MemoryError> {
        self.check(buf)?;
        #[cfg(loom)]
        let values = {
            let v = self.read(buf)?;
            self.buffers[buf.id as usize].words = Words::W32(Values::default());
            Values::from(v)
        };
        #[cfg(not(loom))]
        let values = match std::mem::replace(
            &mut self.buffers[buf.id as usize].words,
            Words::W32(Values::default()),
        ) {
            // Both collects reuse the allocation (same size and alignment) and compile to
            // plain loads: no atomics, no second buffer. The padding comes along.
            Words::W32(w) => Values {
                all: w
                    .all
                    .into_iter()
                    .map(|a| T::from_bits(a.into_inner() as u64))
                    .collect(),
                start: w.start,
            },
            Words::W64(w) => Values {
                all: w
                    .all
                    .into_iter()
                    .map(|a| T::from_bits(a.into_inner()))
                    .collect(),
                start: w.start,
            },
        };
        Ok(values)
    }

    /// One word (host side, no allocation); `None` out of range or on a type mismatch.
    pub fn get<T: Word>(&self, buf: Buf<T>, index: u32) -> Option<T> {
        self.check(buf).ok()?;
        (index < buf.len).then(|| self.word(buf.id, index).load())
    }

    /// Sets one word (host side, no allocation).
    pub fn set<T: Word>(&self, buf: Buf<T>, index: u32, value: T) -> Result<(), MemoryError> {
        self.write(buf, index as u64, std::slice::from_ref(&value))
    }

    /// Writes `data` at `offset` (host side).
    pub fn write<T: Word>(&self, buf: Buf<T>, offset: u64, data: &[T]) -> Result<(), MemoryError> {
        let b = self.check(buf)?;
        if offset + data.len() as u64 > buf.len as u64 {
            return Err(MemoryError::OutOfRange {
                name: b.name.clone(),
                offset,
                len: data.len() as u64,
                words: buf.len,
            });
        }
        for (i, v) in data.iter().enumerate() {
            self.word(buf.id, offset as u32 + i as u32)
                .store(v.to_bits());
        }
        Ok(())
    }

    /// Fills the whole buffer with `value` (host side).
    pub fn fill<T: Word>(&self, buf: Buf<T>, value: T) -> Result<(), MemoryError> {
        self.check(buf)?;
        for i in 0..buf.len {
            self.word(buf.id, i).store(value.to_bits());
        }
        Ok(())
    }

    /// Prefetches of the slots of a per-pixel array (see [`KernelInfo::with_pixel_array`]);
    /// `None` when `array` names no buffer.
    ///
    /// [`KernelInfo::with_pixel_array`]: crate::KernelInfo::with_pixel_array
    pub(crate) fn pixel_prefetcher(
        &self,
        array: PixelArray,
        width: u32,
    ) -> Option<PixelPrefetcher<'_>> {
        let b = self.buffers.get(array.buffer as usize)?;
        let (base, words, word_bytes) = match &b.words {
            Words::W32(w) => (w.as_ptr().cast::<u8>(), w.len(), 4),
            Words::W64(w) => (w.as_ptr().cast::<u8>(), w.len(), 8),
        };
        Some(PixelPrefetcher {
            base,
            words: words as u64,
            word_bytes,
            stride: array.stride as u64,
            width: width as u64,
            _memory: PhantomData,
        })
    }

    /// The word at (buffer, index); the caller has checked bounds.
    #[inline(always)]
    pub(crate) fn word(&self, buffer: u32, index: u32) -> WordRef<'_> {
        match &self.buffers[buffer as usize].words {
            Words::W32(w) => WordRef::W32(&w[index as usize]),
            Words::W64(w) => WordRef::W64(&w[index as usize]),
        }
    }

    /// The words of a buffer of 32-bit words (for [`WordCache`]); a handle of another width
    /// is a foreign one.
    #[inline(always)]
    fn words32(&self, buffer: u32) -> &[AtomicU32] {
        match &self.buffers[buffer as usize].words {
            Words::W32(w) => w,
            Words::W64(_) => foreign_handle(),
        }
    }

    /// [`Self::words32`] for 64-bit words.
    #[inline(always)]
    fn words64(&self, buffer: u32) -> &[AtomicU64] {
        match &self.buffers[buffer as usize].words {
            Words::W64(w) => w,
            Words::W32(_) => foreign_handle(),
        }
    }

    /// The raw bits of the word at a checked address (for the executor: did a step change
    /// memory?).
    pub(crate) fn bits(&self, addr: Addr) -> u64 {
        match self.word(addr.buffer(), addr.index()) {
            WordRef::W32(a) => a.load(Ordering::Relaxed) as u64,
            WordRef::W64(a) => a.load(Ordering::Relaxed),
        }
    }

    /// [`Memory::apply`] for a caller that is the only thread touching this memory (the
    /// scheduled executor): the same result, computed with a plain load and store of the
    /// word instead of a locked read-modify-write.
    #[inline]
    pub(crate) fn apply_exclusive<T: Word>(&self, addr: Addr, op: MemOp) -> u64 {
        match self.word(addr.buffer(), addr.index()) {
            WordRef::W32(a) => {
                let old = a.load(Ordering::Relaxed);
                let (ret, new) = op32::<T>(old, op);
                if let Some(n) = new {
                    a.store(n, Ordering::Relaxed);
                }
                ret as u64
            }
            WordRef::W64(a) => {
                let old = a.load(Ordering::Relaxed);
                let (ret, new) = op64(old, op);
                if let Some(n) = new {
                    a.store(n, Ordering::Relaxed);
                }
                ret
            }
        }
    }

    /// Performs one kernel operation on a checked address; returns the previous value (or
    /// the loaded one) as raw bits. `ordering` is the memory order of the real atomic.
    #[inline(always)]
    pub(crate) fn apply<T: Word>(&self, addr: Addr, op: MemOp, ordering: Ordering) -> u64 {
        // A `Buf<T>` names a buffer of `T`-sized words, so only one arm is reachable for a
        // given `T`: dispatching on `T::WIDE` keeps the other out of every kernel's code.
        let (b, i) = (addr.buffer() as usize, addr.index() as usize);
        match (&self.buffers[b].words, T::WIDE) {
            (Words::W32(w), false) => apply32::<T>(&w[i], op, ordering) as u64,
            (Words::W64(w), true) => apply64(&w[i], op, ordering),
            _ => foreign_handle(),
        }
    }
}

/// The words of the last buffer of each width that a fragment context accessed, for the
/// fused path of the direct executors (kept in [`crate::kernel::DirectState`]).
///
/// [`Memory::apply`] finds a word through the buffer table, the buffer's width tag and its
/// slice: four dependent loads before the operation. On x86 a locked read-modify-write
/// holds back the loads after it, so with one atomic per fragment those loads sat on the
/// critical path of every fragment. Kernels touch few buffers, and the executor keeps this
/// cache in registers across a unit's fragments, so an access is a compare of the buffer id
/// and the operation. A miss finds the words as `apply` does (inline: a kernel that
/// alternates between two buffers pays what it paid before, plus the compare). Buffers are
/// neither added, resized nor replaced during a pass (that takes `&mut Memory`), so a slice
/// found once stays the buffer's.
pub(crate) struct WordCache<'m> {
    w32: Cell<(u32, &'m [AtomicU32])>,
    w64: Cell<(u32, &'m [AtomicU64])>,
}

impl<'m> WordCache<'m> {
    #[inline(always)]
    pub fn new() -> Self {
        // Nothing cached: an id no buffer reaches in practice (were one to, its accesses
        // would index the empty slice and panic, a reported fault, never another buffer).
        WordCache {
            w32: Cell::new((u32::MAX, &[])),
            w64: Cell::new((u32::MAX, &[])),
        }
    }

    /// [`Memory::apply`] through the cache: the same operation on the same word.
    #[inline(always)]
    pub fn apply<T: Word>(
        &self,
        memory: &'m Memory,
        addr: Addr,
        op: MemOp,
        ordering: Ordering,
    ) -> u64 {
        let (b, i) = (addr.buffer(), addr.index() as usize);
        if T::WIDE {
            let (id, mut words) = self.w64.get();
            if id != b {
                words = memory.words64(b);
                self.w64.set((b, words));
            }
            apply64(&words[i], op, ordering)
        } else {
            let (id, mut words) = self.w32.get();
            if id != b {
                words = memory.words32(b);
                self.w32.set((b, words));
            }
            apply32::<T>(&words[i], op, ordering) as u64
        }
    }
}

/// `len` zero 32-bit words, allocated, aligned and zeroed as a new buffer of a
/// [`Memory::with_threads`]`(threads)` is (for measurements that replay a pass's accesses
/// outside the emulator, such as the CLI's `bench --floor`).
pub fn zeroed_u32(len: usize, threads: usize) -> impl std::ops::Deref<Target = [AtomicU32]> {
    zeroed_words::<AtomicU32>(len, threads)
}

/// `len` zero words starting at a multiple of [`BUFFER_ALIGN`] bytes, zeroed by up to
/// `threads` threads.
///
/// One thread: a zero-filled allocation (`calloc`). `malloc` keeps freed blocks of the size
/// of a frame's buffers and hands them back, and `calloc` then zeroes them on the calling
/// thread (1.3-1.7 ms for the 16 MiB of a 2048x2048 `count`, a tenth of the bunny's frame).
/// Large buffers with several threads: an uninitialized allocation zeroed in parts, one per
/// thread, all at once. Either way through `Vec` (an allocation aligned by `Layout` would
/// be mapped afresh at every frame, a page fault per 4 KiB).
#[cfg(not(loom))]
fn zeroed_words<A: ZeroIsValid + Send>(len: usize, threads: usize) -> Values<A> {
    /// Below this a thread costs more than it saves.
    const PER_THREAD_BYTES: usize = 1 << 20;
    let size = std::mem::size_of::<A>();
    // Room to move the start to an aligned address, whatever `malloc` returns.
    let total = len.saturating_add(BUFFER_ALIGN / size);
    let bytes = total.saturating_mul(size);
    let threads = threads.min(bytes / PER_THREAD_BYTES).max(1);
    let all = if threads == 1 {
        // SAFETY: `A` is an atomic integer (`ZeroIsValid` is implemented for `AtomicU32`
        // and `AtomicU64` only), for which all-zero bytes are a valid value (zero).
        let words = unsafe { Box::<[A]>::new_zeroed_slice(total).assume_init() };
        // After `calloc`: memory it got fresh from the OS is still untouched, so the pages
        // faulted in by the pass can be huge ones.
        advise_huge_pages(&words);
        words.into_vec()
    } else {
        let mut words = Box::<[A]>::new_uninit_slice(total);
        // Before zeroing, so that fresh memory is faulted in as huge pages.
        advise_huge_pages(&words);
        let parts: Vec<_> = words.chunks_mut(total.div_ceil(threads)).collect();
        crate::sync::pool::broadcast_each(parts, |part| {
            // SAFETY: `part` is a slice of `MaybeUninit<A>`, valid for writes of its
            // length; any bytes are a valid `MaybeUninit`.
            unsafe { std::ptr::write_bytes(part.as_mut_ptr(), 0, part.len()) };
        });
        // SAFETY: every element was zeroed just above (the parts cover the slice), and
        // all-zero bytes are a valid `A` (see the one-thread case).
        unsafe { words.assume_init() }.into_vec()
    };
    aligned(all, len)
}

/// Asks the OS to back the 2 MiB pages that lie wholly inside `words` with huge pages, for
/// buffers of 4 MiB or more (two huge pages, so that a buffer holds at least one whole one).
///
/// Why: a per-pixel buffer puts each row of a covered run on a page of its own (8 KiB a
/// row at 2048 pixels), so with 4 KiB pages nearly every run needs a new address
/// translation, and the 4096 pages of a 2048x2048 buffer of counters are more than the
/// second-level TLB holds (3072 entries on Zen 4). Measured in `docs/performance.md`
/// ("huge pages").
///
/// Advice only: `madvise(MADV_HUGEPAGE)` changes neither contents nor protections; it
/// marks the range so that pages faulted in from then on may be huge (when the system's
/// `transparent_hugepage` setting is `madvise` or `always`; with `never` it does nothing).
/// Memory the allocator had already faulted in keeps its pages. Failure is ignored: the
/// buffer works the same with small pages.
#[cfg(all(target_os = "linux", not(loom)))]
fn advise_huge_pages<T>(words: &[T]) {
    const HUGE_PAGE: usize = 2 << 20;
    let bytes = std::mem::size_of_val(words);
    if bytes < 2 * HUGE_PAGE {
        return;
    }
    let start = words.as_ptr() as usize;
    let first = start.next_multiple_of(HUGE_PAGE);
    let end = (start + bytes) / HUGE_PAGE * HUGE_PAGE;
    if end > first {
        // SAFETY: `madvise` with `MADV_HUGEPAGE` reads and writes no memory of ours and
        // changes no protection; `[first, end)` is page aligned and inside the allocation
        // of `words`, which outlives the call.
        unsafe { libc::madvise(first as *mut libc::c_void, end - first, libc::MADV_HUGEPAGE) };
    }
}

#[cfg(all(not(target_os = "linux"), not(loom)))]
fn advise_huge_pages<T>(_words: &[T]) {}

/// `all` cut to `len` words from its first one at a multiple of [`BUFFER_ALIGN`] bytes
/// (`all` has room for the padding before it).
#[cfg(not(loom))]
fn aligned<A>(mut all: Vec<A>, len: usize) -> Values<A> {
    // `align_offset` may answer `usize::MAX` ("cannot tell"); the start then stays put,
    // unaligned but correct.
    let start = all.as_ptr().align_offset(BUFFER_ALIGN);
    let start = if start.saturating_add(len) <= all.len() {
        start
    } else {
        0
    };
    all.truncate(start + len);
    Values { all, start }
}

#[cfg(loom)]
fn zeroed_words<A: ZeroIsValid>(len: usize, _threads: usize) -> Values<A> {
    Values {
        all: (0..len).map(|_| A::zero()).collect(),
        start: 0,
    }
}

/// Atomic words whose all-zero bit pattern is the value zero.
trait ZeroIsValid: Sized {
    #[cfg(loom)]
    fn zero() -> Self;
}
impl ZeroIsValid for AtomicU32 {
    #[cfg(loom)]
    fn zero() -> Self {
        AtomicU32::new(0)
    }
}
impl ZeroIsValid for AtomicU64 {
    #[cfg(loom)]
    fn zero() -> Self {
        AtomicU64::new(0)
    }
}

/// A `Buf<T>` whose word size is not its buffer's: a handle made by another device's memory.
#[cold]
#[inline(never)]
fn foreign_handle() -> ! {
    panic!("a buffer handle used with a memory that did not create it")
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
    fn load<T: Word>(&self) -> T {
        T::from_bits(match self {
            WordRef::W32(a) => a.load(Ordering::Relaxed) as u64,
            WordRef::W64(a) => a.load(Ordering::Relaxed),
        })
    }

    fn store(&self, v: u64) {
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
fn apply32<T: Word>(a: &AtomicU32, op: MemOp, ord: Ordering) -> u32 {
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

/// One operation on a 32-bit word holding `old`, as a pure function: (the value returned to
/// the kernel, the new value if the word is written). The semantics of [`apply32`].
#[inline]
fn op32<T: Word>(old: u32, op: MemOp) -> (u32, Option<u32>) {
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
fn op64(old: u64, op: MemOp) -> (u64, Option<u64>) {
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
fn apply64(a: &AtomicU64, op: MemOp, ord: Ordering) -> u64 {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Buffers start at a multiple of `BUFFER_ALIGN` bytes, whatever their size and
    /// however many threads zero them, and `take` hands back exactly their values (the
    /// padding before them hidden).
    #[test]
    fn buffers_are_aligned_and_take_returns_their_values() {
        for threads in [1, 2] {
            let mut m = Memory::with_threads(threads);
            for len in [2u64, 3, 1000, 1 << 20] {
                let a = m.create::<u32>("a", len).unwrap();
                let b = m.create::<u64>("b", len).unwrap();
                for id in [a.id, b.id] {
                    let start = match &m.buffers[id as usize].words {
                        Words::W32(w) => w.as_ptr() as usize,
                        Words::W64(w) => w.as_ptr() as usize,
                    };
                    assert_eq!(start % BUFFER_ALIGN, 0, "len {len}, {threads} threads");
                }
                assert_eq!(m.buffer_len(a.id), len as u32);
                let last = len as u32 - 1;
                m.set(a, 0, 7).unwrap();
                m.set(a, last, 9).unwrap();
                m.set(b, last, u64::MAX).unwrap();
                let read = m.read(a).unwrap();
                let taken = m.take(a).unwrap();
                assert_eq!(taken.len(), len as usize);
                assert_eq!(&taken[..], &read[..]);
                assert_eq!((taken[0], taken[last as usize]), (7, 9));
                assert_eq!(taken.clone().into_vec(), read);
                let b_taken = m.take(b).unwrap();
                assert_eq!(b_taken[last as usize], u64::MAX);
                assert_eq!(b_taken.iter().filter(|&&v| v != 0).count(), 1);
            }
        }
    }

    /// A pixel's slot is word `pixel * stride` of the buffer, for both word widths; a slot
    /// past the end, or a buffer that does not exist, gives no address.
    #[test]
    fn pixel_prefetcher_finds_the_slots() {
        let mut m = Memory::default();
        let a = m.create::<u32>("a", 4 * 3 * 2).unwrap();
        let b = m.create::<u64>("b", 4 * 3).unwrap();
        let width = 4;
        let words = |id: u32| match &m.buffers[id as usize].words {
            Words::W32(w) => w.as_ptr().cast::<u8>(),
            Words::W64(w) => w.as_ptr().cast::<u8>(),
        };
        let pa = m
            .pixel_prefetcher(
                PixelArray {
                    buffer: a.id,
                    stride: 2,
                },
                width,
            )
            .unwrap();
        assert_eq!(pa.slot(1, 2), Some(words(a.id).wrapping_add((9 * 2) * 4)));
        assert_eq!(pa.slot(3, 2), Some(words(a.id).wrapping_add((11 * 2) * 4)));
        assert_eq!(pa.slot(0, 3), None);
        let pb = m
            .pixel_prefetcher(
                PixelArray {
                    buffer: b.id,
                    stride: 1,
                },
                width,
            )
            .unwrap();
        assert_eq!(pb.slot(2, 1), Some(words(b.id).wrapping_add(6 * 8)));
        assert_eq!(pb.slot(0, 3), None);
        let far = m
            .pixel_prefetcher(
                PixelArray {
                    buffer: b.id,
                    stride: u32::MAX,
                },
                u32::MAX,
            )
            .unwrap();
        assert_eq!(far.slot(u32::MAX, u32::MAX), None);
        assert!(m
            .pixel_prefetcher(
                PixelArray {
                    buffer: 2,
                    stride: 1
                },
                width
            )
            .is_none());
    }

    /// `take` moves out what `read` copies, for both word widths, and leaves the buffer
    /// empty; new buffers start at zero.
    #[test]
    fn take_moves_out_what_read_copies() {
        let mut m = Memory::default();
        let a = m.create::<f32>("a", 1000).unwrap();
        let b = m.create::<u64>("b", 3).unwrap();
        assert!(m.read(a).unwrap().iter().all(|&v| v == 0.0));
        for i in 0..1000 {
            m.set(a, i, i as f32 * 0.5 - 7.0).unwrap();
        }
        m.set(b, 2, u64::MAX - 1).unwrap();
        let (ra, rb) = (m.read(a).unwrap(), m.read(b).unwrap());
        assert_eq!(m.take(a).unwrap(), ra);
        assert_eq!(m.take(b).unwrap(), rb);
        assert_eq!(rb, vec![0, 0, u64::MAX - 1]);
        assert_eq!(m.read(a), Err(MemoryError::Taken("a".into())));
        assert_eq!(m.get(a, 0), None);
        assert!(m.take(a).is_err());
    }

    /// Through a [`WordCache`], accesses that alternate between buffers of both widths reach
    /// the words they name: the same results and final contents as [`Memory::apply`] on a
    /// twin memory.
    #[test]
    fn word_cache_follows_the_buffer_named() {
        let build = || {
            let mut m = Memory::default();
            let a = m.create::<u32>("a", 5).unwrap();
            let w = m.create::<u64>("w", 3).unwrap();
            let b = m.create::<i32>("b", 4).unwrap();
            let v = m.create::<u64>("v", 2).unwrap();
            (m, a, w, b, v)
        };
        let (cached, a, w, b, v) = build();
        let (plain, ..) = build();
        let cache = WordCache::new();
        let ord = Ordering::AcqRel;
        // Buffer ids, in an order that misses the cache at every change of buffer.
        let steps: [(u32, u32, bool); 10] = [
            (a.id, 1, false),
            (b.id, 1, false),
            (a.id, 1, false),
            (w.id, 2, true),
            (v.id, 0, true),
            (w.id, 2, true),
            (a.id, 4, false),
            (a.id, 4, false),
            (b.id, 3, false),
            (v.id, 1, true),
        ];
        for (k, &(id, index, wide)) in steps.iter().enumerate() {
            let addr = Addr::new(id, index);
            let op = MemOp::Add(k as u64 + 1);
            let (got, want) = if wide {
                (
                    cache.apply::<u64>(&cached, addr, op, ord),
                    plain.apply::<u64>(addr, op, ord),
                )
            } else {
                (
                    cache.apply::<u32>(&cached, addr, op, ord),
                    plain.apply::<u32>(addr, op, ord),
                )
            };
            assert_eq!(got, want, "step {k}: the value before the add");
        }
        assert_eq!(cached.read(a).unwrap(), plain.read(a).unwrap());
        assert_eq!(cached.read(b).unwrap(), plain.read(b).unwrap());
        assert_eq!(cached.read(w).unwrap(), plain.read(w).unwrap());
        assert_eq!(cached.read(v).unwrap(), plain.read(v).unwrap());
        // The adds landed where they were aimed: a[4] took steps 6 and 7 (7 + 8).
        assert_eq!(cached.read(a).unwrap()[4], 15);
        assert_eq!(cached.read(v).unwrap(), vec![5, 10]);
    }

    /// Every operation on every word type returns the same value and leaves the same word
    /// through the locked path and the exclusive (scheduled executor) path.
    fn same<T: Word>(values: &[T]) {
        let ops = |v: u64, w: u64| {
            [
                MemOp::Load,
                MemOp::Store(v),
                MemOp::AtomicLoad,
                MemOp::AtomicStore(v),
                MemOp::Add(v),
                MemOp::Sub(v),
                MemOp::Min(v),
                MemOp::Max(v),
                MemOp::And(v),
                MemOp::Or(v),
                MemOp::Xor(v),
                MemOp::Exchange(v),
                MemOp::CompareExchange(v, w),
                MemOp::CompareExchange(w, v),
            ]
        };
        for &a in values {
            for &b in values {
                for op in ops(b.to_bits(), a.to_bits()) {
                    let mut m = Memory::new();
                    let x = m.create::<T>("x", 1).unwrap();
                    let y = m.create::<T>("y", 1).unwrap();
                    m.write(x, 0, &[a]).unwrap();
                    m.write(y, 0, &[a]).unwrap();
                    let r1 = m.apply::<T>(Addr::new(x.id, 0), op, Ordering::AcqRel);
                    let r2 = m.apply_exclusive::<T>(Addr::new(y.id, 0), op);
                    assert_eq!(r1, r2, "{a:?} {op:?}: returned");
                    let (w1, w2) = (m.get(x, 0).unwrap(), m.get(y, 0).unwrap());
                    assert_eq!(w1.to_bits(), w2.to_bits(), "{a:?} {op:?}: stored");
                }
            }
        }
    }

    #[test]
    fn the_exclusive_path_computes_what_the_atomics_do() {
        same::<u32>(&[0, 1, 7, 0x8000_0000, u32::MAX]);
        same::<i32>(&[0, 1, -1, -7, i32::MIN, i32::MAX]);
        same::<f32>(&[0.0, -0.0, 1.5, -2.25, f32::INFINITY, f32::MIN, f32::NAN]);
        same::<u64>(&[0, 1, 1 << 40, u64::MAX]);
    }
}
