//! The pipeline: a [`Device`] owns shared memory and runs passes. A geometry pass is
//! vertex transform, binning, then, wave of tiles by wave of tiles: rasterization with
//! early depth/stencil tests (API order, per tile), shading by the chosen executor, and
//! late tests, blending and writes (API order, per tile). A full-screen pass runs one
//! invocation per pixel.
//!
//! Fixed-function results are API-order results whatever order the shader invocations
//! ran in: the early and late stages run per tile in rasterization order, as a GPU's ROP.
//! This module knows nothing of any algorithm.

mod fused;

use std::time::{Duration, Instant};

use glam::Vec4;

use crate::exec::{shade, Binning, ExecConfig, ExecMode, FragOut, ShadeOutcome};
use crate::framebuffer::{Framebuffer, TileMemory};
use crate::geometry::{Draw, MeshError};
use crate::hazard::{Hazard, HazardCounts};
use crate::interlock::Interlock;
use crate::kernel::{FragInput, FragmentKernel, Mode, PassEnv};
use crate::memory::{Buf, Memory, MemoryError, Word};
use crate::raster::{prepare, Binned, PlaneSetup, Prepared, RasterState, Viewport};
use crate::state::{EarlyTests, FragmentState};
use crate::stats::{ContentionTable, Hotspot, Stats};
use crate::sync::pool;

pub use crate::exec::Fault;

/// Why a pass could not run. (Faults of single invocations do not stop a pass: they are in
/// its [`PassReport`].)
#[derive(Debug, thiserror::Error)]
pub enum PassError {
    #[error("invalid mesh: {0}")]
    Mesh(#[from] MeshError),
    #[error("the framebuffer has {fb} samples per pixel but the pass rasterizes {pass}")]
    SampleMismatch { fb: usize, pass: usize },
    #[error("the pass writes {state} render targets but the framebuffer has {fb}")]
    TargetMismatch { state: usize, fb: usize },
    #[error("{0}")]
    Memory(#[from] MemoryError),
}

/// Occlusion-query result of an earlier pass, for conditional rendering.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OcclusionQuery {
    pub samples_passed: u64,
}

/// Fixed-function configuration of a geometry pass.
#[derive(Clone, Debug, Default)]
pub struct PassState {
    pub raster: RasterState,
    pub fragment: FragmentState,
    /// Conditional rendering: the pass is skipped when this query passed no sample.
    pub condition: Option<OcclusionQuery>,
}

/// What a pass did.
#[derive(Clone, Debug, Default)]
pub struct PassReport {
    pub stats: Stats,
    pub hazards: HazardCounts,
    /// The first hazards found, in detail (scheduled executor only).
    pub hazard_list: Vec<Hazard>,
    /// Hazards per pixel, row-major (scheduled executor only; empty otherwise).
    pub hazard_heat: Vec<u32>,
    /// Faults that ended invocations (the first ones; all are counted in `stats.faulted`).
    pub faults: Vec<Fault>,
    /// The schedule, one byte per step, when recording was asked for.
    pub schedule: Option<Vec<u8>>,
    /// True when conditional rendering skipped the pass.
    pub skipped: bool,
    pub wall: Duration,
    /// Load imbalance of the parallel executor's shading: the sum over its threads of the
    /// time each waited, at the end of a shading section, for the last one to finish (zero
    /// with one thread and in the other executors). Timing, like `wall`: it varies from
    /// run to run.
    pub imbalance: Duration,
}

impl PassReport {
    /// The occlusion query of this pass.
    pub fn query(&self) -> OcclusionQuery {
        OcclusionQuery {
            samples_passed: self.stats.samples_passed,
        }
    }
    /// Adds another pass (for multipass algorithms).
    pub fn merge(&mut self, o: &PassReport) {
        self.stats.merge(&o.stats);
        self.hazards.add(&o.hazards);
        self.hazard_list.extend(o.hazard_list.iter().cloned());
        if self.hazard_heat.is_empty() {
            self.hazard_heat = o.hazard_heat.clone();
        } else if self.hazard_heat.len() == o.hazard_heat.len() {
            for (a, b) in self.hazard_heat.iter_mut().zip(&o.hazard_heat) {
                *a += b;
            }
        }
        self.faults.extend(o.faults.iter().cloned());
        if let Some(s) = &o.schedule {
            self.schedule
                .get_or_insert_with(Vec::new)
                .extend_from_slice(s);
        }
        self.wall += o.wall;
        self.imbalance += o.imbalance;
    }
}

/// Tiles shaded together in one wave (bounds the memory of in-flight fragments).
const TILES_PER_WAVE: usize = 256;

/// A software GPU: shared memory plus the pass runner.
#[derive(Default)]
pub struct Device {
    pub memory: Memory,
}

impl Device {
    pub fn new() -> Device {
        Device::default()
    }

    /// A device whose large new buffers are zeroed by `threads` threads (see
    /// [`Memory::with_threads`]).
    pub fn with_threads(threads: usize) -> Device {
        Device {
            memory: Memory::with_threads(threads),
        }
    }

    /// Creates a zero-filled storage buffer.
    pub fn buffer<T: Word>(&mut self, name: &str, len: u64) -> Result<Buf<T>, MemoryError> {
        self.memory.create(name, len)
    }

    /// Runs a geometry pass: `draw` through `state` into `fb`, shading with `kernel`.
    ///
    /// A mesh whose triangles use a non-finite position or an index out of range is an
    /// error ([`PassError::Mesh`], naming the first culprit), returned before anything is
    /// shaded. Binning finds such triangles anyway (it rejects them), so the mesh is only
    /// checked in full when binning rejected some: a large mesh drawn every frame does not
    /// pay for a second pass over it (on the 871K-triangle dragon at 512x512 that pass was
    /// a tenth of the frame, on one thread). Vertices no triangle uses are not checked.
    pub fn draw<K: FragmentKernel>(
        &self,
        fb: &mut Framebuffer,
        draw: &Draw<'_>,
        state: &PassState,
        kernel: &K,
        exec: &ExecConfig,
    ) -> Result<PassReport, PassError> {
        let start = Instant::now();
        if draw
            .mesh
            .normals
            .as_ref()
            .is_some_and(|n| n.len() != draw.mesh.positions.len())
        {
            draw.mesh.validate()?;
        }
        if fb.samples != state.raster.samples {
            return Err(PassError::SampleMismatch {
                fb: fb.samples.count(),
                pass: state.raster.samples.count(),
            });
        }
        if state.fragment.targets.len() > fb.formats.len() {
            return Err(PassError::TargetMismatch {
                state: state.fragment.targets.len(),
                fb: fb.formats.len(),
            });
        }
        let mut report = PassReport::default();
        report.stats.geometry_passes = 1;
        if state.condition.is_some_and(|q| q.samples_passed == 0) {
            report.skipped = true;
            report.wall = start.elapsed();
            return Ok(report);
        }
        let raster = RasterState {
            tile_size: fb.tile_size,
            ..state.raster
        };
        let viewport = Viewport {
            width: fb.width,
            height: fb.height,
        };
        let threads = exec.threads.max(1);
        let info = kernel.info();
        // Planes only for someone who reads them: the kernel's interpolants, or the depth
        // test. Any test keeps them (the tested paths take a depth per fragment).
        let fixed = &state.fragment;
        let plane_setup = if info.interpolants || fixed.depth.test || fixed.stencil.enabled {
            PlaneSetup::Compute
        } else {
            PlaneSetup::Skip
        };
        // Recycled with stale contents (`transform` overwrites every element): a fresh
        // buffer cost a serial clear and a page fault per 4 KiB (7 MB on the 871K dragon).
        let mut clip = ClipPositions(CLIP.take());
        let mut seq_base = 0u64;
        // Passes that need nothing of the framebuffer skip binning (see `Binning::Auto`).
        let try_unbinned = exec.mode == ExecMode::Parallel
            && exec.binning == Binning::Auto
            && !exec.contention
            && info.interlock.is_none()
            && fused::unbinned(fixed, fixed.targets.len());
        for (instance, model) in draw.instances.iter().enumerate() {
            transform(
                &draw.mesh.positions,
                draw.view_proj * *model,
                threads,
                &mut clip.0,
            );
            // Multisampling off: rasterize single-sampled, then a fragment covers every
            // sample of its pixel (see RasterState::multisample).
            let single = !raster.multisample && raster.samples.count() > 1;
            let bin_state = if single {
                RasterState {
                    samples: crate::raster::SampleCount::X1,
                    ..raster
                }
            } else {
                raster
            };
            let prepared = prepare(
                &clip.0,
                draw.indices(),
                &bin_state,
                viewport,
                threads,
                plane_setup,
            );
            let instance = instance as u32;
            // A mesh with bad triangles is binned: binning counts and drops them, and the
            // draw then fails on validation before shading.
            let binned;
            let geo = if try_unbinned && prepared.well_formed(threads) {
                Geometry::Unbinned {
                    prepared: &prepared,
                    instance,
                    first: draw.triangles.start,
                    single,
                }
            } else {
                binned = prepared.bin(threads);
                if binned.rejected > 0 {
                    // Bad input, or positions that the model matrix took out of range
                    // (those are only counted).
                    draw.mesh.validate()?;
                }
                report.stats.rejected_triangles += binned.rejected;
                Geometry::Binned {
                    binned: &binned,
                    instance,
                    first: draw.triangles.start,
                    single,
                }
            };
            self.run_waves(
                fb,
                &geo,
                &state.fragment,
                kernel,
                exec,
                &mut seq_base,
                &mut report,
            );
        }
        report.wall = start.elapsed();
        Ok(report)
    }

    /// Runs `kernel` on explicit fragments (no rasterizer, no framebuffer): for model-sized
    /// experiments (a handful of invocations on one pixel), fuzzing kernels against their
    /// oracles under arbitrary schedules, and the executors' own benchmarks. Fragments of
    /// one pixel must carry their ordered-interlock tickets (0, 1, ... in API order) if the
    /// kernel uses ordered interlock; `seq` is assigned here in slice order.
    pub fn invocations<K: FragmentKernel>(
        &self,
        width: u32,
        height: u32,
        inputs: &[FragInput],
        kernel: &K,
        exec: &ExecConfig,
    ) -> PassReport {
        let start = Instant::now();
        let info = kernel.info();
        let interlock = info.interlock.map(|_| Interlock::new(width, height));
        let env = PassEnv {
            mode: mode_of(exec),
            max_steps: exec.max_steps,
            max_waits: exec.max_waits,
            spurious_cas: exec.spurious_cas_per_mille,
            ..self.explicit_env(width, height, interlock.as_ref(), &info)
        };
        let inputs = explicit_inputs(inputs, width, height);
        let mut outs = vec![FragOut::default(); inputs.len()];
        let mut colors = vec![[0u32; 4]; inputs.len() * 8];
        let outcome = shade(kernel, &env, exec, &inputs, &mut outs, &mut colors, 8);
        let mut report = PassReport::default();
        absorb(&mut report, outcome, &self.memory);
        report.stats.fragments_generated = inputs.len() as u64;
        report.wall = start.elapsed();
        report
    }

    /// Explores schedules of a small model: runs `inputs` (explicit fragments, as
    /// [`Device::invocations`]) once per seed in `seeds` under the scheduled executor
    /// `schedule` (policy, window, recording), with the hazard detector on, reusing every
    /// allocation across executions. After each execution `each` sees its outcome and the
    /// memory (check your invariant there, then reset the buffers); return false to stop.
    /// Returns the number of executions.
    #[allow(clippy::too_many_arguments)] // a model is all of these
    pub fn explore<K: FragmentKernel>(
        &self,
        width: u32,
        height: u32,
        inputs: &[FragInput],
        kernel: &K,
        schedule: &crate::exec::ScheduleConfig,
        max_steps: u64,
        seeds: std::ops::Range<u64>,
        each: impl FnMut(&crate::exec::Execution<'_>, &Memory) -> bool,
    ) -> u64 {
        let info = kernel.info();
        let interlock = info.interlock.map(|_| Interlock::new(width, height));
        let env = PassEnv {
            mode: Mode::Scheduled,
            max_steps,
            max_waits: max_steps,
            ..self.explicit_env(width, height, interlock.as_ref(), &info)
        };
        let inputs = explicit_inputs(inputs, width, height);
        crate::exec::explore(kernel, &env, schedule, max_steps, &inputs, seeds, each)
    }

    /// The environment of explicit invocations (no rasterizer, one sample), direct mode.
    fn explicit_env<'a>(
        &'a self,
        width: u32,
        height: u32,
        interlock: Option<&'a Interlock>,
        info: &crate::kernel::KernelInfo,
    ) -> PassEnv<'a> {
        PassEnv {
            memory: &self.memory,
            tris: &[],
            width,
            height,
            samples: 1,
            interlock,
            interlock_mode: info.interlock,
            sample_tickets: &[],
            mode: Mode::Direct { yield_every: 0 },
            max_steps: u64::MAX,
            max_waits: u64::MAX,
            spurious_cas: 0,
            contention: None,
            no_interpolants: !info.interpolants,
        }
    }

    /// Runs a full-screen pass: one invocation per pixel (all samples covered, depth 0.5,
    /// primitive 0), through `state`'s depth/stencil tests and target writes.
    pub fn fullscreen<K: FragmentKernel>(
        &self,
        fb: &mut Framebuffer,
        state: &FragmentState,
        kernel: &K,
        exec: &ExecConfig,
    ) -> Result<PassReport, PassError> {
        let start = Instant::now();
        if state.targets.len() > fb.formats.len() {
            return Err(PassError::TargetMismatch {
                state: state.targets.len(),
                fb: fb.formats.len(),
            });
        }
        let mut report = PassReport::default();
        report.stats.fullscreen_passes = 1;
        let mut seq_base = 0;
        self.run_waves(
            fb,
            &Geometry::FullScreen,
            state,
            kernel,
            exec,
            &mut seq_base,
            &mut report,
        );
        report.wall = start.elapsed();
        Ok(report)
    }

    #[allow(clippy::too_many_arguments)] // private; the pieces of one pass
    fn run_waves<K: FragmentKernel>(
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
        let interlock = info.interlock.map(|m| {
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
            // Each unit of work brings its own (`fused::run_unbinned`).
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
        // Ordered and parallel draws without interlock or contention counting take the
        // fused path (see `fused`): no fragment lists, one pass over each tile.
        let direct = matches!(exec.mode, ExecMode::Ordered | ExecMode::Parallel);
        let parallel = exec.mode == ExecMode::Parallel;
        let fused_pass = |instance: u32, first: u32, single: bool| fused::FusedPass {
            state,
            instance,
            first,
            single,
            early,
            targets,
            lanes: if parallel { exec.batch.max(1) } else { 1 },
            lockstep: parallel && exec.lockstep,
            threads: if parallel { exec.threads.max(1) } else { 1 },
            segment: (parallel && fused::commutes(state, targets)).then_some(exec.segment.max(1)),
            seq_base: *seq_base,
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
            let pass = fused_pass(*instance, *first, *single);
            let (outcome, counts, rejected, imbalance) =
                fused::run_unbinned(kernel, &env_base, &pass, prepared);
            report.imbalance += imbalance;
            // Invocation ids are by source triangle (see `fused::Row`).
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
            None,
            Geometry::Binned {
                binned,
                instance,
                first,
                single,
            },
        ) = (direct, info.interlock, contention.as_ref(), geo)
        {
            let pass = fused_pass(*instance, *first, *single);
            let (outcome, counts, imbalance) =
                fused::run_fused(kernel, &env_base, &pass, binned, fb.tiles_mut());
            report.imbalance += imbalance;
            // Invocation ids are by source triangle (see `fused::Row`).
            *seq_base =
                seq_base.wrapping_add((binned.input_triangles() as u64).wrapping_mul(pixels));
            counts.add_to(&mut report.stats);
            absorb(report, outcome, &self.memory);
            return;
        }
        let tile_count = fb.tiles().len();
        let mut wave_index = 0u64;
        let mut bytes_used = 0usize;
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
            };
            let counts =
                for_each_tile(tiles, &mut lists, exec.threads, |tile_index, tile, list| {
                    front.tile(first + tile_index, tile, list)
                });
            for c in &counts {
                report.stats.fragments_generated += c.0;
                report.stats.early_culled += c.1;
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
                outs_lists.resize_with(lists.len(), Vec::new);
                colors_lists.resize_with(lists.len(), Vec::new);
                let batch = exec.batch.max(1);
                let mut chunks = Vec::new();
                for ((l, o), c) in lists
                    .iter()
                    .zip(outs_lists.iter_mut())
                    .zip(colors_lists.iter_mut())
                {
                    o.clear();
                    o.resize(l.len(), FragOut::default());
                    c.clear();
                    c.resize(l.len() * targets, [0; 4]);
                    let mut o_rest = &mut o[..];
                    let mut c_rest = &mut c[..];
                    for ins in l.chunks(batch) {
                        let (oo, orest) = o_rest.split_at_mut(ins.len());
                        let (cc, crest) = c_rest.split_at_mut(ins.len() * targets);
                        o_rest = orest;
                        c_rest = crest;
                        chunks.push((ins, oo, cc));
                    }
                }
                let outcome = crate::exec::shade_chunks(kernel, &env_base, exec, chunks, targets);
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
                let exec_wave = match &exec.mode {
                    ExecMode::Scheduled(sc) => {
                        let mut sc = sc.clone();
                        sc.seed = sc
                            .seed
                            .wrapping_add(wave_index.wrapping_mul(0x9E37_79B9_7F4A_7C15));
                        // An explicit schedule runs on across waves: each wave continues where
                        // the previous one stopped reading it.
                        if let crate::exec::Policy::Bytes(b) = &mut sc.policy {
                            b.drain(..bytes_used.min(b.len()));
                        }
                        ExecConfig {
                            mode: ExecMode::Scheduled(sc),
                            ..exec.clone()
                        }
                    }
                    _ => exec.clone(),
                };
                let outcome = if let ExecMode::Scheduled(_) = exec.mode {
                    // Admission order: pixel block by block, API order within a block.
                    let block = exec.block.max(1);
                    let mut order: Vec<usize> = (0..inputs.len()).collect();
                    order.sort_by_key(|&i| {
                        let f = &inputs[i];
                        (
                            (f.y / block) as u64 * fb.width.div_ceil(block) as u64
                                + (f.x / block) as u64,
                            i,
                        )
                    });
                    let sched: Vec<FragInput> = order.iter().map(|&i| inputs[i]).collect();
                    let mut s_outs = vec![FragOut::default(); sched.len()];
                    let mut s_colors = vec![[0u32; 4]; sched.len() * targets];
                    let o = shade(
                        kernel,
                        &env,
                        &exec_wave,
                        &sched,
                        &mut s_outs,
                        &mut s_colors,
                        targets,
                    );
                    for (k, &i) in order.iter().enumerate() {
                        outs[i] = s_outs[k];
                        colors[i * targets..(i + 1) * targets]
                            .copy_from_slice(&s_colors[k * targets..(k + 1) * targets]);
                    }
                    o
                } else {
                    shade(
                        kernel,
                        &env,
                        &exec_wave,
                        &inputs,
                        &mut outs,
                        &mut colors,
                        targets,
                    )
                };
                bytes_used += outcome.bytes_used;
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
            wave_index += 1;
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
fn mode_of(exec: &ExecConfig) -> Mode {
    match exec.mode {
        ExecMode::Scheduled(_) => Mode::Scheduled,
        ExecMode::Parallel if exec.lockstep => Mode::Direct { yield_every: 1 },
        _ => Mode::Direct { yield_every: 0 },
    }
}

/// Explicit fragments numbered in slice order and clamped to the render area.
fn explicit_inputs(inputs: &[FragInput], width: u32, height: u32) -> Vec<FragInput> {
    let mut inputs = inputs.to_vec();
    for (i, f) in inputs.iter_mut().enumerate() {
        f.seq = i as u64;
        f.x = f.x.min(width.saturating_sub(1));
        f.y = f.y.min(height.saturating_sub(1));
    }
    inputs
}

/// Folds one wave's shading outcome into the pass report.
fn absorb(report: &mut PassReport, outcome: ShadeOutcome, memory: &Memory) {
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
type BackItem<'a> = (&'a [FragInput], &'a [FragOut], &'a [[u32; 4]]);

/// Where a pass's fragments come from.
enum Geometry<'a> {
    /// `single`: multisampling off on a multisampled target (one coverage bit for all).
    Binned {
        binned: &'a Binned,
        instance: u32,
        /// The first triangle drawn: primitive id of setup source 0 (see `Draw::triangles`).
        first: u32,
        single: bool,
    },
    /// Set up and rasterized chunk by chunk by the fused path's workers
    /// (`fused::run_unbinned`); made by `Device::draw` only for passes that path runs.
    Unbinned {
        prepared: &'a Prepared<'a>,
        instance: u32,
        first: u32,
        single: bool,
    },
    FullScreen,
}

/// Clip-space positions of draws, reused from draw to draw (see [`crate::raster::pool`]).
static CLIP: crate::raster::pool::Pool<Vec4> = crate::raster::pool::Pool::new();

/// A draw's clip-space positions, handed back to [`CLIP`] when the draw ends (on every path).
struct ClipPositions(Vec<Vec4>);

impl Drop for ClipPositions {
    fn drop(&mut self) {
        CLIP.give_dirty(std::mem::take(&mut self.0));
    }
}

/// Transforms positions to clip space (in parallel). `out` may hold stale positions: it
/// is cut or grown to size (only the growth is cleared) and every element overwritten.
fn transform(positions: &[glam::Vec3], m: glam::Mat4, threads: usize, out: &mut Vec<Vec4>) {
    out.truncate(positions.len());
    out.resize(positions.len(), Vec4::ZERO);
    let chunk = positions.len().div_ceil(threads.max(1)).max(4096);
    let parts: Vec<_> = positions.chunks(chunk).zip(out.chunks_mut(chunk)).collect();
    pool::broadcast_each(parts, |(src, dst)| {
        for (p, o) in src.iter().zip(dst.iter_mut()) {
            *o = m * p.extend(1.0);
        }
    });
}

/// Runs `f` on every (tile, item) pair with up to `threads` threads; returns the results
/// in tile order.
fn for_each_tile<T: Send, R: Send + Default + Clone>(
    tiles: &mut [TileMemory],
    items: &mut [T],
    threads: usize,
    f: impl Fn(usize, &mut TileMemory, &mut T) -> R + Sync,
) -> Vec<R> {
    let n = tiles.len();
    let mut results = vec![R::default(); n];
    let threads = threads.max(1).min(n.max(1));
    if threads == 1 {
        for (i, ((t, it), r)) in tiles
            .iter_mut()
            .zip(items.iter_mut())
            .zip(results.iter_mut())
            .enumerate()
        {
            *r = f(i, t, it);
        }
        return results;
    }
    let work: Vec<(usize, &mut TileMemory, &mut T, &mut R)> = tiles
        .iter_mut()
        .zip(items.iter_mut())
        .zip(results.iter_mut())
        .enumerate()
        .map(|(i, ((t, it), r))| (i, t, it, r))
        .collect();
    let queue = pool::Mutex::new(work.into_iter());
    pool::broadcast(threads, |_| loop {
        let next = queue.lock().unwrap_or_else(|e| e.into_inner()).next();
        let Some((i, t, it, r)) = next else { break };
        *r = f(i, t, it);
    });
    results
}

/// Rasterization and early tests of one tile.
struct RasterFront<'a> {
    geo: &'a Geometry<'a>,
    state: &'a FragmentState,
    early: bool,
    samples: u32,
}

impl RasterFront<'_> {
    /// Returns (fragments generated, early-culled).
    fn tile(
        &self,
        tile_index: usize,
        tile: &mut TileMemory,
        list: &mut Vec<FragInput>,
    ) -> (u64, u64) {
        let mut generated = 0u64;
        let mut culled = 0u64;
        let ts = tile.tile_size;
        // Tickets: per-pixel rank among shaded fragments (ordered interlock).
        let mut tickets = vec![0u32; (ts * ts) as usize];
        let tests = self.early && (self.state.depth.test || self.state.stencil.enabled);
        let all = if self.samples >= 8 {
            0xff
        } else {
            (1u8 << self.samples) - 1
        };
        let sample_mask = self.state.sample_mask & all;
        match self.geo {
            Geometry::Binned {
                binned,
                instance,
                first,
                single,
            } => {
                let positions = crate::raster::SampleCount::from_count(self.samples)
                    .map(|c| c.positions())
                    .unwrap_or(&[(0.5, 0.5)]);
                let per_sample_depth = self.samples > 1 && !*single;
                binned.raster_tile(tile_index, |f| {
                    let f_cov = if *single && f.coverage & 1 != 0 {
                        all
                    } else {
                        f.coverage
                    };
                    let cov = f_cov & sample_mask;
                    if cov == 0 {
                        return;
                    }
                    generated += 1;
                    let t = binned.tris.get(f.tri as usize);
                    let (fx, fy) = (f.x as f32, f.y as f32);
                    // No planes: nothing reads a depth (no depth test, no interpolants).
                    let depth = t.map_or(f32::NAN, |t| t.depth_at(fx + 0.5, fy + 0.5));
                    let (lx, ly) = (f.x - tile.x0, f.y - tile.y0);
                    let mut cov = cov;
                    if tests {
                        let mut depths = [depth; 8];
                        if let (true, Some(t)) = (per_sample_depth, t) {
                            for (s, p) in positions.iter().enumerate() {
                                depths[s] = t.depth_at(fx + p.0, fy + p.1);
                            }
                        }
                        cov = tile.depth_stencil(
                            self.state,
                            lx,
                            ly,
                            cov,
                            &depths,
                            f.front_facing,
                            true,
                        );
                        if cov == 0 {
                            culled += 1;
                            return;
                        }
                    }
                    let slot = &mut tickets[(ly * ts + lx) as usize];
                    let ticket = *slot;
                    *slot += 1;
                    list.push(FragInput {
                        seq: 0,
                        x: f.x,
                        y: f.y,
                        tri: f.tri,
                        primitive_id: f.source + *first,
                        instance_id: *instance,
                        coverage: cov,
                        front_facing: f.front_facing,
                        depth,
                        ticket,
                    });
                });
            }
            Geometry::Unbinned { .. } => {
                unreachable!("unbinned geometry runs on the fused path only (Device::draw)")
            }
            Geometry::FullScreen => {
                for ly in 0..tile.h {
                    for lx in 0..tile.w {
                        // Full-screen invocations are not rasterized fragments: not counted as generated.

                        let mut cov = sample_mask;
                        if tests {
                            cov =
                                tile.depth_stencil(self.state, lx, ly, cov, &[0.5; 8], true, true);
                            if cov == 0 {
                                culled += 1;
                                continue;
                            }
                        }
                        list.push(FragInput {
                            seq: 0,
                            x: tile.x0 + lx,
                            y: tile.y0 + ly,
                            tri: u32::MAX,
                            primitive_id: 0,
                            instance_id: 0,
                            coverage: cov,
                            front_facing: true,
                            depth: 0.5,
                            ticket: 0,
                        });
                    }
                }
            }
        }
        (generated, culled)
    }
}

/// Late tests and target writes of one tile.
struct RasterBack<'a> {
    geo: &'a Geometry<'a>,
    state: &'a FragmentState,
    early: bool,
    samples: u32,
    targets: usize,
}

impl RasterBack<'_> {
    /// Returns (late-culled fragments, samples passed).
    fn tile(
        &self,
        tile: &mut TileMemory,
        (ins, outs, colors): &mut (&[FragInput], &[FragOut], &[[u32; 4]]),
    ) -> (u64, u64) {
        let mut culled = 0;
        let mut passed_samples = 0u64;
        let late_tests = !self.early && (self.state.depth.test || self.state.stencil.enabled);
        let positions = crate::raster::SampleCount::from_count(self.samples)
            .map(|c| c.positions())
            .unwrap_or(&[(0.5, 0.5)]);
        for (i, (f, o)) in ins.iter().zip(outs.iter()).enumerate() {
            if o.faulted || o.discarded {
                continue;
            }
            let (lx, ly) = (f.x - tile.x0, f.y - tile.y0);
            let mut mask = f.coverage;
            if late_tests {
                let mut depths = [o.depth.unwrap_or(f.depth); 8];
                if o.depth.is_none() && self.samples > 1 {
                    if let Geometry::Binned {
                        binned,
                        single: false,
                        ..
                    } = self.geo
                    {
                        let t = &binned.tris[f.tri as usize];
                        for (s, p) in positions.iter().enumerate() {
                            depths[s] = t.depth_at(f.x as f32 + p.0, f.y as f32 + p.1);
                        }
                    }
                }
                mask = tile.depth_stencil(self.state, lx, ly, mask, &depths, f.front_facing, true);
                if mask == 0 {
                    culled += 1;
                    continue;
                }
            }
            passed_samples += mask.count_ones() as u64;
            if self.targets > 0 {
                tile.write_outputs(
                    self.state,
                    lx,
                    ly,
                    mask,
                    &colors[i * self.targets..(i + 1) * self.targets],
                );
            }
        }
        (culled, passed_samples)
    }
}
