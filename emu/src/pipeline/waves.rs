//! A pass's shading, wave of tiles by wave of tiles: the fused path where it applies,
//! otherwise rasterization and early tests per tile, the chosen executor on the wave's
//! fragments, then late tests and writes per tile in API order.

use crate::exec::{shade, ExecConfig, ExecMode, FragOut, ShadeOutcome};
use crate::framebuffer::Framebuffer;
use crate::interlock::Interlock;
use crate::invocation::{Mode, PassEnv};
use crate::kernel::{FragInput, FragmentKernel};
use crate::memory::Memory;
use crate::raster::{Binned, Prepared};
use crate::state::{EarlyTests, FragmentState};
use crate::stats::{ContentionTable, Hotspot, Stats};

use super::tiles::{for_each_tile, RasterBack, RasterFront};
use super::{Device, PassReport};

/// Tiles shaded together in one wave (bounds the memory of in-flight fragments).
pub(super) const TILES_PER_WAVE: usize = 256;

impl Device {
    #[allow(clippy::too_many_arguments)] // private; the pieces of one pass
    pub(super) fn run_waves<K: FragmentKernel>(
        &self,
        fb: &mut Framebuffer,
        geo: &Geometry<'_>,
        state: &FragmentState,
        kernel: &K,
        exec: &ExecConfig,
        seq_base: &mut u64,
        report: &mut PassReport,
    ) {
        let info = kernel.info();
        let early = match state.early {
            EarlyTests::ForceEarly => true,
            EarlyTests::ForceLate => false,
            EarlyTests::Auto => !info.may_discard && !info.writes_depth,
        };
        let targets = state.targets.len();
        let direct = matches!(exec.mode, ExecMode::Ordered | ExecMode::Parallel);
        let parallel = exec.mode == ExecMode::Parallel;
        // Interlock by ownership: on the fused path a binned pass without lockstep gives
        // each tile to one worker, which shades its fragments one at a time to their end
        // in API order (`crate::exec::fused`). Every fragment of a pixel then enters its
        // critical section alone and in API order, as ordered interlock asks, with no lock:
        // a GPU's pixel ordering by tile ownership. The invocations see no `Interlock`
        // (`PassEnv::interlock` is `None` with the mode set).
        let owned = info.interlock.is_some()
            && direct
            && !(parallel && exec.lockstep)
            && !(exec.contention && parallel)
            && matches!(geo, Geometry::Binned { .. });
        let interlock = info.interlock.filter(|_| !owned).map(|m| {
            Interlock::with_samples(
                fb.width,
                fb.height,
                if m.per_sample {
                    fb.samples.count() as u32
                } else {
                    1
                },
            )
        });
        let per_sample_ordered =
            info.interlock.is_some_and(|m| m.per_sample && m.ordered) && fb.samples.count() > 1;
        let mut sample_counters: Vec<u32> = Vec::new();
        let mut side: Vec<[u32; 8]> = Vec::new();
        let contention = (exec.contention && exec.mode == ExecMode::Parallel).then(|| {
            let words: Vec<u32> = self
                .memory
                .buffer_sizes()
                .iter()
                .enumerate()
                .map(|(id, _)| self.memory.buffer_len(id as u32))
                .collect();
            ContentionTable::new(&words)
        });
        let mode = mode_of(exec);
        let tris: &[crate::raster::SetupTriangle] = match geo {
            Geometry::Binned { binned, .. } => &binned.tris,
            // Each unit of work brings its own (`crate::exec::fused::run_unbinned`).
            Geometry::Unbinned { .. } | Geometry::FullScreen => &[],
        };
        let env_base = PassEnv {
            memory: &self.memory,
            tris,
            width: fb.width,
            height: fb.height,
            samples: fb.samples.count() as u32,
            interlock: interlock.as_ref(),
            interlock_mode: info.interlock,
            sample_tickets: &[],
            mode,
            max_steps: exec.max_steps,
            max_waits: exec.max_waits,
            spurious_cas: exec.spurious_cas_per_mille,
            contention: contention.as_ref(),
            no_interpolants: !info.interpolants,
        };
        // Ordered and parallel draws without contention counting take the fused path (see
        // `fused`): no fragment lists, one pass over each tile; with interlock only when
        // the tiles' ownership orders each pixel's fragments (`owned`).
        // The screen blocks this pass marks (geometry on the fused path) or may skip
        // (a full-screen pass whose kernel declares its output at untouched pixels).
        let touched = self.touched();
        let (fw, fh) = (fb.width, fb.height);
        let marking = || touched.and_then(|t| t.for_marking(fw, fh));
        let fused_pass = |instance: u32, first: u32, single: bool| crate::exec::fused::FusedPass {
            state,
            instance,
            first,
            single,
            early,
            targets,
            lanes: if parallel { exec.batch.max(1) } else { 1 },
            lockstep: parallel && exec.lockstep,
            threads: if parallel { exec.threads.max(1) } else { 1 },
            // Segments of one tile shade on several threads at once: not under interlock.
            segment: (parallel && !owned && crate::exec::fused::commutes(state, targets))
                .then_some(exec.segment.max(1)),
            seq_base: *seq_base,
            flat_depth: f32::NAN,
            touched: None,
            untouched_output: None,
        };
        let pixels = fb.width as u64 * fb.height as u64;
        if let Geometry::Unbinned {
            prepared,
            instance,
            first,
            single,
        } = geo
        {
            // `Device::draw` makes unbinned geometry only for passes this path runs.
            debug_assert!(direct && info.interlock.is_none() && contention.is_none());
            let mask = marking();
            let pass = crate::exec::fused::FusedPass {
                touched: mask.as_deref(),
                ..fused_pass(*instance, *first, *single)
            };
            let (outcome, counts, rejected, imbalance) =
                crate::exec::fused::run_unbinned(kernel, &env_base, &pass, prepared);
            report.imbalance += imbalance;
            // Invocation ids are by source triangle (see `crate::exec::fused::Row`).
            *seq_base =
                seq_base.wrapping_add((prepared.triangle_count() as u64).wrapping_mul(pixels));
            report.stats.rejected_triangles += rejected;
            counts.add_to(&mut report.stats);
            absorb(report, outcome, &self.memory);
            return;
        }
        if let (
            true,
            None,
            Geometry::Binned {
                binned,
                instance,
                first,
                single,
            },
        ) = (
            direct && (info.interlock.is_none() || owned),
            contention.as_ref(),
            geo,
        ) {
            let mask = marking();
            let pass = crate::exec::fused::FusedPass {
                touched: mask.as_deref(),
                ..fused_pass(*instance, *first, *single)
            };
            let (outcome, counts, imbalance) =
                crate::exec::fused::run_fused(kernel, &env_base, &pass, binned, fb.tiles_mut());
            report.imbalance += imbalance;
            // Invocation ids are by source triangle (see `crate::exec::fused::Row`).
            *seq_base =
                seq_base.wrapping_add((binned.input_triangles() as u64).wrapping_mul(pixels));
            counts.add_to(&mut report.stats);
            absorb(report, outcome, &self.memory);
            return;
        }
        if let (true, None, None, Geometry::FullScreen) =
            (direct, info.interlock, contention.as_ref(), geo)
        {
            if crate::exec::fused::fullscreen_fuses(state, env_base.samples) {
                // Skipping needs the kernel's word on untouched pixels and a mask of this
                // frame; it defines target 0 only.
                let untouched_output = info.untouched_output.filter(|_| targets <= 1);
                let mask = untouched_output
                    .and(touched)
                    .and_then(|t| t.for_reading(fw, fh));
                let pass = crate::exec::fused::FusedPass {
                    flat_depth: 0.5,
                    touched: mask.as_deref(),
                    untouched_output,
                    ..fused_pass(0, 0, false)
                };
                let (outcome, counts, imbalance) =
                    crate::exec::fused::run_fullscreen(kernel, &env_base, &pass, fb.tiles_mut());
                report.imbalance += imbalance;
                // Invocation ids by pixel, row-major (see `fused::Row`).
                *seq_base = seq_base.wrapping_add(pixels);
                counts.add_to(&mut report.stats);
                absorb(report, outcome, &self.memory);
                return;
            }
        }
        // The general path's geometry marks the blocks its rasterizer reaches, as the fused
        // path does; its full-screen passes skip the unmarked ones under the same terms as
        // the fused full-screen path's (the kernel's declared output, target 0 at most,
        // nothing tested, a sample covered), whatever the executor: the invocation such a
        // pixel would have run accesses nothing another invocation of the pass writes
        // (`KernelInfo::with_untouched_output`; docs/fuzzing.md), so no schedule of it
        // shows a hazard the others' schedules do not.
        let marks = match geo {
            Geometry::FullScreen => None,
            _ => marking(),
        };
        let skip = match geo {
            Geometry::FullScreen => info
                .untouched_output
                .filter(|_| {
                    targets <= 1 && crate::exec::fused::fullscreen_fuses(state, env_base.samples)
                })
                .and_then(|bits| {
                    touched
                        .and_then(|t| t.for_reading(fw, fh))
                        .map(|m| (m, bits))
                }),
            _ => None,
        };
        let tile_count = fb.tiles().len();
        let mut waves = crate::exec::Waves::default();
        let mut lists: Vec<Vec<FragInput>> = Vec::new();
        let mut outs_lists: Vec<Vec<FragOut>> = Vec::new();
        let mut colors_lists: Vec<Vec<[u32; 4]>> = Vec::new();
        let mut first = 0;
        while first < tile_count {
            let last = (first + TILES_PER_WAVE).min(tile_count);
            let tiles = &mut fb.tiles_mut()[first..last];
            lists.resize_with(tiles.len(), Vec::new);
            // 1. Rasterize and run early tests, per tile in parallel, in API order within a tile.
            let front = RasterFront {
                geo,
                state,
                early,
                samples: env_base.samples,
                marks: marks.as_deref(),
                skip: skip.as_ref().map(|(m, bits)| (&**m, *bits)),
                targets,
            };
            let counts =
                for_each_tile(tiles, &mut lists, exec.threads, |tile_index, tile, list| {
                    front.tile(first + tile_index, tile, list)
                });
            for c in &counts {
                c.add_to(&mut report.stats);
            }
            // 2. Shade the wave with the executor.
            let direct = !per_sample_ordered && !matches!(exec.mode, ExecMode::Scheduled(_));
            if direct {
                // Ordered and parallel: batches straight from each tile's list (no copy).
                for l in lists.iter_mut() {
                    for f in l.iter_mut() {
                        f.seq = *seq_base;
                        *seq_base += 1;
                    }
                }
                let outcome = crate::exec::shade_lists(
                    kernel,
                    &env_base,
                    exec,
                    &lists,
                    &mut outs_lists,
                    &mut colors_lists,
                    targets,
                );
                absorb(report, outcome, &self.memory);
                let tiles = &mut fb.tiles_mut()[first..last];
                let back = RasterBack {
                    geo,
                    state,
                    early,
                    samples: env_base.samples,
                    targets,
                };
                let mut ins_lists: Vec<BackItem<'_>> = lists
                    .iter()
                    .zip(&outs_lists)
                    .zip(&colors_lists)
                    .map(|((l, o), c)| (&l[..], &o[..], &c[..]))
                    .collect();
                let counts = for_each_tile(tiles, &mut ins_lists, exec.threads, |_, tile, l| {
                    back.tile(tile, l)
                });
                for c in &counts {
                    report.stats.late_culled += c.0;
                    report.stats.samples_passed += c.1;
                }
            } else {
                let mut inputs: Vec<FragInput> =
                    Vec::with_capacity(lists.iter().map(Vec::len).sum());
                let mut ranges = Vec::with_capacity(lists.len());
                for l in &lists {
                    ranges.push(inputs.len()..inputs.len() + l.len());
                    inputs.extend_from_slice(l);
                }
                for (i, f) in inputs.iter_mut().enumerate() {
                    f.seq = *seq_base + i as u64;
                }
                *seq_base += inputs.len() as u64;
                // Per-sample ordered interlock: each fragment's rank among the fragments covering
                // each of its samples, in API order (the ticket field then indexes this table).
                side.clear();
                if per_sample_ordered {
                    let spp = env_base.samples as usize;
                    if sample_counters.is_empty() {
                        sample_counters = vec![0; fb.width as usize * fb.height as usize * spp];
                    }
                    for (i, f) in inputs.iter_mut().enumerate() {
                        let base = (f.y as usize * fb.width as usize + f.x as usize) * spp;
                        let mut t = [0u32; 8];
                        for (s, slot) in t.iter_mut().enumerate().take(spp) {
                            if f.coverage & (1 << s) != 0 {
                                *slot = sample_counters[base + s];
                                sample_counters[base + s] += 1;
                            }
                        }
                        side.push(t);
                        f.ticket = i as u32;
                    }
                }
                let env = PassEnv {
                    sample_tickets: &side,
                    ..env_base.clone()
                };
                let mut outs = vec![FragOut::default(); inputs.len()];
                let mut colors = vec![[0u32; 4]; inputs.len() * targets];
                let outcome = match &exec.mode {
                    ExecMode::Scheduled(sc) => waves.shade(
                        kernel,
                        &env,
                        exec,
                        sc,
                        &inputs,
                        &mut outs,
                        &mut colors,
                        targets,
                    ),
                    _ => shade(kernel, &env, exec, &inputs, &mut outs, &mut colors, targets),
                };
                absorb(report, outcome, &self.memory);
                // 3. Late tests and writes, per tile in API order.
                let tiles = &mut fb.tiles_mut()[first..last];
                let back = RasterBack {
                    geo,
                    state,
                    early,
                    samples: env.samples,
                    targets,
                };
                let mut ins_lists: Vec<BackItem<'_>> = ranges
                    .iter()
                    .map(|r| {
                        (
                            &inputs[r.clone()],
                            &outs[r.clone()],
                            &colors[r.start * targets..r.end * targets],
                        )
                    })
                    .collect();
                let counts = for_each_tile(tiles, &mut ins_lists, exec.threads, |_, tile, l| {
                    back.tile(tile, l)
                });
                for c in &counts {
                    report.stats.late_culled += c.0;
                    report.stats.samples_passed += c.1;
                }
            }
            for l in &mut lists {
                l.clear();
            }
            first = last;
        }
        if let Some(table) = &contention {
            let hot = table.hotspots(|b| self.memory.buffer_name(b).to_string());
            let mut s = Stats {
                hotspots: hot,
                ..Default::default()
            };
            s.hotspots.sort_by_key(|h| std::cmp::Reverse(h.accesses));
            report.stats.merge(&s);
        }
    }
}

/// How an executor's invocations suspend.
pub(super) fn mode_of(exec: &ExecConfig) -> Mode {
    match exec.mode {
        ExecMode::Scheduled(_) => Mode::Scheduled,
        ExecMode::Parallel if exec.lockstep => Mode::Direct { yield_every: 1 },
        _ => Mode::Direct { yield_every: 0 },
    }
}

/// Explicit fragments numbered in slice order and clamped to the render area.
pub(super) fn explicit_inputs(inputs: &[FragInput], width: u32, height: u32) -> Vec<FragInput> {
    let mut inputs = inputs.to_vec();
    for (i, f) in inputs.iter_mut().enumerate() {
        f.seq = i as u64;
        f.x = f.x.min(width.saturating_sub(1));
        f.y = f.y.min(height.saturating_sub(1));
    }
    inputs
}

/// Folds one wave's shading outcome into the pass report.
pub(super) fn absorb(report: &mut PassReport, outcome: ShadeOutcome, memory: &Memory) {
    report.stats.merge(&outcome.stats);
    report.hazards.add(&outcome.hazard_counts);
    report.hazard_list.extend(outcome.hazards);
    report.hazard_list.truncate(256);
    if !outcome.heat.is_empty() {
        if report.hazard_heat.is_empty() {
            report.hazard_heat = outcome.heat;
        } else {
            for (a, b) in report.hazard_heat.iter_mut().zip(&outcome.heat) {
                *a += b;
            }
        }
    }
    report.faults.extend(outcome.faults);
    report.faults.truncate(64);
    if let Some(s) = outcome.schedule {
        report.schedule.get_or_insert_with(Vec::new).extend(s);
    }
    if !outcome.scheduled_hotspots.is_empty() {
        let hot = outcome
            .scheduled_hotspots
            .iter()
            .map(|&(addr, accesses, peak)| Hotspot {
                buffer: memory.buffer_name(addr.buffer()).to_string(),
                index: addr.index(),
                accesses,
                peak_concurrent: peak,
            })
            .collect();
        report.stats.merge(&Stats {
            hotspots: hot,
            ..Default::default()
        });
    }
}

/// One tile's fragments, results and colours, for the late stage.
pub(super) type BackItem<'a> = (&'a [FragInput], &'a [FragOut], &'a [[u32; 4]]);

/// Where a pass's fragments come from.
pub(super) enum Geometry<'a> {
    /// `single`: multisampling off on a multisampled target (one coverage bit for all).
    Binned {
        binned: &'a Binned,
        instance: u32,
        /// The first triangle drawn: primitive id of setup source 0 (see `Draw::triangles`).
        first: u32,
        single: bool,
    },
    /// Set up and rasterized chunk by chunk by the fused path's workers
    /// (`crate::exec::fused::run_unbinned`); made by `Device::draw` only for passes that path runs.
    Unbinned {
        prepared: &'a Prepared<'a>,
        instance: u32,
        first: u32,
        single: bool,
    },
    FullScreen,
}
