//! A worker of the fused path: shades the warps of its units of work (lanes in lockstep, one
//! after the other, or through the counting loop of unbinned passes without lockstep) and
//! runs their late tests and target writes.

use std::future::Future;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::pin::Pin;
use std::task::{Context, Poll, Waker};

use crate::exec::{record_panic, Acc, Tally};
use crate::framebuffer::TileMemory;
use crate::invocation::{
    DirectCtx, DirectFrag, DirectState, Frag, Halted, Invocation, Mode, PassEnv,
};
use crate::kernel::{FragInput, FragmentKernel};
use crate::memory::{BlockArray, PixelArray};
use crate::pipeline::{BlockMask, BLOCK_SHIFT};
use crate::raster::{SampleCount, Span};

use super::ahead::{prefetch_ahead, Ahead};
use super::{tile_of, FusedCounts, FusedPass, RowSetup, SpanSource, TileAccess};

/// One worker thread's state: its warp of invocation slots and its tallies.
pub(super) struct Worker<'a, K> {
    kernel: &'a K,
    pub(super) pass: &'a FusedPass<'a>,
    slots: Vec<Invocation>,
    /// The current unit's covered runs, rasterized before any is shaded.
    spans: Vec<Span>,
    /// Slots `..filled` hold the fragments gathered for the next warp (API order).
    filled: usize,
    acc: Acc,
    counts: FusedCounts,
    /// Sample positions (pixel-relative) for per-sample depths.
    pub(super) positions: &'static [(f32, f32)],
    pub(super) all_samples: u8,
    pub(super) pixels: u64,
    /// The kernel's per-pixel array, prefetched ahead of shading.
    pixel_array: Option<PixelArray>,
    /// The same array when the kernel declared it its pixels' own
    /// (`KernelInfo::with_own_pixel_array`): on a tile this worker owns, its atomics there
    /// are plain (`DirectState::owning`).
    own_array: Option<PixelArray>,
    /// The kernel's own per-block array (`KernelInfo::with_own_block_array`): plain there
    /// too on an owned tile that holds whole blocks.
    own_block: Option<BlockArray>,
}

impl<'a, K: FragmentKernel> Worker<'a, K> {
    pub(super) fn new(kernel: &'a K, env: &PassEnv<'_>, pass: &'a FusedPass<'a>) -> Self {
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
            own_array: Some(kernel.info())
                .filter(|info| info.pixel_array_own)
                .and_then(|info| info.pixel_array),
            own_block: kernel.info().own_block_array,
        }
    }

    /// What the shading loops prefetch ahead (`Ahead`).
    fn prefetcher<'e>(&self, env: &PassEnv<'e>) -> Ahead<'e> {
        Ahead::of(self.pixel_array, env)
    }

    pub(super) fn finish(mut self) -> (Acc, FusedCounts) {
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
    pub(super) fn run_unit<'t>(
        &mut self,
        src: &impl SpanSource,
        env: &PassEnv<'_>,
        tile: Option<TileAccess<'t>>,
    ) -> Option<TileAccess<'t>> {
        let mut buf = std::mem::take(&mut self.spans);
        let spans = src.spans(&mut buf);
        if let Some(mask) = self.pass.marks() {
            for s in spans {
                mask.mark_run(s.y, s.x0, s.x1);
            }
        }
        // Without lockstep (or with one lane) nothing interleaves inside a worker.
        let tile = if !self.pass.lockstep || self.slots.len() == 1 {
            if self.pass.counting() {
                // A tile held exclusively is this worker's for the whole pass (segments
                // share tiles; unbinned chunks have none).
                let owned = match &tile {
                    Some(TileAccess::Exclusive(t)) => Some(t.tile_size),
                    _ => None,
                };
                // A block lies in one tile when it is no larger (both are powers of two
                // from the origin).
                let block = self.own_block.filter(|b| {
                    owned.is_some_and(|size| b.shift < 32 && 1u64 << b.shift <= u64::from(size))
                });
                if owned.is_some() && (self.own_array.is_some() || block.is_some()) {
                    self.run_unit_counting::<true>(spans, env, block);
                } else {
                    self.run_unit_counting::<false>(spans, env, None);
                }
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
        let state = DirectState::new(env.memory);
        // Counts of the unit's invocations, added to the worker's once at the end.
        let mut tally = Tally::default();
        for (i, span) in spans.iter().enumerate() {
            prefetch_ahead(&ahead, spans, i);
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
                shade_direct::<K, false>(kernel, slot, &state, env);
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
    ///
    /// `OWN`: the worker owns the unit's tile for the whole pass, and the kernel declared
    /// its per-pixel array its pixels' own, or `own_block` (its per-block array, whose
    /// blocks lie in the tile): atomics on the fragment's slot are plain
    /// (`DirectState::owning`). A constant, so that without it the loop stays as it was.
    #[inline(never)]
    fn run_unit_counting<const OWN: bool>(
        &mut self,
        spans: &[Span],
        env: &PassEnv<'_>,
        own_block: Option<BlockArray>,
    ) {
        let rows = RowSetup::new(self, env);
        let ahead = self.prefetcher(env);
        let own = self.own_array;
        let Worker {
            kernel,
            slots,
            acc,
            counts,
            ..
        } = self;
        let kernel = *kernel;
        let slot = &slots[0];
        let state = if OWN {
            DirectState::owning(env.memory, own, own_block, env.width)
        } else {
            DirectState::new(env.memory)
        };
        // The unit's tally, kept per span where it can be: per fragment only what the
        // kernel decides (steps, discard), so that the loop's state fits in registers.
        let mut tally = Tally::default();
        for (i, span) in spans.iter().enumerate() {
            prefetch_ahead(&ahead, spans, i);
            let Some(row) = rows.row(span, counts) else {
                continue;
            };
            let samples = samples_of(row.cov);
            // Nothing culls: every pixel of the span is shaded, with the span's coverage
            // and no depth (`Frag::depth` interpolates it on demand; full-screen passes
            // have a flat one).
            let depth = rows.pass.flat_depth;
            state.reset(row.input(&rows, span, span.x0, row.cov, depth));
            let discarded_before = tally.discarded;
            let mut faulted = 0u64;
            for x in span.x0..span.x1 {
                state.next_pixel(row.seq(x), x);
                shade_direct::<K, OWN>(kernel, slot, &state, env);
                if slot.faulted() {
                    // Counted by the slot's path. The input is rebuilt rather than copied
                    // from the state, so that what the kernel does not read of it need not
                    // be kept across the loop.
                    faulted += 1;
                    state.spill_results(slot, row.input(&rows, span, x, row.cov, depth));
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

    /// One tile of a full-screen pass without lockstep ([`super::run_fullscreen`]): every
    /// pixel, row by row, shaded through [`DirectFrag`] and its outputs written to the tile
    /// as soon as it retires. What [`Self::run_unit_direct`] does with such a tile (nothing
    /// tests before or after shading: [`super::fullscreen_fuses`]), without the span list,
    /// the per-pixel copy of the input into the slot and the general late stage: a
    /// resolve's empty pixels (most of a frame) cost their kernel and one texel write.
    /// Same invocations, ids, counts, faults and target writes, in the same order.
    #[inline(never)]
    pub(super) fn run_tile_fullscreen(
        &mut self,
        tile: &mut TileMemory,
        env: &PassEnv<'_>,
        coverage: u8,
    ) {
        let Worker {
            kernel,
            pass,
            slots,
            acc,
            counts,
            all_samples,
            ..
        } = self;
        let (kernel, pass) = (*kernel, *pass);
        debug_assert!(!pass.lockstep || slots.len() == 1);
        debug_assert!(!pass.early_tests() && !pass.late_tests());
        // Every pixel's coverage: the span's of `run_unit_direct` (`RowSetup::row`).
        let cov = coverage & pass.state.sample_mask & *all_samples;
        if cov == 0 {
            tile.clear_pending_color();
            return;
        }
        // Blocks no geometry reached: their pixels get the kernel's declared output.
        let skip = pass.touched.zip(pass.untouched_output);
        if let Some((mask, bits)) = skip {
            let untouched = Untouched {
                state: pass.state,
                cov,
                bits,
                targets: pass.targets.min(8),
            };
            if untouched.fast_clear(tile, mask, counts) {
                return;
            }
        }
        // A pending clear (planes an earlier framebuffer left, or a fast clear) is done
        // row by row just ahead of the row's writes (`TileMemory::color_fill`), by this
        // thread, in cache.
        let unclear = tile.take_pending_color();
        let samples = samples_of(cov);
        let targets = pass.targets.min(8);
        // One sample, every target written plainly (a resolve): the output's bits go
        // straight to the texel ([`TileMemory::write_outputs`] computes the same).
        let plain = tile.samples == 1
            && cov == 1
            && pass.state.targets[..targets]
                .iter()
                .all(|t| t.plain_write());
        let slot = &slots[0];
        let state = DirectState::new(env.memory);
        let mut tally = Tally::default();
        let (x0, y0) = (tile.x0, tile.y0);
        for ly in 0..tile.h {
            if let Some(v) = unclear {
                tile.clear_color_row(ly, v);
            }
            let y = y0 + ly;
            // Full-screen ids are by pixel, row-major (`Row::row_seq` with source 0).
            let row_seq = pass.seq_base.wrapping_add(y as u64 * env.width as u64);
            state.reset(FragInput {
                seq: row_seq.wrapping_add(x0 as u64),
                x: x0,
                y,
                tri: u32::MAX,
                primitive_id: pass.first,
                instance_id: pass.instance,
                coverage: cov,
                front_facing: true,
                depth: pass.flat_depth,
                ticket: 0,
            });
            let mut lx = 0;
            while lx < tile.w {
                // The pixels up to the next block boundary: skipped together or shaded.
                let end = block_end(x0, lx, tile.w);
                if let Some((mask, bits)) = skip {
                    if !mask.touched((x0 + lx) >> BLOCK_SHIFT, y >> BLOCK_SHIFT) {
                        let untouched = Untouched {
                            state: pass.state,
                            cov,
                            bits,
                            targets,
                        };
                        untouched.skip_run(tile, ly, lx..end, counts);
                        lx = end;
                        continue;
                    }
                }
                let run = lx..end;
                lx = end;
                for lx in run {
                    let x = x0 + lx;
                    state.next_pixel(row_seq.wrapping_add(x as u64), x);
                    slot.clear_outputs();
                    shade_direct::<K, false>(kernel, slot, &state, env);
                    if slot.faulted() {
                        // Counted (and its fault kept) by the slot's path; nothing is written.
                        state.spill(slot);
                        acc.count(slot);
                        continue;
                    }
                    tally.add_direct(&state, samples);
                    if state.discarded.get() || targets == 0 {
                        continue;
                    }
                    if plain {
                        let at = (ly * tile.tile_size + lx) as usize;
                        for (plane, o) in tile.color.iter_mut().zip(&slot.outputs).take(targets) {
                            plane[at] = o.get();
                        }
                        continue;
                    }
                    let mut colors = [[0u32; 4]; 8];
                    for (c, o) in colors.iter_mut().zip(&slot.outputs).take(targets) {
                        *c = o.get();
                    }
                    tile.write_outputs(pass.state, lx, ly, cov, &colors[..targets]);
                }
            }
        }
        if let Some(v) = unclear {
            // The padding rows of an edge tile (never written, but the planes' values).
            for ly in tile.h..tile.tile_size {
                tile.clear_color_row(ly, v);
            }
        }
        slot.clear_outputs();
        state.drain_ops(slot);
        acc.add_tally(tally);
        counts.samples_passed += tally.samples_passed;
    }

    /// Writes the declared output of a full-screen kernel to the pixels of `tile` in blocks
    /// no geometry reached (`mask`), and counts them as skipped; the lockstep path then
    /// shades the rest ([`super::FullScreenSpans`] with the same mask).
    pub(super) fn skip_untouched(
        &mut self,
        tile: &mut TileMemory,
        mask: &BlockMask,
        bits: [u32; 4],
        coverage: u8,
    ) {
        let pass = self.pass;
        let cov = coverage & pass.state.sample_mask & self.all_samples;
        if cov == 0 {
            return;
        }
        let untouched = Untouched {
            state: pass.state,
            cov,
            bits,
            targets: pass.targets.min(8),
        };
        if untouched.fast_clear(tile, mask, &mut self.counts) {
            return;
        }
        for ly in 0..tile.h {
            let y = tile.y0 + ly;
            let mut lx = 0;
            while lx < tile.w {
                let end = block_end(tile.x0, lx, tile.w);
                if !mask.touched((tile.x0 + lx) >> BLOCK_SHIFT, y >> BLOCK_SHIFT) {
                    untouched.skip_run(tile, ly, lx..end, &mut self.counts);
                }
                lx = end;
            }
        }
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
            prefetch_ahead(&ahead, spans, i);
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
fn shade_direct<'a, K: FragmentKernel, const OWN: bool>(
    kernel: &K,
    inv: &'a Invocation,
    state: &'a DirectState<'a>,
    env: &'a PassEnv<'a>,
) {
    debug_assert!(matches!(env.mode, Mode::Direct { .. }));
    // `DirectFrag` counts no contention: passes that keep the table take the general path.
    debug_assert!(env.contention.is_none());
    if env.interlock_mode.is_some() {
        inv.reset_interlock();
    }
    let r = catch_unwind(AssertUnwindSafe(|| {
        let mut cx = Context::from_waker(Waker::noop());
        // Interlock here is by ownership (no lock to leave, no turn to pass: `PassEnv::
        // interlock`), so the kernel is the whole invocation.
        let ctx = DirectCtx {
            frag: Frag { inv, env },
            state,
        };
        let frag = DirectFrag::<OWN>::new(&ctx);
        // One poll: under `DirectFrag` nothing suspends, and an invocation that faults
        // leaves its kernel by unwinding (`Halted`). Pending here is a future that is not
        // the kernel API's, or the general context's halt after a misuse of the interlock.
        let pending = std::pin::pin!(kernel.shade(frag))
            .poll(&mut cx)
            .is_pending();
        if pending && !inv.faulted() {
            pending_without_fault(inv);
        }
    }));
    if let Err(payload) = r {
        // An invocation that faulted (its fault recorded) left its kernel: nothing more.
        if !payload.is::<Halted>() {
            record_panic(inv, payload.as_ref());
        }
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

/// The end (tile-relative, exclusive) of the run of pixels from `lx` to the next block
/// boundary of the touched mask (or the tile's end).
#[inline(always)]
pub(crate) fn block_end(x0: u32, lx: u32, w: u32) -> u32 {
    let x = x0 + lx;
    ((((x >> BLOCK_SHIFT) + 1) << BLOCK_SHIFT) - x0).min(w)
}

/// What a full-screen pass does at the pixels of blocks no geometry reached, instead of
/// running its kernel there: the kernel's declared output ([`crate::kernel::KernelInfo`]'s
/// untouched output, target 0) written as the invocations' target writes would.
#[derive(Clone, Copy)]
pub(crate) struct Untouched<'s> {
    pub(crate) state: &'s crate::state::FragmentState,
    /// Every pixel's coverage (the pass's, as its invocations would have had).
    pub(crate) cov: u8,
    pub(crate) bits: [u32; 4],
    pub(crate) targets: usize,
}

impl Untouched<'_> {
    /// The untouched step for a whole tile no geometry reached (no block of `mask`), when
    /// its one colour plane takes the declared bits as they are (one sample, every sample
    /// covered, a plain write): a fast clear of the tile to them
    /// ([`TileMemory::fast_clear`]), which writes nothing until the tile is next written or
    /// read back, counted as [`Self::skip_run`] counts its pixels. What a resolve does at
    /// the empty tiles of a frame (three in four of the bunny's at 2048 x 2048). False,
    /// with nothing done, otherwise.
    pub(crate) fn fast_clear(
        &self,
        tile: &mut TileMemory,
        mask: &BlockMask,
        counts: &mut FusedCounts,
    ) -> bool {
        if !(self.targets == 1
            && tile.color.len() == 1
            && tile.samples == 1
            && self.cov == 1
            && self.state.targets[0].plain_write())
        {
            return false;
        }
        let (bx0, bx1) = (
            tile.x0 >> BLOCK_SHIFT,
            (tile.x0 + tile.w - 1) >> BLOCK_SHIFT,
        );
        let (by0, by1) = (
            tile.y0 >> BLOCK_SHIFT,
            (tile.y0 + tile.h - 1) >> BLOCK_SHIFT,
        );
        if (by0..=by1).any(|by| (bx0..=bx1).any(|bx| mask.touched(bx, by))) {
            return false;
        }
        let n = u64::from(tile.w) * u64::from(tile.h);
        counts.skipped += n;
        counts.samples_passed += n;
        tile.fast_clear(self.bits);
        true
    }

    /// The untouched-run step: writes the declared bits to the pixels `run` of row `ly` of
    /// `tile`, counts them as skipped and their samples as passed (as the kernel's
    /// invocations, which would not have discarded, would have been).
    #[inline]
    pub(crate) fn skip_run(
        &self,
        tile: &mut TileMemory,
        ly: u32,
        run: std::ops::Range<u32>,
        counts: &mut FusedCounts,
    ) {
        let n = u64::from(run.end - run.start);
        counts.skipped += n;
        counts.samples_passed += u64::from(samples_of(self.cov)) * n;
        if self.targets == 0 {
            return;
        }
        debug_assert_eq!(self.targets, 1);
        if tile.samples == 1 && self.cov == 1 && self.state.targets[0].plain_write() {
            // The bits go straight to the texels (what `write_outputs` computes).
            tile.clear_pending_color();
            let row = (ly * tile.tile_size) as usize;
            tile.color[0][row + run.start as usize..row + run.end as usize].fill(self.bits);
            return;
        }
        let outputs = [self.bits];
        for lx in run {
            tile.write_outputs(self.state, lx, ly, self.cov, &outputs);
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
