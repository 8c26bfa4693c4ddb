//! A process-wide pool of the rasterizer's large buffers, reused from frame to frame.
//!
//! Why: binning a dense mesh touches tens of megabytes (projected vertices, setup records, bin
//! lists). Fresh memory costs a page fault per 4 KiB page, a few microseconds each in a VM,
//! which measured at more than half of the whole setup time of the 871K-triangle dragon.
//! `malloc` does not reliably keep such blocks (large blocks are unmapped or trimmed on free),
//! so the rasterizer keeps them itself: [`super::Binned`] hands its buffers back here when
//! dropped, and the next [`super::bin_triangles`] takes them. At most [`MAX_PER_KIND`] buffers
//! of each kind are kept (the memory of the largest recent frames stays allocated).
//!
//! Plain `std` mutex, not [`crate::sync`]: this is bookkeeping outside the modelled protocols.
use std::sync::Mutex;

/// Buffers kept per kind: enough for a couple of concurrent binnings with a chunk per thread,
/// few enough to bound the memory kept (a few frames' worth).
const MAX_PER_KIND: usize = 8;

/// A stack of spare buffers of one element type.
pub(crate) struct Pool<T> {
    free: Mutex<Vec<Vec<T>>>,
}

impl<T> Pool<T> {
    pub const fn new() -> Pool<T> {
        Pool {
            free: Mutex::new(Vec::new()),
        }
    }

    /// A buffer with the capacity of a previously returned one when available: empty, or with
    /// stale contents if it was returned by [`Pool::give_dirty`].
    pub fn take(&self) -> Vec<T> {
        let mut free = self.free.lock().unwrap_or_else(|e| e.into_inner());
        free.pop().unwrap_or_default()
    }

    /// Returns a buffer for reuse (dropped if the pool is full or it never allocated).
    pub fn give(&self, mut v: Vec<T>) {
        v.clear();
        self.give_dirty(v);
    }

    /// Returns a buffer for reuse *with* its contents, for buffers whose next user overwrites
    /// every element it reads (then `resize` writes only the part beyond the old length,
    /// instead of clearing megabytes that are about to be overwritten anyway).
    pub fn give_dirty(&self, v: Vec<T>) {
        if v.capacity() == 0 {
            return;
        }
        let mut free = self.free.lock().unwrap_or_else(|e| e.into_inner());
        if free.len() < MAX_PER_KIND {
            free.push(v);
        }
    }
}
