//! The allocations of large buffers, kept from device to device ([`Recycled`]).
//!
//! Why: a frame of an OIT algorithm runs on a fresh device whose buffers are tens of
//! megabytes (the bunny's `ll` at 2048x2048: 16 MiB of counts, 16 MiB of list heads, 43 MiB
//! of nodes). Freed, such blocks go back to the OS (`malloc` unmaps blocks above its mmap
//! threshold, at most 32 MiB, and trims the top of its heap), so the next frame faulted its
//! buffers in again: a page fault per 4 KiB page, whose zeroing by the kernel came on top of
//! the buffer's own (docs/performance.md, "2026-11-27, evening"). A renderer keeps its
//! buffers from frame to frame and clears them (the llvmpipe peer clears and reuses one node
//! pool); a device does the same through this pool: a dropped `Memory` hands the
//! allocations of its large buffers here, and a new buffer takes one that fits, zeroed again
//! as a new buffer is (`values::zeroed_words`). Contents never carry over.
//!
//! Plain `std` mutex, not [`crate::sync`]: bookkeeping outside the modelled protocols (as
//! the rasterizer's `raster::pool`).

use std::sync::Mutex;

use crate::sync::{AtomicU32, AtomicU64};

/// Smallest allocation kept: below it `malloc` keeps freed blocks itself.
const MIN_BYTES: usize = 1 << 20;
/// Most allocations kept per word width.
const MAX_KEPT: usize = 16;
/// Most bytes kept per word width (the largest recent frames' buffers).
const MAX_KEPT_BYTES: usize = 1 << 30;

/// Spare allocations of one word type, each empty (length 0) with its capacity.
pub(super) struct Recycled<A> {
    free: Mutex<Vec<Vec<A>>>,
}

impl<A> Recycled<A> {
    const fn new() -> Self {
        Recycled {
            free: Mutex::new(Vec::new()),
        }
    }

    /// An empty allocation with room for `total` words and at most twice that (a small
    /// buffer does not hold a large block), the smallest such; `None` if none is kept.
    pub(super) fn take(&self, total: usize) -> Option<Vec<A>> {
        if total.saturating_mul(std::mem::size_of::<A>()) < MIN_BYTES {
            return None;
        }
        let mut free = self.free.lock().unwrap_or_else(|e| e.into_inner());
        let best = free
            .iter()
            .enumerate()
            .filter(|(_, v)| v.capacity() >= total && v.capacity() / 2 <= total)
            .min_by_key(|(_, v)| v.capacity())
            .map(|(i, _)| i)?;
        Some(free.swap_remove(best))
    }

    /// Keeps `v`'s allocation for a later buffer (its contents are dropped): if it is large
    /// enough to be worth it and the pool has room; otherwise it is freed.
    pub(super) fn give(&self, mut v: Vec<A>) {
        let bytes = v.capacity().saturating_mul(std::mem::size_of::<A>());
        if bytes < MIN_BYTES {
            return;
        }
        v.clear();
        let mut free = self.free.lock().unwrap_or_else(|e| e.into_inner());
        let size = std::mem::size_of::<A>();
        let kept: usize = free.iter().map(|k| k.capacity() * size).sum();
        if free.len() < MAX_KEPT && kept + bytes <= MAX_KEPT_BYTES {
            free.push(v);
        }
    }
}

/// Atomic words whose allocations are kept here.
pub(super) trait Recyclable: Sized + 'static {
    /// The pool of this word type.
    fn recycled() -> &'static Recycled<Self>;
}

static W32: Recycled<AtomicU32> = Recycled::new();
static W64: Recycled<AtomicU64> = Recycled::new();

impl Recyclable for AtomicU32 {
    fn recycled() -> &'static Recycled<Self> {
        &W32
    }
}

impl Recyclable for AtomicU64 {
    fn recycled() -> &'static Recycled<Self> {
        &W64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn takes_the_smallest_fitting_allocation_and_never_a_much_larger_one() {
        let pool: Recycled<u32> = Recycled::new();
        let words = MIN_BYTES / 4;
        pool.give(Vec::with_capacity(words * 3));
        pool.give(Vec::with_capacity(words * 5));
        pool.give(Vec::with_capacity(16)); // too small to keep
        assert_eq!(pool.free.lock().unwrap().len(), 2);
        // Too small a request: not served from the pool.
        assert!(pool.take(16).is_none());
        // 5x is more than twice 2x: only the 3x allocation fits.
        let v = pool.take(words * 2).expect("the 3x allocation");
        assert!(v.capacity() >= words * 3 && v.is_empty());
        assert!(pool.take(words * 2).is_none());
        let v = pool.take(words * 4).expect("the 5x allocation");
        assert!(v.capacity() >= words * 5);
    }
}
