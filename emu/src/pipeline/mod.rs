//! The pipeline: a [`Device`] owns shared memory and runs passes. A geometry pass is
//! vertex transform, binning, then, wave of tiles by wave of tiles: rasterization with
//! early depth/stencil tests (API order, per tile), shading by the chosen executor, and
//! late tests, blending and writes (API order, per tile). A full-screen pass runs one
//! invocation per pixel.
//!
//! Fixed-function results are API-order results whatever order the shader invocations
//! ran in: the early and late stages run per tile in rasterization order, as a GPU's ROP.
//! This module knows nothing of any algorithm, and runs no shading loop of its own: it
//! hands fragments (or, on the fused path, set-up triangles and tiles) to [`crate::exec`].
//!
//! Files: this one (the [`Device`] and its passes), `region` (a geometry pass and a
//! full-screen pass run tile by tile), `report` (what a pass did), `vertex`
//! (clip-space transform, and the last draw's vertices kept for the next), `waves` (a pass
//! wave of tiles by wave of tiles), `tiles` (the per-tile fixed-function stages before and
//! after shading).

mod region;
mod report;
mod tiles;
mod touched;
mod vertex;
mod waves;

pub use report::{OcclusionQuery, PassError, PassReport, PassState, PassTime};
use touched::Touched;
pub use touched::{BlockMask, Coverage, BLOCK_SHIFT};
use vertex::{VertexCache, VertexKey};
use waves::{absorb, explicit_inputs, mode_of, Geometry};

use std::time::{Duration, Instant};

use crate::exec::{shade, Binning, ExecConfig, ExecMode, FragOut};
use crate::framebuffer::Framebuffer;
use crate::geometry::Draw;
use crate::interlock::Interlock;
use crate::invocation::{Mode, PassEnv};
use crate::kernel::{FragInput, FragmentKernel};
use crate::memory::{Buf, Memory, MemoryError, Word};
use crate::raster::{prepare, prepare_projected, PlaneSetup, RasterState, Viewport};
use crate::state::FragmentState;

pub use crate::exec::Fault;

/// A software GPU: shared memory plus the pass runner.
#[derive(Default)]
pub struct Device {
    pub memory: Memory,
    /// The last draw's vertices, for the next draw of the same mesh and matrix.
    #[cfg(not(loom))]
    vertices: VertexCache,
    /// The screen blocks this device's geometry passes rasterized (see `touched`).
    #[cfg(not(loom))]
    touched: Touched,
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
            ..Device::default()
        }
    }

    /// This device with its geometry passes marking the screen blocks they reach, or not
    /// ([`Coverage`]; untracked by default). Under loom nothing is marked or skipped.
    pub fn with_coverage(self, coverage: Coverage) -> Device {
        #[cfg(not(loom))]
        {
            let mut d = self;
            d.touched.coverage = coverage;
            d
        }
        #[cfg(loom)]
        {
            let _ = coverage;
            self
        }
    }

    /// The cache of the last draw's vertices (under loom, a fresh one each time: loom's
    /// models build devices from their memory alone).
    #[cfg(not(loom))]
    fn vertex_cache(&self) -> &VertexCache {
        &self.vertices
    }
    #[cfg(loom)]
    fn vertex_cache(&self) -> VertexCache {
        VertexCache::default()
    }

    /// The screen blocks this device's geometry passes reached (under loom, none is
    /// kept: nothing is skipped).
    #[cfg(not(loom))]
    fn touched(&self) -> Option<&Touched> {
        Some(&self.touched)
    }
    #[cfg(loom)]
    fn touched(&self) -> Option<&Touched> {
        None
    }

    /// Creates a zero-filled storage buffer.
    pub fn buffer<T: Word>(&mut self, name: &str, len: u64) -> Result<Buf<T>, MemoryError> {
        self.memory.create(name, len)
    }

    /// A buffer of `len` words of `T`, each `value` ([`Memory::create_filled`]).
    pub fn buffer_filled<T: Word>(
        &mut self,
        name: &str,
        len: u64,
        value: T,
    ) -> Result<Buf<T>, MemoryError> {
        self.memory.create_filled(name, len, value)
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
        self.draw_with::<K, K>(fb, draw, state, kernel, exec, None)
    }

    /// [`Device::draw`], and with `then` the full-screen pass that follows it run tile by
    /// tile with it (`region`: only for the draws [`Device::draw_then_fullscreen`] fuses).
    fn draw_with<K: FragmentKernel, R: FragmentKernel>(
        &self,
        fb: &mut Framebuffer,
        draw: &Draw<'_>,
        state: &PassState,
        kernel: &K,
        exec: &ExecConfig,
        mut then: Option<&mut region::Then<'_, R>>,
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
            report.passes.push(PassTime {
                kernel: kernel.info().name,
                full_screen: false,
                wall: report.wall,
            });
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
        let mut seq_base = 0u64;
        // Passes that need nothing of the framebuffer skip binning (see `Binning::Auto`).
        let try_unbinned = then.is_none()
            && exec.mode == ExecMode::Parallel
            && exec.binning == Binning::Auto
            && !exec.contention
            && info.interlock.is_none()
            && crate::exec::fused::unbinned(fixed, fixed.targets.len());
        for (instance, model) in draw.instances.iter().enumerate() {
            let m = draw.view_proj * *model;
            // The clip-space positions (recycled with stale contents, every element
            // overwritten: a fresh buffer cost a serial clear and a page fault per 4 KiB, 7 MB
            // on the 871K dragon), and their projection, both kept from the last draw when
            // it drew the same positions through the same matrix.
            let mut vertices = self.vertex_cache().vertices(
                VertexKey::new(&draw.mesh.positions, m),
                &draw.mesh.positions,
                m,
                threads,
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
            let prepared = match vertices.projected.take() {
                Some(projected) => prepare_projected(
                    &vertices.clip,
                    draw.indices(),
                    &bin_state,
                    viewport,
                    threads,
                    plane_setup,
                    projected,
                ),
                None => prepare(
                    &vertices.clip,
                    draw.indices(),
                    &bin_state,
                    viewport,
                    threads,
                    plane_setup,
                ),
            };
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
            match (then.as_deref_mut(), &geo) {
                (Some(then), Geometry::Binned { binned, .. }) => {
                    let pass = region::GeometryPass {
                        binned,
                        instance,
                        first: draw.triangles.start,
                        single,
                        state: &state.fragment,
                        kernel,
                    };
                    self.run_by_region(fb, pass, then, exec, &mut report);
                }
                _ => self.run_waves(
                    fb,
                    &geo,
                    &state.fragment,
                    kernel,
                    exec,
                    &mut seq_base,
                    &mut report,
                ),
            }
            vertices.projected = Some(prepared.into_projected());
            self.vertex_cache().keep(vertices);
        }
        // The full-screen pass's share of the fused wall time is its own.
        let then_wall = then.map_or(Duration::ZERO, |t| t.report.wall);
        report.wall = start.elapsed().saturating_sub(then_wall);
        report.passes.push(PassTime {
            kernel: info.name,
            full_screen: false,
            wall: report.wall,
        });
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
        // Explicit fragments reach pixels without the rasterizer.
        if let Some(t) = self.touched() {
            t.forget();
        }
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
        // Explicit fragments reach pixels without the rasterizer.
        if let Some(t) = self.touched() {
            t.forget();
        }
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
        report.passes.push(PassTime {
            kernel: kernel.info().name,
            full_screen: true,
            wall: report.wall,
        });
        Ok(report)
    }
}
