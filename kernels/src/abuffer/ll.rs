//! `ll`: per-pixel linked lists (Yang et al. 2010, \[24\] of the depth-fighting paper; section
//! 3.1.3 "Overview" and Fig. 3(b) there; the llvmpipe peer's `--algo ll`), and the list pieces
//! `bun-ll` shares (insertion, resolve walk, host walk).
//!
//! "One buffer to store all linked-list node data and another buffer to store head offsets
//! that point the start of the linked lists in the first buffer. A single shared counter
//! (next) is atomically incremented to compute the mapping of an incoming fragment, followed
//! by an update of the head pointer" (depth-fighting paper 3.1.3). Here:
//! - the head image is a `u32` per pixel (`EMPTY` = end of list), updated with an atomic
//!   exchange, as the peer's `imageAtomicExchange`;
//! - a node is three words `[depth bits, primitive, next]` (the peer's std430
//!   `Node { float depth; uint color; uint next; }`, with the primitive in place of the
//!   colour so the oracle can compare (depth, primitive));
//! - the pool holds `capacity` nodes: `params.pool_per_pixel x pixels`, or, when that is
//!   `None`, exactly the fragment count of a count pass (as the peer sizes its pool). A
//!   fragment whose counter value is `>= capacity` is dropped and counted, so
//!   `dropped = max(counter - capacity, 0)` exactly.
//! - **A counter per screen block when the count pass sized the pool** ([`Blocks`]): the
//!   count pass says how many fragments each block of 32 x 32 pixels has, so block `b` gets
//!   its own exact range of the pool and its own counter (on its own cache line). With one
//!   global counter, two threads shading different parts of the screen took its cache line
//!   from each other at every fragment, and their nodes (consecutive counter values,
//!   interleaved between the threads) shared lines too: the bunny's insert pass at
//!   2048x2048 took 74 ms on one thread and 164 ms on two. A block's nodes are also near
//!   each other for the resolve. Each block's counter follows the rule above for its own
//!   range (`dropped` is the sum over blocks); with `pool_per_pixel` there is no count, and
//!   the single counter of the paper is used. The blocks and the count of a draw are kept
//!   for the next frame of the same draw (`sizing`). A fragment takes its node from its own
//!   block's counter only, and the capture kernel says so (`with_own_block_array`): where a
//!   worker owns a tile for the pass (blocks of 32 lie in tiles of 64), the counter's atomic
//!   add is then a plain load and store, as the head's exchange already was.
//!
//! **Publication order.** A node's payload (depth, primitive) is written *before* the head
//! exchange publishes it; its `next` link is the exchange's result, so it is written after
//! (as in every exchange-based list, the peer's included). The planted bug
//! ([`LinkedList::publish_before_write`]) exchanges first and writes the whole node after:
//! a reader that follows the head in between sees a half-written node. Across a pass
//! boundary nobody can (the resolve runs after the capture pass), so the bug is invisible
//! to the oracle; it shows only to a reader inside the capture pass
//! ([`LinkedList::concurrent_reader`]), where the hazard detector reports the reader's
//! payload record as torn and the reader itself counts half-written nodes.

use fragrace_emu::{Buf, ExecConfig, Fragment, FragmentKernel, KernelInfo, PassReport};

use super::checks::CaptureOrder;
use super::list_resolve::ListResolve;
use super::run::{AbRun, Readback};
use super::sizing::{sized_by_count, Blocks, BLOCK_SHIFT, COUNTER_STRIDE};
use super::walk::Walk;
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity,
    Check, Frame, HazardClass, Params,
};
use crate::common::EMPTY;
use crate::resolve::Composite;

pub(super) fn algorithms() -> Vec<Box<dyn Algorithm>> {
    vec![Box::new(LinkedList::correct())]
}

/// Words per node: `[depth bits, primitive, next]`.
pub const NODE_WORDS: u32 = 3;
/// Words of a node's payload (depth, primitive): the record a reader loads at once.
const PAYLOAD_WORDS: u32 = 2;
pub(super) const NEXT: u32 = 2;

/// Most nodes a pool may hold (the node buffer must stay addressable by `u32` word indices).
pub(super) const MAX_POOL_NODES: u64 = fragrace_emu::memory::MAX_BUFFER_WORDS / NODE_WORDS as u64;

/// The buffers of a node pool split into `regions` (1 for `ll`, one per bucket for `bun-ll`),
/// each with its own allocation counter and dropped counter.
#[derive(Clone, Copy)]
pub struct ListPool {
    /// List heads, `EMPTY` when empty.
    pub heads: Buf<u32>,
    /// Nodes, `NODE_WORDS` words each.
    pub nodes: Buf<u32>,
    /// Allocation counter of each region.
    pub counters: Buf<u32>,
    /// Fragments dropped by each region for lack of nodes.
    pub dropped: Buf<u32>,
}

/// What the words of a pool's nodes hold before anything writes them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unwritten {
    /// `EMPTY`, so that an unwritten word is recognisable: a reader inside the capture pass
    /// counts the half-written nodes it sees ([`LlInsert::reader`]).
    Empty,
    /// Zero, as in a fresh buffer, for pools that nobody reads before the capture pass ends
    /// (every node reachable then was written whole): no fill of the pool in the frame (at
    /// 2048x2048 the bunny's 43 MB, the 871K dragon's about three times that).
    Zero,
}

impl ListPool {
    /// Allocates the pool: `lists` heads and `nodes` nodes (filled with `EMPTY`, so an
    /// unwritten word is recognisable), `regions` counters.
    pub fn new(
        device: &mut fragrace_emu::Device,
        prefix: &str,
        lists: u64,
        nodes: u64,
        regions: u64,
    ) -> Result<ListPool, AlgoError> {
        Self::with_nodes(device, prefix, lists, nodes, regions, Unwritten::Empty)
    }

    /// [`ListPool::new`] with the nodes' words before the pass as `unwritten` says.
    pub fn with_nodes(
        device: &mut fragrace_emu::Device,
        prefix: &str,
        lists: u64,
        nodes: u64,
        regions: u64,
        unwritten: Unwritten,
    ) -> Result<ListPool, AlgoError> {
        if nodes > MAX_POOL_NODES {
            return Err(AlgoError::Invalid(format!(
                "{prefix}: a pool of {nodes} nodes is larger than a buffer can hold"
            )));
        }
        let heads = device.buffer_filled::<u32>(&format!("{prefix}-heads"), lists, EMPTY)?;
        let node_words = nodes.max(1) * NODE_WORDS as u64;
        let nodes = device.buffer_filled::<u32>(
            &format!("{prefix}-nodes"),
            node_words,
            match unwritten {
                Unwritten::Empty => EMPTY,
                Unwritten::Zero => 0,
            },
        )?;
        let counters = device.buffer::<u32>(&format!("{prefix}-counters"), regions)?;
        let dropped = device.buffer::<u32>(&format!("{prefix}-dropped"), regions)?;
        Ok(ListPool {
            heads,
            nodes,
            counters,
            dropped,
        })
    }
}

/// Inserts the fragment into list `head` with a node of `region` (nodes
/// `[base, base + cap)`): takes `i = atomicAdd(counter[region], 1)`; if `i >= cap` the
/// fragment is dropped and counted; otherwise node `base + i` is written and published.
/// Evaluates to the node, if any.
///
/// `list_insert!(f, pool, head, region, base, cap, publish_before_write)`, inside a kernel's
/// `shade`. A macro rather than an `async fn`, so that it expands into the kernel's own state
/// machine: a nested `async fn` is a second state machine whose `poll` the compiler does not
/// inline into the shading loop (6 KB of code with the fault paths of its four accesses). Its
/// arguments are written into its future and read back at every fragment: `ll`'s insert
/// pass of the bunny at 2048 x 2048 took 39 ms as a nested `async fn` and 30 ms expanded
/// (docs/performance.md).
macro_rules! list_insert {
    ($f:expr, $pool:expr, $head:expr, $region:expr, $base:expr, $cap:expr, $publish_before_write:expr) => {{
        use $crate::abuffer::ll::{NEXT, NODE_WORDS};
        // `$f` is used as it is: bound to a reference, it would be kept in the kernel's
        // future and every access would load it from there first.
        let (pool, head, region) = (&$pool, $head, $region);
        let i = $f.atomic_add(pool.counters, region, 1).await;
        if i >= $cap {
            $f.atomic_add(pool.dropped, region, 1).await;
            None
        } else {
            let node: u32 = $base + i;
            let at = node * NODE_WORDS;
            let (depth, prim) = ($f.depth().to_bits(), $f.primitive_id());
            if $publish_before_write {
                // The planted bug: the node is reachable from the head before it holds anything.
                let next = $f.atomic_exchange(pool.heads, head, node).await;
                $f.store_record(pool.nodes, at, &[depth, prim, next]).await;
            } else {
                // Payload first; the exchange publishes a node whose payload is complete. `next`
                // is the exchange's result, so it can only be written after it.
                $f.store_record(pool.nodes, at, &[depth, prim]).await;
                let next = $f.atomic_exchange(pool.heads, head, node).await;
                $f.store(pool.nodes, at + NEXT, next).await;
            }
            Some(node)
        }
    }};
}
pub(super) use list_insert;

/// Pool size in nodes for `params.pool_per_pixel` nodes per pixel.
pub(super) fn pool_from_params(per_pixel: f32, pixels: usize) -> u64 {
    let v = per_pixel as f64 * pixels as f64;
    if v.is_finite() && v > 0.0 {
        v.floor() as u64
    } else {
        0
    }
}

/// A linked-list capture kernel. In reader mode, after inserting, each fragment walks its
/// pixel's list as it stands (an in-pass consumer, the situation in which the publication
/// order matters), loading each node's payload as one record and counting the half-written
/// payloads it sees (`EMPTY` words: the pool is filled with `EMPTY` before the pass).
pub struct LlInsert {
    pub pool: ListPool,
    /// Nodes in the pool (region 0 is the whole pool, when `blocks` is `None`).
    pub cap: u32,
    /// A counter and a range of the pool per screen block (the pool sized by a count pass);
    /// `None`: one counter for the whole pool.
    pub blocks: Option<Blocks>,
    pub publish_before_write: bool,
    /// `[half-written payloads seen]`, in reader mode.
    pub reader: Option<Buf<u32>>,
}

impl FragmentKernel for LlInsert {
    fn info(&self) -> KernelInfo {
        let info = KernelInfo::new(if self.publish_before_write {
            "ll-insert-publish-first"
        } else {
            "ll-insert"
        });
        // Each fragment exchanges its pixel's head (prefetched ahead of shading), and only
        // its pixel's: a tile's heads belong to the tile, as on a tiled GPU.
        let info = info.with_own_pixel_array(self.pool.heads, 1);
        // With a counter per screen block, a fragment takes a node from its block's
        // counter only: a tile's blocks' counters belong to the tile too. (The in-pass
        // reader and the planted bug keep the declaration: it changes no result.)
        match self.blocks {
            Some(_) => info.with_own_block_array(self.pool.counters, BLOCK_SHIFT, COUNTER_STRIDE),
            None => info,
        }
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let (region, base, cap) = match &self.blocks {
            Some(blocks) => {
                let b = blocks.of(f.x(), f.y());
                let (base, cap) = blocks.range(b);
                (b as u32 * COUNTER_STRIDE, base, cap)
            }
            None => (0, 0, self.cap),
        };
        list_insert!(f, self.pool, p, region, base, cap, self.publish_before_write);
        let Some(seen) = self.reader else { return };
        let mut cur = f.atomic_load(self.pool.heads, p).await;
        let mut steps = 0;
        while cur != EMPTY && cur < self.cap && steps < self.cap {
            let mut payload = [0u32; PAYLOAD_WORDS as usize];
            f.load_record(self.pool.nodes, cur * NODE_WORDS, &mut payload)
                .await;
            if payload.contains(&EMPTY) {
                f.atomic_add(seen, 0, 1).await;
            }
            cur = f.load(self.pool.nodes, cur * NODE_WORDS + NEXT).await;
            steps += 1;
        }
    }
}

/// `ll`: per-pixel linked lists. The registered algorithm is `LinkedList::default()`; the
/// other settings exist for verifying the hazard detector and the invariants on a known
/// bug (`ll-publish-first`, `ll-reader`, `ll-publish-first-reader`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LinkedList {
    /// The planted bug: exchange the head (publish the node) before writing the node.
    pub publish_before_write: bool,
    /// Every fragment also walks its pixel's list inside the capture pass (the reader that
    /// can see a half-written node). With it the detector also reports data races on the
    /// node words in the correct order: it judges by overlapping lifetimes and does not
    /// model the release/acquire edge of the head exchange; torn records and half-written
    /// nodes, though, appear only with the planted bug.
    pub concurrent_reader: bool,
}

impl LinkedList {
    /// The correct lists (the registered `ll`).
    pub const fn correct() -> LinkedList {
        LinkedList {
            publish_before_write: false,
            concurrent_reader: false,
        }
    }
    /// The planted bug with the in-pass reader that exposes it.
    pub const fn planted_bug() -> LinkedList {
        LinkedList {
            publish_before_write: true,
            concurrent_reader: true,
        }
    }
    /// The correct order with the in-pass reader (the control for [`LinkedList::planted_bug`]).
    pub const fn correct_with_reader() -> LinkedList {
        LinkedList {
            publish_before_write: false,
            concurrent_reader: true,
        }
    }

    fn name(&self) -> &'static str {
        match (self.publish_before_write, self.concurrent_reader) {
            (false, false) => "ll",
            (true, false) => "ll-publish-first",
            (false, true) => "ll-reader",
            (true, true) => "ll-publish-first-reader",
        }
    }
}

impl Algorithm for LinkedList {
    /// Neither k (it keeps every fragment) nor a spin cap.
    fn reads(&self, _: crate::Param) -> bool {
        false
    }

    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: self.name(),
            family: "a-buffer",
            summary: if self.publish_before_write {
                "per-pixel linked lists with the planted bug: the head exchange publishes a node before it is \
                 written (a concurrent reader may follow a half-written node)"
            } else {
                "per-pixel linked lists: global atomic node counter, head exchange after the node's payload \
                 is written, pool sized by a count pass or pool_per_pixel; resolve walks, sorts, composites"
            },
            source: "Yang et al. 2010, ref [24] of the depth-fighting paper, section 3.1.3 and Fig. 3(b); \
                     the llvmpipe peer's `--algo ll`",
            passes: "1 geometry (+1 count pass when the pool is sized exactly) + 1 full-screen",
            memory: "4 + 12 n bytes (head; depth, primitive, next per node; +4 for the sizing count pass); \
                     Table 1: 3 C(Zall) + 3 words",
            hazard: if self.publish_before_write { HazardClass::HazardProne } else { HazardClass::HazardFree },
            capacity: Capacity::All,
        }
    }


    /// The count pass (when the pool is sized exactly; on a direct executor, the last
    /// frame's count when it drew the same: `sizing::sized_by_count`), the capture pass and
    /// the resolve; the lists are walked and checked afterwards ([`AlgoResult::deferred`]).
    fn run_frame(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        let mut run = AbRun::new(frame, params, exec)?;
        let n = run.n;
        // The resolve writes nothing back; the host sorts the lists it reads (`Walk`).
        run.order = CaptureOrder::Host;
        // The count pass is optional: the report starts empty.
        let mut report = PassReport::default();

        // Pool size: nodes per pixel x pixels (one counter), or exactly the count pass's
        // total (a counter per screen block, sized by its count). The counts are moved out
        // of the device (no copy) for the list-length check.
        let mut counted = None;
        let mut blocks = None;
        let capacity = match params.pool_per_pixel {
            Some(per_pixel) => pool_from_params(per_pixel, n),
            None => {
                let sized = sized_by_count(&mut run, &mut report)?;
                let total = sized.blocks.total();
                blocks = Some(sized.blocks.clone());
                counted = Some(sized);
                total
            }
        };
        // Counters (and dropped counts) of the regions: one, or one cache line per block.
        let regions = blocks
            .as_ref()
            .map_or(1, |b| b.len() as u64 * u64::from(COUNTER_STRIDE));
        let device = &mut run.device;
        // Only the in-pass reader looks at nodes before they are written.
        let unwritten = if self.concurrent_reader {
            Unwritten::Empty
        } else {
            Unwritten::Zero
        };
        let pool = ListPool::with_nodes(device, "ll", n as u64, capacity, regions, unwritten)?;
        let cap = capacity as u32;
        let reader = if self.concurrent_reader {
            Some(device.buffer::<u32>("ll-reader-half-written", 1)?)
        } else {
            None
        };
        let faults = device.buffer::<u32>("ll-resolve-faults", 2)?;

        // Each block's (first node, nodes), for the readback; one region without blocks.
        let ranges: Vec<(u32, u32)> = match &blocks {
            Some(b) => (0..b.len()).map(|i| b.range(i)).collect(),
            None => vec![(0, cap)],
        };
        let insert = LlInsert {
            pool,
            cap,
            blocks: blocks.clone(),
            publish_before_write: self.publish_before_write,
            reader,
        };
        let resolve = ListResolve {
            pool,
            lists: 1,
            pool_nodes: cap,
            faults,
            composite: Composite::of(params),
            blocks,
        };
        let generated = run.store_and_resolve(&mut report, &insert, &resolve)?;

        let memory = &run.device.memory;
        // Region r's counter and dropped count are word r (one region) or r * COUNTER_STRIDE.
        let stride = if ranges.len() == 1 { 1 } else { COUNTER_STRIDE as usize };
        let counters = memory.read(pool.counters)?;
        let dropped_words = memory.read(pool.dropped)?;
        let (mut counter, mut dropped, mut allocated, mut dropped_counter) = (0u64, 0u64, 0u32, 0u64);
        for (r, &(_, size)) in ranges.iter().enumerate() {
            let c = counters[r * stride];
            counter += u64::from(c);
            dropped += u64::from(c.saturating_sub(size));
            allocated += c.min(size);
            dropped_counter += u64::from(dropped_words[r * stride]);
        }
        let (width, height) = (frame.width, frame.height);
        Ok(run.finish_deferred(report, dropped, move |device| {
            let memory = &device.memory;
            // One region: its allocated nodes are a prefix of the pool. Blocks: every node
            // is some block's (an exact count allocates them all).
            let range = if ranges.len() == 1 { allocated } else { cap };
            let walk = Walk::new(
                &memory.read(pool.heads)?,
                &memory.read(pool.nodes)?,
                1,
                &[(0, range)],
            );
            let capture = walk.capture_sized(width, height, 1);
            let own = vec![
                Check::new(
                    "every generated fragment stored exactly once unless the pool overflowed",
                    walk.stored + dropped == generated && walk.stored == allocated as u64 && walk.revisits == 0,
                    format!(
                        "stored {} (allocated {allocated}), dropped {dropped}, generated {generated}; pool {cap} nodes",
                        walk.stored
                    ),
                ),
                Check::new(
                    "overflow counted exactly",
                    dropped_counter == dropped,
                    format!(
                        "dropped counter {dropped_counter}, the sum over {} regions of max(node counter - capacity, 0) = {dropped} \
                         (counters {counter} in all, capacity {cap})",
                        ranges.len()
                    ),
                ),
                walk.integrity_check(&memory.read(faults)?),
            ];
            let mut later = Vec::new();
            if let Some(c) = &counted {
                let bad = (0..n)
                    .filter(|&p| walk.lists[p].len() as u32 != c.counts[p])
                    .count();
                later.push(Check::new(
                    "list lengths equal the count pass (per pixel)",
                    bad == 0,
                    format!("{bad} pixels differ"),
                ));
            }
            if let Some(r) = reader {
                let half = memory.read(r)?[0];
                later.push(Check::new(
                    "the in-pass reader never saw a half-written node",
                    half == 0,
                    format!("{half} half-written node payloads seen"),
                ));
            }
            Ok(Readback { capture, own, later })
        }))
    }
}

#[cfg(test)]
mod tests {
    use fragrace_emu::Policy;

    use super::*;
    use crate::basic::Truth;
    use crate::oracle;
    use crate::testing::*;

    #[test]
    fn ll_is_exact_and_hazard_free_under_every_executor() {
        assert_exact_and_hazard_free_everywhere(&LinkedList::default());
        let mesh = layers();
        let f = frame_sized(&mesh, 24, 20);
        // A roomy pool from pool_per_pixel instead of the count pass.
        let params = Params {
            pool_per_pixel: Some(8.0),
            ..Params::default()
        };
        for exec in [
            ExecConfig::ordered(),
            ExecConfig::parallel(4),
            ExecConfig::scheduled(Policy::Random, 9),
        ] {
            assert_exact(&LinkedList::default(), &f, &params, &exec);
        }
        // Deep lists: the resolve shell-sorts.
        let mesh = stack(19);
        let f = frame_sized(&mesh, 5, 4);
        for exec in [
            ExecConfig::ordered(),
            ExecConfig::parallel(2),
            ExecConfig::scheduled(Policy::Random, 2),
        ] {
            assert_exact(&LinkedList::default(), &f, &Params::default(), &exec);
        }
    }

    #[test]
    fn ll_small_pool_counts_overflow_exactly_and_never_corrupts() {
        let mesh = stack(4);
        let f = frame_sized(&mesh, 6, 5); // 30 pixels x 4 = 120 fragments
        let truth = Truth::capture(&f, 1).unwrap();
        for (per_pixel, capacity) in [(1.5, 45u64), (0.0, 0), (3.99, 119), (4.0, 120)] {
            let params = Params {
                pool_per_pixel: Some(per_pixel),
                ..Params::default()
            };
            for exec in executor_configs() {
                let r = LinkedList::default().run(&f, &params, &exec).unwrap();
                let what = format!("pool {per_pixel}/px under {:?}", exec.mode);
                for c in &r.checks {
                    assert!(c.passed, "{what}: `{}`: {}", c.name, c.detail);
                }
                assert_eq!(r.dropped, 120 - capacity, "{what}");
                let m = oracle::compare(&LinkedList::default().info(), &r, &truth, &params);
                assert_eq!(m.captured, capacity, "{what}");
                // Whatever was kept is a real fragment of its pixel, once.
                let c = r.capture.as_ref().unwrap();
                let t = truth.capture.as_ref().unwrap();
                for p in 0..c.pixels() {
                    for fr in c.pixel(p) {
                        assert!(
                            t.pixel(p).contains(fr),
                            "{what}: pixel {p}: {fr:?} is not one of truth's"
                        );
                    }
                }
                assert_eq!(r.report.hazards.total(), 0, "{what}");
            }
        }
    }

    /// Runs a variant on a tiny, deep scene (16 pixels x 8 layers: every fragment of a pixel
    /// is in the scheduler's window at once) under `seeds` random schedules; returns
    /// (torn records, races, half-written nodes seen) per seed.
    fn race_bug(variant: LinkedList, seeds: u64) -> Vec<(u64, u64, bool)> {
        let mesh = stack(8);
        let f = frame_sized(&mesh, 4, 4);
        let truth = Truth::capture(&f, 1).unwrap();
        (0..seeds)
            .map(|seed| {
                let exec = ExecConfig::scheduled(Policy::Random, seed);
                let r = variant.run(&f, &Params::default(), &exec).unwrap();
                // Across the pass boundary the lists are always complete: the oracle cannot
                // tell the planted bug from the correct order.
                let m = oracle::compare(&variant.info(), &r, &truth, &Params::default());
                assert_eq!(m.epr, 0.0, "{} seed {seed}", variant.info().name);
                let half = r
                    .checks
                    .iter()
                    .any(|c| c.name.contains("half-written") && !c.passed);
                for c in r.checks.iter().filter(|c| !c.name.contains("half-written")) {
                    assert!(
                        c.passed,
                        "{} seed {seed}: `{}`: {}",
                        variant.info().name,
                        c.name,
                        c.detail
                    );
                }
                (r.report.hazards.torn, r.report.hazards.races, half)
            })
            .collect()
    }

    #[test]
    fn planted_bug_shows_torn_records_and_half_written_nodes() {
        let bug = race_bug(LinkedList::planted_bug(), 8);
        assert!(
            bug.iter().any(|&(torn, _, _)| torn > 0),
            "no seed tore a record: {bug:?}"
        );
        assert!(
            bug.iter().any(|&(_, _, half)| half),
            "no seed let the reader see a half-written node: {bug:?}"
        );
        // The control: same reader, correct order. The detector still reports races (the
        // reader's plain loads overlap the writers' lifetimes) but never a torn payload, and
        // the reader never sees a half-written one.
        let control = race_bug(LinkedList::correct_with_reader(), 8);
        assert!(
            control.iter().all(|&(torn, _, half)| torn == 0 && !half),
            "{control:?}"
        );
        // Without a reader the bug is latent: no hazard, exact result.
        let latent = race_bug(
            LinkedList {
                publish_before_write: true,
                concurrent_reader: false,
            },
            4,
        );
        assert!(
            latent
                .iter()
                .all(|&(torn, races, half)| torn == 0 && races == 0 && !half),
            "{latent:?}"
        );
        let correct = race_bug(LinkedList::correct(), 8);
        assert!(
            correct
                .iter()
                .all(|&(torn, races, half)| torn == 0 && races == 0 && !half),
            "{correct:?}"
        );
    }

    #[test]
    fn names_and_declared_classes() {
        assert_eq!(LinkedList::default(), LinkedList::correct());
        assert_eq!(LinkedList::correct().info().name, "ll");
        assert_eq!(LinkedList::correct().info().hazard, HazardClass::HazardFree);
        assert_eq!(
            LinkedList::planted_bug().info().name,
            "ll-publish-first-reader"
        );
        assert_eq!(
            LinkedList::planted_bug().info().hazard,
            HazardClass::HazardProne
        );
        assert_eq!(
            algorithms()
                .iter()
                .map(|a| a.info().name)
                .collect::<Vec<_>>(),
            ["ll"]
        );
    }
}
