//! What the fused path keeps to reach words fast: the words of the last buffers accessed
//! ([`WordCache`]) and the addresses of the slots of a per-pixel array ([`PixelPrefetcher`]).

use std::cell::Cell;
use std::marker::PhantomData;

use super::ops::{apply32, apply32_owned, apply64, apply64_owned, MemOp};
use super::word::{Addr, PixelArray, Word};
use super::{Memory, Words};
use crate::sync::{AtomicU32, AtomicU64, Ordering};

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

/// The words of the buffers a fragment context accesses, for the fused path of the direct
/// executors (kept in `crate::invocation::DirectState`).
///
/// [`Memory::apply`] finds a word through the buffer table, the buffer's width tag and its
/// slice: four dependent loads before the operation. On x86 a locked read-modify-write
/// holds back the loads after it, so with one atomic per fragment those loads sat on the
/// critical path of every fragment. Here the slices of the 32-bit buffers are found once,
/// when the state is made, for the first [`TABLE`] buffer ids (a device numbers its buffers
/// in the order it creates them, and a kernel's are few): an access loads its buffer's
/// slice by id, with no compare against a cached id and nothing written back. Buffers are
/// neither added, resized nor replaced during a pass (that takes `&mut Memory`), so a slice
/// found once stays the buffer's. A buffer past the table, or not of 32-bit words, is found
/// through the memory (which reports a handle of another memory as `apply` does); 64-bit
/// buffers, rarer, keep a one-entry cache.
pub(crate) struct WordCache<'m> {
    /// The 32-bit words of buffer `id`, for `id < TABLE`; empty for a buffer of 64-bit
    /// words or an id no buffer has.
    w32: [&'m [AtomicU32]; TABLE],
    w64: Cell<(u32, &'m [AtomicU64])>,
}

/// Buffer ids whose 32-bit words [`WordCache`] holds.
const TABLE: usize = 32;

/// Bytes of a cache line (x86-64, and most others), the step of [`WordCache::prefetch32`].
const LINE: usize = 64;

impl<'m> WordCache<'m> {
    /// The table of `memory`'s buffers.
    #[inline]
    pub fn new(memory: &'m Memory) -> Self {
        WordCache {
            w32: std::array::from_fn(|id| memory.words32_if_any(id)),
            // Nothing cached: an id no buffer reaches in practice (were one to, its accesses
            // would index the empty slice and panic, a reported fault, never another buffer).
            w64: Cell::new((u32::MAX, &[])),
        }
    }

    /// The 64-bit words of buffer `b`: the cached slice, or the buffer's (then cached).
    #[inline(always)]
    fn words64(&self, memory: &'m Memory, b: u32) -> &'m [AtomicU64] {
        let (id, mut words) = self.w64.get();
        if id != b {
            words = memory.words64(b);
            self.w64.set((b, words));
        }
        words
    }

    /// The 32-bit words of buffer `b`: from the table, or the buffer's.
    #[inline(always)]
    fn words32(&self, memory: &'m Memory, b: u32) -> &'m [AtomicU32] {
        match self.w32.get(b as usize) {
            Some(words) if !words.is_empty() => words,
            _ => memory.words32(b),
        }
    }

    /// Requests the cache lines of the words `words` of the 32-bit buffer `b`, cut to the
    /// buffer's end; nothing for a buffer past the table (the hint of
    /// [`crate::Fragment::prefetch`]).
    #[inline]
    pub fn prefetch32(&self, b: u32, words: std::ops::Range<u32>) {
        let Some(all) = self.w32.get(b as usize) else {
            return;
        };
        let end = (words.end as usize).min(all.len());
        let start = words.start as usize;
        if start >= end {
            return;
        }
        // One hint a 64-byte line, from the line of the range's first word to the line of
        // its last.
        let range = &all[start..end];
        let first = range.as_ptr().cast::<u8>();
        let offset = first as usize % LINE;
        let line = first.wrapping_sub(offset);
        for at in (0..offset + std::mem::size_of_val(range)).step_by(LINE) {
            crate::hint::prefetch(line.wrapping_add(at));
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
            apply64(&self.words64(memory, b)[i], op, ordering)
        } else {
            apply32::<T>(&self.words32(memory, b)[i], op, ordering) as u64
        }
    }

    /// [`WordCache::apply`] on a word only this thread accesses during the pass (an own
    /// pixel's slot in an owned tile): the operation as a plain load and store.
    #[inline(always)]
    pub fn apply_owned<T: Word>(&self, memory: &'m Memory, addr: Addr, op: MemOp) -> u64 {
        let (b, i) = (addr.buffer(), addr.index() as usize);
        if T::WIDE {
            apply64_owned(&self.words64(memory, b)[i], op)
        } else {
            apply32_owned::<T>(&self.words32(memory, b)[i], op) as u64
        }
    }

    /// Plain loads of the words `base..base + out.len()` of buffer `b` (in bounds: the
    /// caller checked, [`crate::invocation`]'s record fast path), the buffer's slice found
    /// once for the record: what `out.len()` calls of [`WordCache::apply`] with
    /// [`MemOp::Load`] return.
    #[inline(always)]
    pub fn load_record<T: Word>(&self, memory: &'m Memory, b: u32, base: u32, out: &mut [T]) {
        let base = base as usize;
        if T::WIDE {
            let words = &self.words64(memory, b)[base..base + out.len()];
            for (o, w) in out.iter_mut().zip(words) {
                *o = T::from_bits(w.load(Ordering::Relaxed));
            }
        } else {
            let words = &self.words32(memory, b)[base..base + out.len()];
            for (o, w) in out.iter_mut().zip(words) {
                *o = T::from_bits(u64::from(w.load(Ordering::Relaxed)));
            }
        }
    }

    /// Plain stores of `values` to the words `base..base + values.len()` of buffer `b` (in
    /// bounds, as for [`WordCache::load_record`]): what `values.len()` calls of
    /// [`WordCache::apply`] with [`MemOp::Store`] write.
    #[inline(always)]
    pub fn store_record<T: Word>(&self, memory: &'m Memory, b: u32, base: u32, values: &[T]) {
        let base = base as usize;
        if T::WIDE {
            let words = &self.words64(memory, b)[base..base + values.len()];
            for (v, w) in values.iter().zip(words) {
                w.store(v.to_bits(), Ordering::Relaxed);
            }
        } else {
            let words = &self.words32(memory, b)[base..base + values.len()];
            for (v, w) in values.iter().zip(words) {
                w.store(v.to_bits() as u32, Ordering::Relaxed);
            }
        }
    }
}

impl Memory {
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
}
