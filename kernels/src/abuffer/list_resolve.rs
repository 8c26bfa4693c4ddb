//! The resolve of the list A-buffers (`ll` and `bun-ll`): [`ListResolve`], one invocation a
//! pixel that walks its lists, sorts their fragments and composites them front to back, and
//! the per-thread state it keeps from pixel to pixel (scratch vectors, and how far it has
//! asked for its block's nodes: a cache hint).

use std::cell::Cell;

use fragrace_emu::{Buf, Fragment, FragmentKernel, KernelInfo};

use super::ll::{ListPool, NEXT, NODE_WORDS};
use super::sizing::Blocks;
use crate::algo::CapturedFrag;
use crate::common::{sort_fragments, sort_key, sort_keys_changed, EMPTY};
use crate::resolve::Composite;

/// The resolve of list A-buffers: one invocation per pixel walks each of its `lists` lists
/// (bounded by the pool size, so a cycle cannot hang it; a link out of the pool ends the walk;
/// both are counted in `faults[0]` and `faults[1]`), loading every node as one record, sorts
/// each list's fragments in its own memory (`sort_fragments`) and composites the lists'
/// concatenation front to back.
///
/// The pool is only read: the lists are collected and the fragments blended in order
/// (Yang et al. 2010 "use dynamic linked lists to collect fragments and blend them in
/// order", the depth-presorted paper, section 2), and the llvmpipe peer's resolve binds the
/// nodes `readonly`; nothing is written back. The host sorts each list it reads back
/// (`Walk::capture_sized`, with the standard library's sort), so the resolve's order is
/// checked through its image ("resolve image is the composite of the captured fragments"). Writing the sorted
/// payloads back along the lists, as this resolve did before, was a fifth of its time: the
/// bunny's at 2048 x 2048 on one thread took 34.5 ms with it and 27.3 ms without
/// (docs/performance.md).
pub(super) struct ListResolve {
    pub pool: ListPool,
    /// Lists per pixel (the heads of pixel `p` are `p * lists ..`).
    pub lists: u32,
    /// Nodes in the pool.
    pub pool_nodes: u32,
    /// `[links out of the pool, walks cut at the pool size]`.
    pub faults: Buf<u32>,
    pub composite: Composite,
    /// The pool's screen blocks, when it is cut into them
    /// ([`LlInsert::blocks`](super::ll::LlInsert::blocks)): each block's nodes are
    /// prefetched a few lines at a time as the block is shaded.
    pub blocks: Option<Blocks>,
}

impl FragmentKernel for ListResolve {
    fn info(&self) -> KernelInfo {
        // A pixel no fragment reached has empty lists (the heads are filled with `EMPTY`):
        // it writes the background.
        KernelInfo::new("list-resolve")
            .with_untouched_output(self.composite.background_bits())
            // A pixel's lists hold only nodes its own fragments inserted.
            .with_by_region_reads()
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        // The block's nodes (its pixels' nodes, and only theirs) are asked of the cache a few
        // lines at a time as this thread shades the block, from the first: the walks below
        // follow them link by link, each load waiting for the one before, so a pool read
        // from memory (a pass whose resolve runs after all of its geometry, the 871K
        // dragon's at 2048 x 2048) would wait for one miss at a time. A few lines at a
        // time, not the block's all at once: more requests than the cache can have in
        // flight are dropped. A hint: no access, no effect on any value.
        if let Some(blocks) = &self.blocks {
            let (x, y) = (f.x(), f.y());
            if x % PREFETCH_EVERY == 0 {
                let b = blocks.of(x, y);
                let words = CURSOR.with(|c| c.next(b, || blocks.range(b)));
                if !words.is_empty() {
                    f.prefetch(self.pool.nodes, words);
                }
            }
        }
        let first = p * self.lists;
        let head = f.load(self.pool.heads, first).await;
        // An empty pixel (most of a frame) loads its one head and writes the background.
        if self.lists == 1 && head == EMPTY {
            self.composite.output(&f, &[]);
            return;
        }
        if self.lists == 1 {
            // A list of at most `SHORT` nodes, all in the pool, is gathered on the stack
            // rather than in the thread's scratch vectors (whose take and put back cost about
            // a tenth of the resolve's instructions). Written here, not as an `async fn` of
            // its own, for the reason `list_insert!` gives. A longer list, or one that leaves
            // the pool, is left to the general walk below (which counts the fault).
            // The fragments as sort keys (`sort_key`: one word each, see there).
            let mut keys = [0u64; SHORT];
            let mut n = 0;
            let mut cur = head;
            while cur != EMPTY && n < SHORT && cur < self.pool_nodes && (n as u32) < self.pool_nodes
            {
                let mut rec = [0u32; NODE_WORDS as usize];
                f.load_record(self.pool.nodes, cur * NODE_WORDS, &mut rec)
                    .await;
                keys[n] = sort_key(rec[0], rec[1]);
                n += 1;
                cur = rec[NEXT as usize];
            }
            if cur == EMPTY {
                let keys = &mut keys[..n];
                // Whether the sort moved anything does not matter here: nothing is written back.
                sort_keys_changed(keys);
                self.composite.output_keys(&f, keys);
                return;
            }
        }
        // The lists are gathered in this thread's scratch vectors, reused from pixel to
        // pixel (not two allocations per covered pixel). An invocation that finds them
        // taken (another one on this thread is suspended holding them, under the
        // scheduled executor) starts from empty ones; the last one back keeps its own.
        let (mut all, mut frags) = SCRATCH.with(Cell::take);
        all.clear();
        for b in 0..self.lists {
            let mut cur = if b == 0 {
                head
            } else {
                f.load(self.pool.heads, first + b).await
            };
            frags.clear();
            while cur != EMPTY {
                if cur >= self.pool_nodes {
                    f.atomic_add(self.faults, 0, 1).await;
                    break;
                }
                if frags.len() as u32 >= self.pool_nodes {
                    f.atomic_add(self.faults, 1, 1).await;
                    break;
                }
                let mut rec = [0u32; NODE_WORDS as usize];
                f.load_record(self.pool.nodes, cur * NODE_WORDS, &mut rec)
                    .await;
                frags.push(CapturedFrag::from_bits(rec[0], rec[1]));
                cur = rec[NEXT as usize];
            }
            sort_fragments(&mut frags);
            all.extend_from_slice(&frags);
        }
        self.composite.output(&f, &all);
        SCRATCH.with(|s| s.set((all, frags)));
    }
}

/// Most nodes of a list [`ListResolve`] gathers on the stack (the bunny at
/// 2048 x 2048 has 4 fragments a covered pixel on average, the 871K dragon 6).
const SHORT: usize = 16;

thread_local! {
    /// [`ListResolve`]'s per-thread scratch: the pixel's fragments and one list's fragments.
    static SCRATCH: Cell<(Vec<CapturedFrag>, Vec<CapturedFrag>)> = Cell::default();
    /// How far this thread's [`ListResolve`] has asked for its last two blocks' nodes.
    static CURSOR: PrefetchCursor = const { PrefetchCursor(Cell::new([(usize::MAX, 0, 0); 2])) };
}

/// A resolve asks for the next [`PREFETCH_WORDS`] of its block's nodes at every
/// `PREFETCH_EVERY`th pixel of a row: the executor shades or skips runs of 8 pixels together
/// (a block no geometry reached is skipped whole), so each run that is shaded asks.
const PREFETCH_EVERY: u32 = 8;

/// Node words a resolve asks of the cache at a time (16 lines of 64 bytes).
const PREFETCH_WORDS: u32 = 256;

/// The last two blocks a thread's resolve was in, newest first, and the words of their
/// nodes not yet asked for: `(block, next, end)`. Two, because a tile of 64 pixels holds
/// two blocks of 32 across and its rows alternate between them. Only a hint depends on it
/// (`Fragment::prefetch`): whatever it holds, the resolve's values do not change.
struct PrefetchCursor(Cell<[(usize, u32, u32); 2]>);

impl PrefetchCursor {
    /// The node words to ask for at a pixel of block `b` (whose nodes are `range()`): the
    /// next [`PREFETCH_WORDS`] of its nodes, from the first when the block is not one of
    /// the last two.
    #[inline]
    fn next(&self, b: usize, range: impl FnOnce() -> (u32, u32)) -> std::ops::Range<u32> {
        let [newest, older] = self.0.get();
        let (mut next, end, other) = if newest.0 == b {
            (newest.1, newest.2, older)
        } else if older.0 == b {
            (older.1, older.2, newest)
        } else {
            let (start, count) = range();
            (start * NODE_WORDS, (start + count) * NODE_WORDS, newest)
        };
        let from = next;
        next = end.min(next.saturating_add(PREFETCH_WORDS));
        self.0.set([(b, next, end), other]);
        from..next
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cursor_asks_for_each_blocks_nodes_once_in_order_for_two_blocks_at_a_time() {
        let c = PrefetchCursor(Cell::new([(usize::MAX, 0, 0); 2]));
        // Block 5: nodes 10..110 (300 words); block 6: nodes 200..210 (30 words).
        let range = |b: usize| match b {
            5 => (10, 100),
            6 => (200, 10),
            _ => (0, 1),
        };
        let mut asked = [Vec::new(), Vec::new()];
        // The rows of a tile alternate between two blocks.
        for _ in 0..4 {
            for (k, b) in [5usize, 6].into_iter().enumerate() {
                asked[k].push(c.next(b, || range(b)));
            }
        }
        assert_eq!(asked[0], [30..286, 286..330, 330..330, 330..330]);
        assert_eq!(asked[1], [600..630, 630..630, 630..630, 630..630]);
        // A third block takes the place of the older one; the newer keeps its place.
        assert_eq!(c.next(7, || range(7)), 0..3);
        assert_eq!(c.next(6, || range(6)), 630..630);
        assert_eq!(c.next(5, || range(5)), 30..286);
    }
}
