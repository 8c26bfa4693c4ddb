//! The fused path of the `ordered` and `parallel` executors: rasterize, test, shade and
//! write one unit of tile work at a time, with no per-pass fragment lists.
//!
//! The general path ([`super::Device::run_waves`]) materializes every fragment of a wave
//! (rasterize all tiles, shade all fragments, then run the late stage), which the scheduled
//! executor needs (it interleaves invocations of many tiles) and ordered interlock needs
//! (tickets). Direct executors need none of that: a worker takes a unit of work (a tile, or a
//! [`Segment`] of one), rasterizes it into a warp of at most `batch` fragments, shades the
//! warp (lanes in lockstep or one after the other, as `ExecConfig::lockstep` says), runs the
//! late tests and target writes in API order, and goes on. Memory stays in the tile; nothing
//! is allocated per fragment.
//!
//! When the pass's fixed-function results commute (no colour targets, no stencil, no depth
//! writes: capture passes, counting), a tile's triangles are cut into segments of at most
//! `ExecConfig::segment` and different threads take segments of the same tile at the same
//! time: fragments of one pixel then run concurrently on different threads, as on a GPU,
//! and races on shared memory are real races. Otherwise a tile belongs to one worker at a
//! time, so depth, stencil and blending happen in API order. When a pass needs nothing of
//! the framebuffer at all (no test either), the parallel executor skips the tiles:
//! [`run_unbinned`] hands out chunks of triangles, set up and shaded by whichever worker
//! takes them. Without lockstep such passes also shade through a loop of their own
//! (`Worker::run_unit_counting`), which carries nothing per pixel but the kernel.
//!
//! This module knows no algorithm; it does not handle interlock (ordered interlock needs the
//! per-pixel tickets of the general path) nor the contention table.

use std::future::Future;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::pin::Pin;
use std::task::{Context, Poll, Waker};
use std::time::{Duration, Instant};

use crate::exec::{record_panic, Acc, ShadeOutcome, Tally};
use crate::fragment::DirectFrag;
use crate::framebuffer::TileMemory;
use crate::kernel::{
    DirectState, Frag, FragInput, FragmentKernel, Invocation, Mode, PassEnv, PixelArray,
};
use crate::memory::PixelPrefetcher;
use crate::raster::{Binned, FlatChunk, Prepared, SampleCount, Segment, SetupTriangle, Span};
use crate::state::FragmentState;
use crate::sync::pool;
use crate::sync::split::SplitRange;

/// What a fused pass needs besides the kernel and its environment.
pub(crate) struct FusedPass<'a> {
    pub state: &'a FragmentState,
    pub instance: u32,
    /// Primitive id of setup source 0 (the draw's first triangle, `Draw::triangles`).
    pub first: u32,
    /// Multisampling off on a multisampled target: one coverage bit covers every sample.
    pub single: bool,
    /// Depth and stencil tests before shading (otherwise after).
    pub early: bool,
    pub targets: usize,
    /// Lanes per warp.
    pub lanes: usize,
    pub lockstep: bool,
    pub threads: usize,
    /// `Some(n)`: cut tiles into segments of at most `n` triangles shared between threads
    /// (only when the fixed-function results commute); `None`: one tile per unit.
    pub segment: Option<u32>,
    /// Invocation ids of this pass start here (see [`FragInput::seq`]).
    pub seq_base: u64,
}

/// Where a unit of work's covered runs come from: a segment of a tile's bin lists
/// (rasterized into the worker's buffer), or a chunk of triangles set up without binning
/// (whose setup produced them).
trait SpanSource {
    fn spans<'s>(&'s self, buf: &'s mut Vec<Span>) -> &'s [Span];
}

struct SegmentSpans<'b> {
    binned: &'b Binned,
    seg: Segment,
}

impl SpanSource for SegmentSpans<'_> {
    fn spans<'s>(&'s self, buf: &'s mut Vec<Span>) -> &'s [Span] {
        buf.clear();
        self.binned.raster_segment_spans(&self.seg, |s| buf.push(s));
        buf
    }
}

impl SpanSource for FlatChunk {
    fn spans<'s>(&'s self, _: &'s mut Vec<Span>) -> &'s [Span] {
        &self.spans
    }
}

/// Fixed-function counts of a fused pass.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct FusedCounts {
    pub generated: u64,
    pub early_culled: u64,
    pub late_culled: u64,
    pub samples_passed: u64,
}

impl FusedCounts {
    /// Adds these counts to a pass's statistics.
    pub fn add_to(&self, stats: &mut crate::stats::Stats) {
        stats.fragments_generated += self.generated;
        stats.early_culled += self.early_culled;
        stats.late_culled += self.late_culled;
        stats.samples_passed += self.samples_passed;
    }

    fn add(&mut self, o: &FusedCounts) {
        self.generated += o.generated;
        self.early_culled += o.early_culled;
        self.late_culled += o.late_culled;
        self.samples_passed += o.samples_passed;
    }
}

/// Whether a pass's fixed-function work commutes, so that several threads may work on one
/// tile at once (tests read the tile and nothing writes it).
pub(crate) fn commutes(state: &FragmentState, targets: usize) -> bool {
    targets == 0 && !state.stencil.enabled && !(state.depth.test && state.depth.write)
}

/// A worker's view of its current tile: shared (segments; tests only read) or exclusive.
enum TileAccess<'t> {
    Shared(&'t TileMemory),
    Exclusive(&'t mut TileMemory),
}

impl TileAccess<'_> {
    fn tile(&self) -> &TileMemory {
        match self {
            TileAccess::Shared(t) => t,
            TileAccess::Exclusive(t) => t,
        }
    }

    #[inline]
    fn test(
        &mut self,
        state: &FragmentState,
        (lx, ly): (u32, u32),
        cov: u8,
        depths: &[f32; 8],
        front_facing: bool,
    ) -> u8 {
        match self {
            TileAccess::Shared(t) => t.depth_test_readonly(state, lx, ly, cov, depths),
            TileAccess::Exclusive(t) => {
                t.depth_stencil(state, lx, ly, cov, depths, front_facing, true)
            }
        }
    }
}

/// Runs a fused pass over `tiles` (all of the framebuffer's tiles, in tile order).
// Never inlined: one call per pass, and profiles can then tell the pass apart.
#[inline(never)]
pub(crate) fn run_fused<K: FragmentKernel>(
    kernel: &K,
    env: &PassEnv<'_>,
    pass: &FusedPass<'_>,
    binned: &Binned,
    tiles: &mut [TileMemory],
) -> (ShadeOutcome, FusedCounts, Duration) {
    let threads = pass.threads.max(1);
    if pass.state.depth.test || pass.state.stencil.enabled {
        // Tests read the depth and stencil planes of every tile (lazily allocated).
        for t in tiles.iter_mut() {
            t.materialize();
        }
    }
    let (results, imbalance): (Vec<(Acc, FusedCounts)>, Duration) = match pass.segment {
        Some(max) => {
            debug_assert!(commutes(pass.state, pass.targets));
            let mut segments = Vec::new();
            for t in 0..tiles.len() {
                binned.tile_segments(t, max, &mut segments);
            }
            let tiles: &[TileMemory] = tiles;
            // One shared counter, not `SplitRange`: segments of one tile are cut so that
            // different threads shade them at the same time (`ExecConfig::segment`).
            let next = crate::sync::AtomicUsize::new(0);
            let work = |_| {
                let mut w = Worker::new(kernel, env, pass);
                loop {
                    let i = next.fetch_add(1, crate::sync::Ordering::Relaxed);
                    let Some(&seg) = segments.get(i) else { break };
                    let tile = TileAccess::Shared(&tiles[seg.tile as usize]);
                    w.run_unit(&SegmentSpans { binned, seg }, env, Some(tile));
                }
                w.finish()
            };
            broadcast_timed(threads.min(segments.len().max(1)), work)
        }
        None => {
            let count = tiles.len();
            let threads = threads.min(count.max(1));
            // Each tile is handed out once (`SplitRange`), so its lock is never contended:
            // it only moves the `&mut` to the thread that took the index.
            let slots: Vec<pool::Mutex<Option<&mut TileMemory>>> = tiles
                .iter_mut()
                .map(|t| pool::Mutex::new(Some(t)))
                .collect();
            let queue = SplitRange::new(count, threads);
            let work = |me: usize| {
                let mut w = Worker::new(kernel, env, pass);
                let mut segs = Vec::new();
                while let Some(index) = queue.next(me) {
                    let taken = slots[index]
                        .lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .take();
                    let Some(tile) = taken else { continue };
                    segs.clear();
                    // Several units in turn, in API order: each unit's spans are gathered
                    // before shading (see `Worker::run_unit`).
                    binned.tile_segments(index, EXCLUSIVE_UNIT, &mut segs);
                    let mut access = Some(TileAccess::Exclusive(tile));
                    for &seg in &segs {
                        access = w.run_unit(&SegmentSpans { binned, seg }, env, access);
                    }
                }
                w.finish()
            };
            broadcast_timed(threads, work)
        }
    };
    let mut outcome = ShadeOutcome::default();
    let mut counts = FusedCounts::default();
    for (acc, c) in results {
        acc.finish(&mut outcome);
        counts.add(&c);
    }
    (outcome, counts, imbalance)
}

/// [`pool::broadcast`], and how long the threads waited for the last one to finish: the sum
/// over threads of the time from a thread's end to the last thread's end (load imbalance,
/// [`PassReport::imbalance`](super::PassReport::imbalance)).
fn broadcast_timed<R: Send>(n: usize, work: impl Fn(usize) -> R + Sync) -> (Vec<R>, Duration) {
    let results = pool::broadcast(n, |i| {
        let r = work(i);
        (r, Instant::now())
    });
    let last = results.iter().map(|(_, end)| *end).max();
    let imbalance = match last {
        Some(last) => results.iter().map(|(_, end)| last - *end).sum(),
        None => Duration::ZERO,
    };
    (results.into_iter().map(|(r, _)| r).collect(), imbalance)
}

/// Most bin entries per unit of work of a tile that one worker holds (units of one tile run
/// in turn, in API order).
const EXCLUSIVE_UNIT: u32 = 1024;

/// Most input triangles per unit of work of [`run_unbinned`]: its setup records stay in
/// the worker's cache between setup and shading.
pub(crate) const UNBINNED_CHUNK: usize = 512;

/// Fewest chunks of [`run_unbinned`] per thread (when the mesh has enough triangles): a
/// thread that ends its part takes chunks from the back of another's, so the threads end
/// at most about a chunk apart. With 8 a thread, the bunny @2048 (3674 triangles, chunks
/// of 230, about 0.35 ms each on two threads) left the threads 221 µs apart on average at
/// the end of the pass (`PassReport::imbalance`), 5 % of its frame; 32: 102 µs, 64: 53 µs.
const CHUNKS_PER_THREAD: usize = 64;

/// Whether a pass can run unbinned ([`run_unbinned`]): its fixed-function work commutes,
/// and it has no depth or stencil test and no target, so that a fragment needs nothing
/// of the framebuffer and the order in which threads visit pixels does not matter.
pub(crate) fn unbinned(state: &FragmentState, targets: usize) -> bool {
    commutes(state, targets) && !state.depth.test
}

/// Runs a fused pass without binning: workers take chunks of at most [`UNBINNED_CHUNK`]
/// input triangles in turn, set each up ([`Prepared::setup_flat`]) and rasterize and shade it
/// at once, in API order within the chunk. Fragments of one pixel from different chunks run
/// concurrently on different threads, as on a GPU. Only for passes that
/// [`unbinned`] allows (nothing per-pixel is ordered) and well-formed meshes
/// ([`Prepared::well_formed`]). Returns the outcome, the counts and the triangles rejected.
#[inline(never)]
pub(crate) fn run_unbinned<K: FragmentKernel>(
    kernel: &K,
    env: &PassEnv<'_>,
    pass: &FusedPass<'_>,
    prepared: &Prepared<'_>,
) -> (ShadeOutcome, FusedCounts, u64, Duration) {
    debug_assert!(unbinned(pass.state, pass.targets) && !pass.early_tests());
    let n = prepared.triangle_count();
    let threads = pass.threads.max(1);
    // At least about `CHUNKS_PER_THREAD` chunks a thread, so that a mesh of few large
    // triangles still spreads over the threads and the threads end close together.
    let size = n
        .div_ceil(threads * CHUNKS_PER_THREAD)
        .clamp(16, UNBINNED_CHUNK);
    let chunks = n.div_ceil(size);
    let threads = threads.min(chunks.max(1));
    // Threads start far apart in the mesh (see `SplitRange`).
    let queue = SplitRange::new(chunks, threads);
    let work = |me: usize| {
        let mut w = Worker::new(kernel, env, pass);
        let mut chunk = FlatChunk::default();
        let mut rejected = 0;
        while let Some(c) = queue.next(me) {
            prepared.setup_flat(c * size..(c + 1) * size, &mut chunk);
            rejected += chunk.rejected;
            // The chunk's setup records are this unit's planes.
            let chunk_env = PassEnv {
                tris: &chunk.tris,
                ..env.clone()
            };
            w.run_unit(&chunk, &chunk_env, None);
        }
        let (acc, counts) = w.finish();
        (acc, counts, rejected)
    };
    let (results, imbalance) = broadcast_timed(threads, work);
    let mut outcome = ShadeOutcome::default();
    let mut counts = FusedCounts::default();
    let mut rejected = 0;
    for (acc, c, r) in results {
        acc.finish(&mut outcome);
        counts.add(&c);
        rejected += r;
    }
    (outcome, counts, rejected, imbalance)
}

/// What the fragments of a unit of work share before shading: coverage masking and the
/// early tests (both loops of [`Worker::run_unit`] rasterize the same way).
struct RowSetup<'p> {
    pass: &'p FusedPass<'p>,
    /// The unit's setup records (planes), for the tests.
    tris: &'p [SetupTriangle],
    tests: bool,
    sample_mask: u8,
    all_samples: u8,
    per_sample_depth: bool,
    positions: &'static [(f32, f32)],
    width: u32,
    pixels: u64,
}

/// What the pixels of one span share.
struct Row<'p> {
    cov: u8,
    /// The setup record (planes), only for the tests: loading it per span cost a cache
    /// miss per triangle on large meshes.
    planes: Option<&'p SetupTriangle>,
    fy: f32,
    /// `seq` of the span's pixel 0: unique and increasing in API order (source triangle,
    /// then pixel). By source triangle, not setup index, so that ids do not depend on how
    /// setup was split among threads; unique because the fan pieces of a clipped
    /// triangle cover disjoint samples and, with several samples, are merged per pixel.
    row_seq: u64,
}

impl FusedPass<'_> {
    /// Depth or stencil tests run before shading.
    fn early_tests(&self) -> bool {
        self.early && (self.state.depth.test || self.state.stencil.enabled)
    }

    /// Depth or stencil tests run after shading.
    fn late_tests(&self) -> bool {
        !self.early && (self.state.depth.test || self.state.stencil.enabled)
    }

    /// Nothing per pixel around the kernel: no test before or after shading and no target
    /// to write, so a fragment is shaded and counted, nothing else (capture and counting
    /// passes).
    fn counting(&self) -> bool {
        !self.early_tests() && !self.late_tests() && self.targets == 0
    }
}

impl<'p> RowSetup<'p> {
    fn new<K>(worker: &Worker<'p, K>, env: &'p PassEnv<'p>) -> Self {
        let pass = worker.pass;
        RowSetup {
            pass,
            tris: env.tris,
            tests: pass.early_tests(),
            sample_mask: pass.state.sample_mask & worker.all_samples,
            all_samples: worker.all_samples,
            per_sample_depth: env.samples > 1 && !pass.single,
            positions: worker.positions,
            width: env.width,
            pixels: worker.pixels,
        }
    }

    /// The span's shared values (`None`: masked out); counts its fragments as generated.
    #[inline(always)]
    fn row(&self, span: &Span, counts: &mut FusedCounts) -> Option<Row<'p>> {
        let pass = self.pass;
        let cov = if pass.single && span.coverage & 1 != 0 {
            self.all_samples
        } else {
            span.coverage
        };
        let cov = cov & self.sample_mask;
        if cov == 0 {
            return None;
        }
        counts.generated += u64::from(span.x1 - span.x0);
        Some(Row {
            cov,
            planes: self.tests.then(|| &self.tris[span.tri as usize]),
            fy: span.y as f32,
            row_seq: pass
                .seq_base
                .wrapping_add(span.source as u64 * self.pixels)
                .wrapping_add(span.y as u64 * self.width as u64),
        })
    }
}

/// The tile of a unit of work that tests or writes targets (units without either have none).
fn tile_of<'a, 't>(tile: &'a mut Option<TileAccess<'t>>) -> &'a mut TileAccess<'t> {
    tile.as_mut()
        .expect("a pass with tests or targets runs tile by tile")
}

impl Row<'_> {
    /// The early tests of pixel `x`: its surviving coverage and centre depth, or `None`
    /// when they cull it. The depth is interpolated here only for the tests (NaN otherwise:
    /// `Frag::depth` does it on demand).
    #[inline(always)]
    fn early(
        &self,
        rows: &RowSetup<'_>,
        span: &Span,
        x: u32,
        tile: &mut Option<TileAccess<'_>>,
        counts: &mut FusedCounts,
    ) -> Option<(u8, f32)> {
        let Some(t) = self.planes else {
            return Some((self.cov, f32::NAN));
        };
        let fx = x as f32;
        let depth = t.depth_at(fx + 0.5, self.fy + 0.5);
        let mut depths = [depth; 8];
        if rows.per_sample_depth {
            for (s, p) in rows.positions.iter().enumerate() {
                depths[s] = t.depth_at(fx + p.0, self.fy + p.1);
            }
        }
        let tile = tile_of(tile);
        let (x0, y0) = (tile.tile().x0, tile.tile().y0);
        let cov = tile.test(
            rows.pass.state,
            (x - x0, span.y - y0),
            self.cov,
            &depths,
            span.front_facing,
        );
        if cov == 0 {
            counts.early_culled += 1;
            return None;
        }
        Some((cov, depth))
    }

    /// The invocation id of pixel `x`.
    #[inline(always)]
    fn seq(&self, x: u32) -> u64 {
        self.row_seq.wrapping_add(x as u64)
    }

    /// The input of pixel `x`.
    #[inline(always)]
    fn input(
        &self,
        rows: &RowSetup<'_>,
        span: &Span,
        x: u32,
        coverage: u8,
        depth: f32,
    ) -> FragInput {
        FragInput {
            seq: self.seq(x),
            x,
            y: span.y,
            tri: span.tri,
            primitive_id: span.source + rows.pass.first,
            instance_id: rows.pass.instance,
            coverage,
            front_facing: span.front_facing,
            depth,
            ticket: 0,
        }
    }
}

/// One worker thread's state: its warp of invocation slots and its tallies.
struct Worker<'a, K> {
    kernel: &'a K,
    pass: &'a FusedPass<'a>,
    slots: Vec<Invocation>,
    /// The current unit's covered runs, rasterized before any is shaded.
    spans: Vec<Span>,
    /// Slots `..filled` hold the fragments gathered for the next warp (API order).
    filled: usize,
    acc: Acc,
    counts: FusedCounts,
    /// Sample positions (pixel-relative) for per-sample depths.
    positions: &'static [(f32, f32)],
    all_samples: u8,
    pixels: u64,
    /// The kernel's per-pixel array, prefetched ahead of shading.
    pixel_array: Option<PixelArray>,
}

/// Covered runs ahead of the one being shaded whose per-pixel slots are prefetched: far
/// enough for a miss to the last-level cache to land (about a dozen fragments of a dense
/// mesh), near enough for the line to still be there.
const PREFETCH_SPANS: usize = 8;

impl<'a, K: FragmentKernel> Worker<'a, K> {
    fn new(kernel: &'a K, env: &PassEnv<'_>, pass: &'a FusedPass<'a>) -> Self {
        let lanes = pass.lanes.max(1);
        let samples = env.samples;
        Worker {
            kernel,
            pass,
            slots: (0..lanes).map(|_| Invocation::new()).collect(),
            spans: Vec::new(),
            filled: 0,
            acc: Acc::default(),
            counts: FusedCounts::default(),
            positions: SampleCount::from_count(samples)
                .map(|c| c.positions())
                .unwrap_or(&[(0.5, 0.5)]),
            all_samples: if samples >= 8 {
                0xff
            } else {
                (1u8 << samples) - 1
            },
            pixels: env.width as u64 * env.height as u64,
            pixel_array: kernel.info().pixel_array,
        }
    }

    /// The prefetcher of the kernel's per-pixel array (`None`: no hint, or no such buffer).
    fn prefetcher<'e>(&self, env: &PassEnv<'e>) -> Option<PixelPrefetcher<'e>> {
        self.pixel_array
            .and_then(|a| env.memory.pixel_prefetcher(a, env.width))
    }

    fn finish(mut self) -> (Acc, FusedCounts) {
        for slot in &self.slots {
            self.acc.add_ops(slot);
        }
        (self.acc, self.counts)
    }

    /// Rasterizes, tests, shades and writes one unit of work (a segment of a tile, or a
    /// chunk of unbinned triangles, whose setup records `env.tris` holds); hands the tile
    /// access back. `tile` is `None` only for units that neither test nor write targets.
    ///
    /// The unit is rasterized into [`Worker::spans`] first, then shaded: so the shading
    /// loops have one instantiation whatever the source, and the kernel one call site in
    /// each, which is what lets the compiler inline its state machine into the loop.
    fn run_unit<'t>(
        &mut self,
        src: &impl SpanSource,
        env: &PassEnv<'_>,
        tile: Option<TileAccess<'t>>,
    ) -> Option<TileAccess<'t>> {
        let mut buf = std::mem::take(&mut self.spans);
        let spans = src.spans(&mut buf);
        // Without lockstep (or with one lane) nothing interleaves inside a worker.
        let tile = if !self.pass.lockstep || self.slots.len() == 1 {
            if self.pass.counting() {
                self.run_unit_counting(spans, env);
                tile
            } else {
                self.run_unit_direct(spans, env, tile)
            }
        } else {
            self.run_unit_lockstep(spans, env, tile)
        };
        self.spans = buf;
        tile
    }

    /// [`Self::run_unit`] without lockstep: each fragment is shaded through
    /// [`DirectFrag`] as soon as it is rasterized and tested, runs to its end and is retired
    /// at once (API order holds), in one slot, with no warp to gather.
    #[inline(never)]
    fn run_unit_direct<'t>(
        &mut self,
        spans: &[Span],
        env: &PassEnv<'_>,
        mut tile: Option<TileAccess<'t>>,
    ) -> Option<TileAccess<'t>> {
        let rows = RowSetup::new(self, env);
        let ahead = self.prefetcher(env);
        let Worker {
            kernel,
            pass,
            slots,
            acc,
            counts,
            positions,
            ..
        } = self;
        let (kernel, pass, positions) = (*kernel, *pass, *positions);
        let late_tests = pass.late_tests();
        // Nothing to test or write after shading (passes with early tests and no target,
        // such as occlusion queries; those with no test at all take `run_unit_counting`).
        let count_only = !late_tests && pass.targets == 0;
        let slot = &slots[0];
        // The fragment's state, in registers (see `DirectState`); the slot takes colour
        // outputs and faults, and the state when the slot's path must see it.
        let state = DirectState::new();
        // Counts of the unit's invocations, added to the worker's once at the end.
        let mut tally = Tally::default();
        for (i, span) in spans.iter().enumerate() {
            prefetch_ahead(ahead.as_ref(), spans, i);
            let Some(row) = rows.row(span, counts) else {
                continue;
            };
            // The state holds the input of the span's previous pixel (`first`: not yet).
            let mut first = true;
            for x in span.x0..span.x1 {
                let Some((cov, depth)) = row.early(&rows, span, x, &mut tile, counts) else {
                    continue;
                };
                if first {
                    state.reset(row.input(&rows, span, x, cov, depth));
                    first = false;
                } else {
                    state.reset_next(row.seq(x), x, cov, depth);
                }
                // Colour outputs are read only by the late stage: a counting pass leaves
                // them (a load behind the previous fragment's lock) until the unit's end.
                if !count_only {
                    slot.clear_outputs();
                }
                shade_direct(kernel, slot, &state, env);
                if count_only && !slot.faulted() {
                    tally.add_direct(&state, samples_of(cov));
                } else {
                    // A fault to report, or late tests and target writes: the slot's path.
                    state.spill(slot);
                    if count_only {
                        acc.tally_one(&mut tally, slot, samples_of(cov));
                    } else {
                        late(pass, env, positions, acc, counts, slot, tile_of(&mut tile));
                    }
                }
            }
        }
        slot.clear_outputs();
        state.drain_ops(slot);
        acc.add_tally(tally);
        counts.samples_passed += tally.samples_passed;
        tile
    }

    /// [`Self::run_unit_direct`] for passes with nothing per pixel around the kernel: no
    /// test before shading, nothing to test or write after it (capture and counting passes,
    /// [`FusedPass::counting`]). Only what differs from pixel to pixel is set per fragment,
    /// and the loop holds nothing else, so its state stays in registers (in the general
    /// loop, the tests' code kept the fragment's state on the stack). Its prologue and
    /// epilogue repeat [`Self::run_unit_direct`]'s on purpose: with the epilogue in a shared
    /// inlined helper, LLVM allocated registers differently and the bunny's loop took 13 %
    /// more instructions (callgrind, 83.3 against 94.4 M).
    #[inline(never)]
    fn run_unit_counting(&mut self, spans: &[Span], env: &PassEnv<'_>) {
        let rows = RowSetup::new(self, env);
        let ahead = self.prefetcher(env);
        let Worker {
            kernel,
            slots,
            acc,
            counts,
            ..
        } = self;
        let kernel = *kernel;
        let slot = &slots[0];
        let state = DirectState::new();
        // The unit's tally, kept per span where it can be: per fragment only what the
        // kernel decides (steps, discard), so that the loop's state fits in registers.
        let mut tally = Tally::default();
        for (i, span) in spans.iter().enumerate() {
            prefetch_ahead(ahead.as_ref(), spans, i);
            let Some(row) = rows.row(span, counts) else {
                continue;
            };
            let samples = samples_of(row.cov);
            // Nothing culls: every pixel of the span is shaded, with the span's coverage
            // and no depth (`Frag::depth` interpolates it on demand).
            state.reset(row.input(&rows, span, span.x0, row.cov, f32::NAN));
            let discarded_before = tally.discarded;
            let mut faulted = 0u64;
            for x in span.x0..span.x1 {
                state.next_pixel(row.seq(x), x);
                shade_direct(kernel, slot, &state, env);
                if slot.faulted() {
                    // Counted by the slot's path. The input is rebuilt rather than copied
                    // from the state, so that what the kernel does not read of it need not
                    // be kept across the loop.
                    faulted += 1;
                    state.spill_results(slot, row.input(&rows, span, x, row.cov, f32::NAN));
                    acc.count(slot);
                } else {
                    let steps = state.steps.get();
                    tally.steps += steps;
                    tally.max_steps = tally.max_steps.max(steps);
                    tally.discarded += u64::from(state.discarded.get());
                }
            }
            let finished = u64::from(span.x1 - span.x0) - faulted;
            tally.shaded += finished;
            tally.samples_passed +=
                u64::from(samples) * (finished - (tally.discarded - discarded_before));
        }
        // Colour outputs are read only by the late stage, which these passes lack.
        slot.clear_outputs();
        state.drain_ops(slot);
        acc.add_tally(tally);
        counts.samples_passed += tally.samples_passed;
    }

    /// [`Self::run_unit`] with lockstep warps: fragments gather into a warp of slots,
    /// whose lanes take turns at every access ([`shade_lockstep`]).
    #[inline(never)]
    fn run_unit_lockstep<'t>(
        &mut self,
        spans: &[Span],
        env: &PassEnv<'_>,
        mut tile: Option<TileAccess<'t>>,
    ) -> Option<TileAccess<'t>> {
        let lanes = self.slots.len();
        let rows = RowSetup::new(self, env);
        let ahead = self.prefetcher(env);
        for (i, span) in spans.iter().enumerate() {
            prefetch_ahead(ahead.as_ref(), spans, i);
            let Some(row) = rows.row(span, &mut self.counts) else {
                continue;
            };
            for x in span.x0..span.x1 {
                let Some((cov, depth)) = row.early(&rows, span, x, &mut tile, &mut self.counts)
                else {
                    continue;
                };
                self.slots[self.filled].reset_direct(row.input(&rows, span, x, cov, depth));
                self.filled += 1;
                if self.filled == lanes {
                    self.flush(env, &mut tile);
                }
            }
        }
        self.flush(env, &mut tile);
        tile
    }

    /// Shades the gathered warp, then runs the late stage in API order.
    fn flush(&mut self, env: &PassEnv<'_>, tile: &mut Option<TileAccess<'_>>) {
        let n = self.filled;
        if n == 0 {
            return;
        }
        self.filled = 0;
        let slots = &self.slots[..n];
        // Only lockstep warps are gathered (see `run_unit`).
        debug_assert!(self.pass.lockstep);
        shade_lockstep(self.kernel, slots, env);
        let late_tests = self.pass.late_tests();
        if !late_tests && self.pass.targets == 0 {
            // Nothing to test or write (capture and counting passes): count them.
            self.counts.samples_passed += self.acc.count_passing(slots);
            return;
        }
        for slot in slots {
            late(
                self.pass,
                env,
                self.positions,
                &mut self.acc,
                &mut self.counts,
                slot,
                tile_of(tile),
            );
        }
    }
}

/// Prefetches the per-pixel slot of the first pixel of the covered run
/// [`PREFETCH_SPANS`] after run `i` (runs are short on dense meshes, and the hardware
/// prefetcher follows a long one).
#[inline(always)]
fn prefetch_ahead(ahead: Option<&PixelPrefetcher<'_>>, spans: &[Span], i: usize) {
    if let (Some(p), Some(s)) = (ahead, spans.get(i + PREFETCH_SPANS)) {
        p.pixel(s.x0, s.y);
    }
}

/// Shades `slots` with their lanes in lockstep: every lane takes one step per turn (see
/// `Access::poll`). A panic ends the lane that raised it and the turns go on.
fn shade_lockstep<K: FragmentKernel>(kernel: &K, slots: &[Invocation], env: &PassEnv<'_>) {
    let n = slots.len();
    let mut cx = Context::from_waker(Waker::noop());
    // Interlock is not used on this path, so the kernel is the whole invocation.
    let mut futs: Vec<Option<_>> = slots
        .iter()
        .map(|slot| Some(kernel.shade(Frag { inv: slot, env })))
        .collect();
    let mut left = n;
    // Next lane to poll in the current round. One `catch_unwind` covers many polls; a
    // panic ends the lane being polled (`lane - 1`) and the rounds go on after it.
    let mut lane = 0;
    while left > 0 {
        let rounds = catch_unwind(AssertUnwindSafe(|| loop {
            while lane < n {
                let i = lane;
                lane += 1;
                let Some(fut) = futs[i].as_mut() else {
                    continue;
                };
                // SAFETY: the futures live in `futs`, which is not resized or moved until
                // every one of them is dropped in place (`= None`), so a future is never
                // moved after this pin.
                let pinned = unsafe { Pin::new_unchecked(fut) };
                let done = match pinned.poll(&mut cx) {
                    Poll::Ready(()) => true,
                    Poll::Pending => slots[i].faulted(),
                };
                if done {
                    futs[i] = None;
                    left -= 1;
                }
            }
            if left == 0 {
                break;
            }
            lane = 0;
        }));
        if let Err(payload) = rounds {
            let i = lane - 1;
            record_panic(&slots[i], payload.as_ref());
            futs[i] = None;
            left -= 1;
        }
    }
}

/// Shades one invocation to its end through [`DirectFrag`] (no lockstep: an access never
/// suspends, so the kernel's state machine folds into this loop). A panic ends it.
#[inline(always)]
fn shade_direct<'a, K: FragmentKernel>(
    kernel: &K,
    inv: &'a Invocation,
    state: &'a DirectState<'a>,
    env: &'a PassEnv<'a>,
) {
    debug_assert!(matches!(env.mode, Mode::Direct { .. }));
    // `DirectFrag` counts no contention: passes that keep the table take the general path.
    debug_assert!(env.contention.is_none());
    let r = catch_unwind(AssertUnwindSafe(|| {
        let mut cx = Context::from_waker(Waker::noop());
        // Interlock is not used on this path, so the kernel is the whole invocation.
        let frag = DirectFrag::new(Frag { inv, env }, state);
        // One poll: under `DirectFrag` nothing suspends, and an invocation is pending
        // only once it has faulted (it is then dropped).
        let pending = std::pin::pin!(kernel.shade(frag))
            .poll(&mut cx)
            .is_pending();
        if pending && !inv.faulted() {
            pending_without_fault(inv);
        }
    }));
    if let Err(payload) = r {
        record_panic(inv, payload.as_ref());
    }
}

/// A kernel under `DirectFrag` returned `Pending` with no fault: a future that is not the
/// kernel API's suspended it (an invocation cannot wait on anything else).
#[cold]
#[inline(never)]
fn pending_without_fault(inv: &Invocation) {
    inv.set_fault(crate::kernel::FaultKind::Misuse {
        message: "the kernel awaited a future that is not a kernel API access, and it did \
                  not complete"
            .into(),
    });
}

/// Counts a shaded fragment and runs its late tests and target writes.
#[inline]
fn late(
    pass: &FusedPass<'_>,
    env: &PassEnv<'_>,
    positions: &[(f32, f32)],
    acc: &mut Acc,
    counts: &mut FusedCounts,
    slot: &Invocation,
    tile: &mut TileAccess<'_>,
) {
    let faulted = acc.count(slot);
    if faulted || slot.discarded.get() {
        return;
    }
    let state = pass.state;
    let late_tests = pass.late_tests();
    let f = slot.input.get();
    let (lx, ly) = (f.x - tile.tile().x0, f.y - tile.tile().y0);
    let mut mask = f.coverage;
    if late_tests {
        let centre = || {
            let t = &env.tris[f.tri as usize];
            t.depth_at(f.x as f32 + 0.5, f.y as f32 + 0.5)
        };
        let mut depths = [slot.depth_out.get().unwrap_or_else(centre); 8];
        if slot.depth_out.get().is_none() && env.samples > 1 && !pass.single {
            let t = &env.tris[f.tri as usize];
            for (s, p) in positions.iter().enumerate() {
                depths[s] = t.depth_at(f.x as f32 + p.0, f.y as f32 + p.1);
            }
        }
        mask = tile.test(state, (lx, ly), mask, &depths, f.front_facing);
        if mask == 0 {
            counts.late_culled += 1;
            return;
        }
    }
    counts.samples_passed += mask.count_ones() as u64;
    if pass.targets > 0 {
        if let TileAccess::Exclusive(t) = tile {
            let mut colors = [[0u32; 4]; 8];
            for (c, o) in colors.iter_mut().zip(&slot.outputs).take(pass.targets) {
                *c = o.get();
            }
            t.write_outputs(state, lx, ly, mask, &colors[..pass.targets]);
        }
    }
}

/// Covered samples in a coverage mask (`count_ones` without `popcnt`, which the baseline
/// x86-64 target lacks: a table lookup rather than a dozen bit operations per fragment).
#[inline(always)]
fn samples_of(coverage: u8) -> u8 {
    const TABLE: [u8; 256] = {
        let mut t = [0u8; 256];
        let mut i = 0;
        while i < 256 {
            t[i] = (i as u8).count_ones() as u8;
            i += 1;
        }
        t
    };
    TABLE[coverage as usize]
}
