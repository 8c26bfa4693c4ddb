//! Buffer contents: aligned, zeroed allocations of atomic words ([`Values`]), zeroed by
//! several threads at once for large buffers, backed by huge pages where the OS allows.

// Under loom the buffers are not aligned by hand (loom's atomics are not plain words).
#[cfg(not(loom))]
use super::recycle::Recyclable;
#[cfg(not(loom))]
use super::BUFFER_ALIGN;
use crate::sync::{AtomicU32, AtomicU64};

/// A buffer's contents: a `Vec` a little longer than the buffer, whose first `start`
/// elements are padding that puts the first word at a multiple of [`BUFFER_ALIGN`] bytes.
/// Derefs to the words, the padding hidden. `Memory` keeps its buffers' atomic words so
/// (allocated, reused and freed as any `Vec`), and [`Memory::take`] hands them to the host
/// as plain values in the same allocation, without a copy.
#[derive(Clone)]
pub struct Values<T> {
    pub(super) all: Vec<T>,
    pub(super) start: usize,
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
///
/// A large buffer takes, when one fits, the allocation of a buffer of an earlier device
/// ([`super::recycle`]), zeroed the same way (in parts when there are several threads): no
/// page faults for memory the process already has.
#[cfg(not(loom))]
pub(super) fn zeroed_words<A: ZeroIsValid + Recyclable + Send>(
    len: usize,
    threads: usize,
) -> Values<A> {
    filled_words(len, threads, 0)
}

/// [`zeroed_words`] with every word `bits` instead of zero (its low 32 bits for 32-bit
/// words): a buffer that starts at another value is written once, not zeroed and then
/// filled (`ll`'s list heads, `EMPTY`, 16 MiB at 2048x2048).
#[cfg(not(loom))]
pub(super) fn filled_words<A: ZeroIsValid + Recyclable + Send>(
    len: usize,
    threads: usize,
    bits: u64,
) -> Values<A> {
    /// Below this a thread costs more than it saves.
    const PER_THREAD_BYTES: usize = 1 << 20;
    let size = std::mem::size_of::<A>();
    // Room to move the start to an aligned address, whatever `malloc` returns.
    let total = len.saturating_add(BUFFER_ALIGN / size);
    let bytes = total.saturating_mul(size);
    let threads = threads.min(bytes / PER_THREAD_BYTES).max(1);
    if let Some(mut all) = A::recycled().take(total) {
        let spare = &mut all.spare_capacity_mut()[..total];
        let parts: Vec<_> = spare.chunks_mut(total.div_ceil(threads)).collect();
        crate::sync::pool::broadcast_each(parts, |part| fill_uninit(part, bits));
        // SAFETY: the first `total` elements (within the capacity, `take` checked it) were
        // initialized just above (`fill_uninit` writes every element of its part).
        unsafe { all.set_len(total) };
        return aligned(all, len);
    }
    let all = if threads == 1 && bits != 0 {
        let mut words = Box::<[A]>::new_uninit_slice(total);
        advise_huge_pages(&words);
        fill_uninit(&mut words, bits);
        // SAFETY: `fill_uninit` initialized every element.
        unsafe { words.assume_init() }.into_vec()
    } else if threads == 1 {
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
        crate::sync::pool::broadcast_each(parts, |part| fill_uninit(part, bits));
        // SAFETY: every element was initialized just above (the parts cover the slice).
        unsafe { words.assume_init() }.into_vec()
    };
    aligned(all, len)
}

/// Writes the word `bits` to every element of `part`: by bytes when all of the word's
/// bytes are equal (zero, `u32::MAX`: one `memset`), else word by word.
#[cfg(not(loom))]
fn fill_uninit<A: ZeroIsValid>(part: &mut [std::mem::MaybeUninit<A>], bits: u64) {
    match A::repeated_byte(bits) {
        // SAFETY: `part` is a slice of `MaybeUninit<A>`, valid for writes of its length; `A`
        // is an atomic integer (`ZeroIsValid` is implemented for `AtomicU32` and
        // `AtomicU64` only), for which every bit pattern is a valid value, here `bits`'s
        // own (all of its bytes are `byte`).
        Some(byte) => unsafe { std::ptr::write_bytes(part.as_mut_ptr(), byte, part.len()) },
        None => {
            for w in part {
                w.write(A::of_bits(bits));
            }
        }
    }
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
pub(super) fn zeroed_words<A: ZeroIsValid>(len: usize, threads: usize) -> Values<A> {
    filled_words(len, threads, 0)
}

#[cfg(loom)]
pub(super) fn filled_words<A: ZeroIsValid>(len: usize, _threads: usize, bits: u64) -> Values<A> {
    Values {
        all: (0..len).map(|_| A::of_bits(bits)).collect(),
        start: 0,
    }
}

/// Atomic words whose all-zero bit pattern is the value zero (and every bit pattern a
/// value).
pub(super) trait ZeroIsValid: Sized {
    /// The word holding `bits` (the low 32 bits for a 32-bit word).
    fn of_bits(bits: u64) -> Self;
    /// The byte every byte of the word `bits` is, if they are all one.
    #[cfg_attr(loom, allow(dead_code, reason = "loom's words are built one by one"))]
    fn repeated_byte(bits: u64) -> Option<u8>;
}
impl ZeroIsValid for AtomicU32 {
    fn of_bits(bits: u64) -> Self {
        AtomicU32::new(bits as u32)
    }
    fn repeated_byte(bits: u64) -> Option<u8> {
        let b = (bits as u32).to_le_bytes();
        b.iter().all(|&x| x == b[0]).then_some(b[0])
    }
}
impl ZeroIsValid for AtomicU64 {
    fn of_bits(bits: u64) -> Self {
        AtomicU64::new(bits)
    }
    fn repeated_byte(bits: u64) -> Option<u8> {
        let b = bits.to_le_bytes();
        b.iter().all(|&x| x == b[0]).then_some(b[0])
    }
}
