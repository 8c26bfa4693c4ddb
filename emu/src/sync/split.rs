//! Indices `0..n` handed out to `t` threads, each index exactly once: the range split into
//! `t` contiguous parts, one per thread, which its thread takes from the front; a thread
//! whose part is empty takes from the back of the part with the most left.
//!
//! Why not one shared counter: work items next to each other in submission order touch
//! memory next to each other (tiles side by side in a row of tiles, chunks of a mesh's
//! triangles over one region of the screen). Two threads taking consecutive items from one
//! counter work side by side, and even when they never touch one cache line, each core's
//! prefetchers fetch the lines of the other's next item, and the other's locked adds wait
//! to get them back: one locked add per pixel of 64x64 tiles of a 2048x2048 buffer took as
//! long on two threads as on one with a shared counter, and 1.7-1.9x less with a part
//! each (`ci/c/tile_neighbours.c`); `bench --floor` on the bunny at 2048x2048 went from
//! 3.7-3.9 to 2.7-2.9 ms on two threads, and `count` binned into tiles from 7.8 to 7.0 ms
//! (docs/performance.md, "2026-11-27, night"). With a part each, the threads work on items
//! far apart in submission order, and meet only at the end, when one steals the other's
//! last items. Fragments of one pixel can still run at the same time on two threads (two
//! parts may cover the same pixels, and stolen items run beside their part's owner): the
//! order of work is one a GPU could produce, as with one counter.

use super::{AtomicU64, CachePadded, Ordering};

/// The parts: `(front, end)` of each, packed in one word so that the owner's take from
/// the front and a thief's take from the back never hand out the same index.
pub struct SplitRange {
    parts: Box<[Part]>,
}

/// One part's `front << 32 | end`, on its own cache line (the owner updates it at every
/// take; two parts on one line would be the contention this type avoids).
type Part = CachePadded<AtomicU64>;

#[inline]
fn pack(front: u32, end: u32) -> u64 {
    (u64::from(front) << 32) | u64::from(end)
}

#[inline]
fn unpack(v: u64) -> (u32, u32) {
    ((v >> 32) as u32, v as u32)
}

impl SplitRange {
    /// `0..n` in `threads` parts of (nearly) equal length (at least one part).
    ///
    /// # Panics
    /// If `n` does not fit in a `u32` (the callers hand out chunks of triangles or tiles).
    pub fn new(n: usize, threads: usize) -> SplitRange {
        let n = u32::try_from(n).expect("at most u32::MAX work items");
        let t = threads.max(1) as u64;
        let parts = (0..t)
            .map(|i| {
                // Part i is [n * i / t, n * (i + 1) / t): the lengths differ by at most one.
                let front = (u64::from(n) * i / t) as u32;
                let end = (u64::from(n) * (i + 1) / t) as u32;
                CachePadded::new(AtomicU64::new(pack(front, end)))
            })
            .collect();
        SplitRange { parts }
    }

    /// The next index for thread `me` (its part's front, or else the back of the part
    /// with the most left); `None` once every index has been taken.
    pub fn next(&self, me: usize) -> Option<usize> {
        if let Some(own) = self.parts.get(me) {
            if let Some(i) = take(own, Side::Front) {
                return Some(i as usize);
            }
        }
        loop {
            // The part with the most left; none: all taken (parts only shrink).
            let victim = self
                .parts
                .iter()
                .map(|p| {
                    let (front, end) = unpack(p.load(Ordering::Relaxed));
                    (end.saturating_sub(front), p)
                })
                .filter(|&(left, _)| left > 0)
                .max_by_key(|&(left, _)| left)?
                .1;
            if let Some(i) = take(victim, Side::Back) {
                return Some(i as usize);
            }
            // Emptied meanwhile: look again.
        }
    }
}

#[derive(Clone, Copy)]
enum Side {
    Front,
    Back,
}

/// Takes one index from `side` of the part in `word`; `None` if it is empty.
#[inline]
fn take(word: &AtomicU64, side: Side) -> Option<u32> {
    let mut v = word.load(Ordering::Relaxed);
    loop {
        let (front, end) = unpack(v);
        if front >= end {
            return None;
        }
        let (taken, next) = match side {
            Side::Front => (front, pack(front + 1, end)),
            Side::Back => (end - 1, pack(front, end - 1)),
        };
        // Relaxed: the index is all that is handed over (the items' data was published
        // before the threads started).
        match word.compare_exchange_weak(v, next, Ordering::Relaxed, Ordering::Relaxed) {
            Ok(_) => return Some(taken),
            Err(now) => v = now,
        }
    }
}

#[cfg(all(test, not(loom)))]
mod tests {
    use super::*;

    #[test]
    fn one_thread_takes_every_index_in_order() {
        for n in [0, 1, 7, 100] {
            for parts in [1, 3] {
                let r = SplitRange::new(n, parts);
                let got: Vec<usize> = std::iter::from_fn(|| r.next(0)).collect();
                // Its own part in order, then the others from the back of the longest.
                let mut sorted = got.clone();
                sorted.sort_unstable();
                assert_eq!(sorted, (0..n).collect::<Vec<_>>(), "n {n} parts {parts}");
                let own = n / parts;
                assert_eq!(&got[..own], &(0..own).collect::<Vec<_>>()[..]);
            }
        }
    }

    #[test]
    fn threads_start_far_apart_and_share_every_index_once() {
        let n = 10_000;
        let threads = 4;
        let r = SplitRange::new(n, threads);
        let taken: Vec<Vec<usize>> =
            crate::sync::pool::broadcast(threads, |me| std::iter::from_fn(|| r.next(me)).collect());
        for (me, got) in taken.iter().enumerate() {
            // Each thread's first index is the front of its part.
            if let Some(&first) = got.first() {
                assert_eq!(first, n * me / threads);
            }
        }
        let mut all: Vec<usize> = taken.into_iter().flatten().collect();
        all.sort_unstable();
        assert_eq!(all, (0..n).collect::<Vec<_>>());
    }

    #[test]
    fn more_threads_than_indices() {
        let r = SplitRange::new(2, 5);
        let mut all: Vec<usize> = (0..5).flat_map(|me| r.next(me)).collect();
        all.sort_unstable();
        assert_eq!(all, vec![0, 1]);
        assert!((0..5).all(|me| r.next(me).is_none()));
    }
}
