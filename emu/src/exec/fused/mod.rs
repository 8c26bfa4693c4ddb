//! The fused path of the `ordered` and `parallel` executors: rasterize, test, shade and
//! write one unit of tile work at a time, with no per-pass fragment lists.
//!
//! The general path (`crate::pipeline` (`run_waves`)) materializes every fragment of a wave
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
//! Interlock runs here by ownership, without lockstep: a binned pass's tile belongs to one
//! worker, which shades its fragments one at a time to their end in API order, so each
//! pixel's critical sections are entered alone and in order with no lock (a GPU orders a
//! pixel's fragments the same way, by the tile's owner). Lockstep warps interleave the
//! fragments of a pixel, so interlock with lockstep takes the general path and its
//! per-pixel tickets (`crate::pipeline`), as does the contention table.
//!
//! This module knows no algorithm.

use std::time::{Duration, Instant};

use crate::exec::{Acc, ShadeOutcome};
use crate::framebuffer::TileMemory;
use crate::invocation::PassEnv;
use crate::kernel::{FragInput, FragmentKernel};
use crate::pipeline::{BlockMask, BLOCK_SHIFT};
use crate::raster::{Binned, FlatChunk, Prepared, Segment, SetupTriangle, Span};
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
    /// The depth of fragments without a setup record: NaN for rasterized ones (nothing
    /// reads it: `Fragment::depth` interpolates their triangle's plane), 0.5 in full-screen
    /// passes (their fragments' depth).
    pub flat_depth: f32,
    /// Geometry passes: the screen blocks their covered runs mark. Full-screen passes:
    /// the blocks no geometry reached, whose pixels get `untouched_output` without running
    /// the kernel (both set, or no skipping).
    pub touched: Option<&'a BlockMask>,
    /// What the kernel declared it writes to target 0 at an untouched pixel
    /// (`KernelInfo::untouched_output`).
    pub untouched_output: Option<[u32; 4]>,
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

/// The pixels of one tile in a full-screen pass: a span per row, every sample covered, no
/// setup record (`tri` = `u32::MAX`), primitive 0, front facing (as the general path's
/// full-screen fragments).
struct FullScreenSpans<'m> {
    x0: u32,
    y0: u32,
    w: u32,
    h: u32,
    coverage: u8,
    /// Only the pixels of blocks this mask marks (the others are skipped:
    /// `Worker::skip_untouched`).
    touched: Option<&'m BlockMask>,
}

impl SpanSource for FullScreenSpans<'_> {
    fn spans<'s>(&'s self, buf: &'s mut Vec<Span>) -> &'s [Span] {
        buf.clear();
        let span = |y, x0, x1| Span {
            y,
            x0,
            x1,
            tri: u32::MAX,
            coverage: self.coverage,
            source: 0,
            front_facing: true,
        };
        for y in self.y0..self.y0 + self.h {
            let Some(mask) = self.touched else {
                buf.push(span(y, self.x0, self.x0 + self.w));
                continue;
            };
            let mut lx = 0;
            while lx < self.w {
                let end = worker::block_end(self.x0, lx, self.w);
                if mask.touched((self.x0 + lx) >> BLOCK_SHIFT, y >> BLOCK_SHIFT) {
                    // Touched runs next to each other make one span.
                    match buf.last_mut() {
                        Some(last) if last.y == y && last.x1 == self.x0 + lx => {
                            last.x1 = self.x0 + end
                        }
                        _ => buf.push(span(y, self.x0 + lx, self.x0 + end)),
                    }
                }
                lx = end;
            }
        }
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
    /// Full-screen invocations not run (their block untouched: `FusedPass::touched`).
    pub skipped: u64,
}

impl FusedCounts {
    /// Adds these counts to a pass's statistics.
    pub fn add_to(&self, stats: &mut crate::stats::Stats) {
        stats.fragments_generated += self.generated;
        stats.early_culled += self.early_culled;
        stats.late_culled += self.late_culled;
        stats.samples_passed += self.samples_passed;
        stats.skipped += self.skipped;
    }

    fn add(&mut self, o: &FusedCounts) {
        self.generated += o.generated;
        self.early_culled += o.early_culled;
        self.late_culled += o.late_culled;
        self.samples_passed += o.samples_passed;
        self.skipped += o.skipped;
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
            let slots = TileSlots::new(tiles);
            let queue = SplitRange::new(count, threads);
            let work = |me: usize| {
                let mut w = Worker::new(kernel, env, pass);
                let mut segs = Vec::new();
                while let Some(index) = queue.next(me) {
                    let Some(tile) = slots.take(index) else {
                        continue;
                    };
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

/// Whether a full-screen pass with `state` runs on the fused path: nothing tests a depth
/// or stencil before or after shading (its fragments have no setup record for the tests to
/// read; the general path tests them at depth 0.5), and the sample mask leaves some of the
/// `samples` samples covered.
pub(crate) fn fullscreen_fuses(state: &FragmentState, samples: u32) -> bool {
    !state.depth.test && !state.stencil.enabled && state.sample_mask & all_samples(samples) != 0
}

/// The coverage mask of every sample of a pixel with `samples` samples.
fn all_samples(samples: u32) -> u8 {
    if samples >= 8 {
        0xff
    } else {
        (1u8 << samples) - 1
    }
}

/// Runs a full-screen pass on the fused path ([`fullscreen_fuses`]): every pixel of every
/// tile, tiles handed out to the threads as in [`run_fused`] (one tile per worker at a
/// time, so target writes need no lock), the pixels of a tile row by row.
#[inline(never)]
pub(crate) fn run_fullscreen<K: FragmentKernel>(
    kernel: &K,
    env: &PassEnv<'_>,
    pass: &FusedPass<'_>,
    tiles: &mut [TileMemory],
) -> (ShadeOutcome, FusedCounts, Duration) {
    debug_assert!(fullscreen_fuses(pass.state, env.samples) && env.tris.is_empty());
    let count = tiles.len();
    let threads = pass.threads.max(1).min(count.max(1));
    let coverage = all_samples(env.samples);
    let slots = TileSlots::new(tiles);
    let queue = SplitRange::new(count, threads);
    let work = |me: usize| {
        let mut w = Worker::new(kernel, env, pass);
        while let Some(index) = queue.next(me) {
            let Some(tile) = slots.take(index) else {
                continue;
            };
            fullscreen_tile(&mut w, tile, env, coverage);
        }
        w.finish()
    };
    let (results, imbalance) = broadcast_timed(threads, work);
    let mut outcome = ShadeOutcome::default();
    let mut counts = FusedCounts::default();
    for (acc, c) in results {
        acc.finish(&mut outcome);
        counts.add(&c);
    }
    // Full-screen invocations are not rasterized fragments: not counted as generated.
    counts.generated = 0;
    (outcome, counts, imbalance)
}

/// The full-screen invocations of one tile, `coverage` at every pixel: the per-pixel loop
/// without lockstep, lockstep warps otherwise (after the untouched blocks' declared output).
fn fullscreen_tile<K: FragmentKernel>(
    w: &mut Worker<'_, K>,
    tile: &mut TileMemory,
    env: &PassEnv<'_>,
    coverage: u8,
) {
    let pass = w.pass;
    if !pass.lockstep || pass.lanes <= 1 {
        w.run_tile_fullscreen(tile, env, coverage);
        return;
    }
    let skip = pass.touched.zip(pass.untouched_output);
    if let Some((mask, bits)) = skip {
        w.skip_untouched(tile, mask, bits, coverage);
    }
    let src = FullScreenSpans {
        x0: tile.x0,
        y0: tile.y0,
        w: tile.w,
        h: tile.h,
        coverage,
        touched: skip.map(|(mask, _)| mask),
    };
    w.run_unit(&src, env, Some(TileAccess::Exclusive(tile)));
}

/// One pass of [`run_by_region`]: its kernel, environment and fused-pass description.
pub(crate) struct RegionPass<'a, K> {
    pub kernel: &'a K,
    pub env: &'a PassEnv<'a>,
    pub pass: &'a FusedPass<'a>,
}

/// What each pass of [`run_by_region`] did: its outcome and counts, and the time the
/// workers spent in it (summed over workers).
pub(crate) struct RegionResult {
    pub outcome: ShadeOutcome,
    pub counts: FusedCounts,
    pub busy: Duration,
}

/// Runs a geometry pass (`geo`, binned into `binned`) and a full-screen pass (`fs`) whose
/// kernel reads by region (`KernelInfo::by_region`) tile by tile: a worker takes a tile,
/// runs the geometry pass's units of that tile in API order ([`run_fused`] with one worker
/// per tile), then the full-screen invocations of that tile ([`run_fullscreen`]), so the
/// words the tile's fragments wrote are still in the worker's cache when its full-screen
/// invocations read them (a tiled GPU's subpass with a by-region dependency). Each pass
/// sees the same invocations, ids, counts and target writes as when run alone; only the
/// interleaving of the two passes' invocations of different tiles differs. Returns the two
/// passes' results and the threads' imbalance at the end.
#[inline(never)]
pub(crate) fn run_by_region<G: FragmentKernel, R: FragmentKernel>(
    geo: RegionPass<'_, G>,
    binned: &Binned,
    fs: RegionPass<'_, R>,
    tiles: &mut [TileMemory],
) -> (RegionResult, RegionResult, Duration) {
    debug_assert!(geo.pass.segment.is_none());
    debug_assert!(!geo.pass.state.depth.test && !geo.pass.state.stencil.enabled);
    debug_assert!(fullscreen_fuses(fs.pass.state, fs.env.samples) && fs.env.tris.is_empty());
    let count = tiles.len();
    let threads = geo.pass.threads.max(1).min(count.max(1));
    let coverage = all_samples(fs.env.samples);
    let slots = TileSlots::new(tiles);
    let queue = SplitRange::new(count, threads);
    let work = |me: usize| {
        let mut g = Worker::new(geo.kernel, geo.env, geo.pass);
        let mut r = Worker::new(fs.kernel, fs.env, fs.pass);
        let mut segs = Vec::new();
        let (mut g_busy, mut r_busy) = (Duration::ZERO, Duration::ZERO);
        while let Some(index) = queue.next(me) {
            let Some(tile) = slots.take(index) else {
                continue;
            };
            let start = Instant::now();
            segs.clear();
            binned.tile_segments(index, EXCLUSIVE_UNIT, &mut segs);
            let mut access = Some(TileAccess::Exclusive(tile));
            for &seg in &segs {
                access = g.run_unit(&SegmentSpans { binned, seg }, geo.env, access);
            }
            let Some(TileAccess::Exclusive(tile)) = access else {
                unreachable!("a geometry unit hands its exclusive tile back")
            };
            let mid = Instant::now();
            fullscreen_tile(&mut r, tile, fs.env, coverage);
            g_busy += mid - start;
            r_busy += mid.elapsed();
        }
        (g.finish(), r.finish(), g_busy, r_busy)
    };
    let (results, imbalance) = broadcast_timed(threads, work);
    let empty = || RegionResult {
        outcome: ShadeOutcome::default(),
        counts: FusedCounts::default(),
        busy: Duration::ZERO,
    };
    let (mut g, mut r) = (empty(), empty());
    for ((g_acc, g_counts), (r_acc, r_counts), g_busy, r_busy) in results {
        g_acc.finish(&mut g.outcome);
        g.counts.add(&g_counts);
        g.busy += g_busy;
        r_acc.finish(&mut r.outcome);
        r.counts.add(&r_counts);
        r.busy += r_busy;
    }
    // Full-screen invocations are not rasterized fragments: not counted as generated.
    r.counts.generated = 0;
    (g, r, imbalance)
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

    /// The mask a geometry pass marks (full-screen passes only read theirs).
    fn marks(&self) -> Option<&BlockMask> {
        self.touched.filter(|_| self.untouched_output.is_none())
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
            return Some((self.cov, rows.pass.flat_depth));
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

mod ahead;
mod worker;

use worker::Worker;
pub(crate) use worker::{block_end, Untouched};

/// The tiles of an exclusive pass, each handed out once to the worker that takes its
/// index (`SplitRange`): a tile's lock is never contended, it only moves the `&mut` to
/// that worker's thread.
struct TileSlots<'t>(Vec<pool::Mutex<Option<&'t mut TileMemory>>>);

impl<'t> TileSlots<'t> {
    fn new(tiles: &'t mut [TileMemory]) -> Self {
        TileSlots(
            tiles
                .iter_mut()
                .map(|t| pool::Mutex::new(Some(t)))
                .collect(),
        )
    }

    /// Tile `index`, the first time it is asked for.
    fn take(&self, index: usize) -> Option<&'t mut TileMemory> {
        self.0[index]
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take()
    }
}
