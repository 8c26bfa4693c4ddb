//! Shared memory: storage buffers of 32-bit words (u32, i32, f32) and 64-bit words (u64),
//! addressed through typed handles, accessed by kernels only through [`crate::Frag`].
//!
//! Every word is an atomic from [`crate::sync`]: a kernel's *plain* load or store is a
//! relaxed atomic access (racy, as on a GPU, but never undefined behaviour) and its atomics
//! are real read-modify-write instructions. This module knows nothing of invocations,
//! schedules or hazards: it checks bounds and performs operations.
//!
//! Files: this one (the device's buffers and their host-side access), `word` (word types,
//! handles, addresses, per-pixel arrays), `ops` (the operations and their semantics),
//! `values` (allocation, alignment and zeroing of buffer contents), `recycle` (large
//! buffers' allocations kept from device to device), `cache` (the fused path's word cache
//! and per-pixel prefetches).

mod cache;
mod ops;
#[cfg(not(loom))]
mod recycle;
mod values;
mod word;

pub(crate) use cache::{PixelPrefetcher, WordCache};
pub use ops::{f32_order_key, OpKind};
pub(crate) use ops::{MemOp, WordRef};
pub use values::{zeroed_u32, Values};
pub use word::{Addr, BlockArray, Buf, PixelArray, Word, WordKind};

use crate::sync::{AtomicU32, AtomicU64, Ordering};
use ops::{apply32, apply64, op32, op64};
use values::filled_words;

/// Largest buffer, in words (4 GiB of 32-bit words would not be addressable by u32 indices).
pub const MAX_BUFFER_WORDS: u64 = 1 << 31;
/// Largest total storage of a device, in bytes.
pub const MAX_TOTAL_BYTES: u64 = 16 << 30;

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

/// Runs `store` on every word of `words`, split among up to `threads` threads when the
/// buffer is large (the worker pool is std's: under loom, one thread).
fn fill_parts<A: Sync>(words: &[A], threads: usize, store: impl Fn(&A) + Sync) {
    /// Below this many words a thread costs more than it saves.
    const MIN_PART: usize = 1 << 18;
    #[cfg(not(loom))]
    crate::sync::pool::map_parts(words, threads, MIN_PART, |part| {
        part.iter().for_each(&store)
    });
    #[cfg(loom)]
    {
        let _ = (threads, MIN_PART);
        words.iter().for_each(store);
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

/// A device's large buffers leave their allocations for later devices (see `recycle`).
#[cfg(not(loom))]
impl Drop for Memory {
    fn drop(&mut self) {
        use recycle::Recyclable;
        for b in self.buffers.drain(..) {
            match b.words {
                Words::W32(w) => AtomicU32::recycled().give(w.all),
                Words::W64(w) => AtomicU64::recycled().give(w.all),
            }
        }
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
            buffers: Vec::new(),
            bytes: 0,
            clear_threads: threads,
        }
    }

    /// Creates a zero-filled buffer of `len` words of `T`.
    pub fn create<T: Word>(&mut self, name: &str, len: u64) -> Result<Buf<T>, MemoryError> {
        self.create_filled(name, len, T::from_bits(0))
    }

    /// Creates a buffer of `len` words of `T`, each `value`: what [`Memory::create`] then
    /// [`Memory::fill`] leave, written once.
    pub fn create_filled<T: Word>(
        &mut self,
        name: &str,
        len: u64,
        value: T,
    ) -> Result<Buf<T>, MemoryError> {
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
        let (threads, bits) = (self.clear_threads, value.to_bits());
        let words = if T::WIDE {
            Words::W64(filled_words(len as usize, threads, bits))
        } else {
            Words::W32(filled_words(len as usize, threads, bits))
        };
        self.bytes += bytes;
        let id = self.buffers.len() as u32;
        self.buffers.push(Buffer {
            name: name.into(),
            ty: T::NAME,
            words,
        });
        Ok(Buf::new(id, len as u32))
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

    #[inline]
    fn check<T: Word>(&self, buf: Buf<T>) -> Result<&Buffer, MemoryError> {
        let b = self
            .buffers
            .get(buf.id as usize)
            .ok_or(MemoryError::NoSuchBuffer(buf.id))?;
        // (The names are static strings: the same pointer is the same type, without the
        // string comparison every host-side `get` and `set` made.)
        if !std::ptr::eq(b.ty, T::NAME) && b.ty != T::NAME {
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
    #[inline]
    pub fn set<T: Word>(&self, buf: Buf<T>, index: u32, value: T) -> Result<(), MemoryError> {
        let b = self.check(buf)?;
        if index >= buf.len {
            // (As `write` reports it.)
            return Err(MemoryError::OutOfRange {
                name: b.name.clone(),
                offset: index as u64,
                len: 1,
                words: buf.len,
            });
        }
        self.word(buf.id, index).store(value.to_bits());
        Ok(())
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

    /// Fills the whole buffer with `value` (host side): a large buffer by several threads
    /// at once, as new buffers are zeroed ([`Memory::with_threads`]).
    pub fn fill<T: Word>(&self, buf: Buf<T>, value: T) -> Result<(), MemoryError> {
        let b = self.check(buf)?;
        let (len, bits, threads) = (buf.len as usize, value.to_bits(), self.clear_threads);
        match &b.words {
            Words::W32(w) => fill_parts(&w[..len], threads, |a| {
                a.store(bits as u32, Ordering::Relaxed)
            }),
            Words::W64(w) => fill_parts(&w[..len], threads, |a| a.store(bits, Ordering::Relaxed)),
        }
        Ok(())
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

    /// The 32-bit words of buffer `id`; empty when it holds 64-bit words or no buffer has
    /// that id ([`WordCache`]'s table).
    pub(crate) fn words32_if_any(&self, id: usize) -> &[AtomicU32] {
        match self.buffers.get(id).map(|b| &b.words) {
            Some(Words::W32(w)) => w,
            _ => &[],
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

/// A `Buf<T>` whose word size is not its buffer's: a handle made by another device's memory.
#[cold]
#[inline(never)]
fn foreign_handle() -> ! {
    panic!("a buffer handle used with a memory that did not create it")
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

    /// Through a [`WordCache`], accesses that alternate between buffers of both widths, in
    /// its table and past it, reach the words they name: the same results and final
    /// contents as [`Memory::apply`] on a twin memory.
    #[test]
    fn word_cache_follows_the_buffer_named() {
        let build = || {
            let mut m = Memory::default();
            let a = m.create::<u32>("a", 5).unwrap();
            let w = m.create::<u64>("w", 3).unwrap();
            // Ids past the cache's table: `b` and `v` are found through the memory.
            for i in 0..40 {
                m.create::<u32>(&format!("filler {i}"), 1).unwrap();
            }
            let b = m.create::<i32>("b", 4).unwrap();
            let v = m.create::<u64>("v", 2).unwrap();
            (m, a, w, b, v)
        };
        let (cached, a, w, b, v) = build();
        let (plain, ..) = build();
        let cache = WordCache::new(&cached);
        let ord = Ordering::AcqRel;
        // Buffer ids, in an order that changes buffer at almost every step.
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
