//! A geometry pass and the full-screen pass after it, run tile by tile when the full-screen
//! kernel reads by region ([`KernelInfo::by_region`]): a tiled GPU's two subpasses with a
//! by-region dependency (Vulkan's `VK_DEPENDENCY_BY_REGION_BIT`, Metal's tile shaders).
//! A worker runs a tile's fragments, then the tile's full-screen invocations, while what
//! the fragments wrote is still in its cache, instead of streaming every pass's buffers
//! through memory twice. Executors that cannot (scheduled; interlock, contention counting)
//! run the two passes one after the other.
//!
//! [`KernelInfo::by_region`]: crate::kernel::KernelInfo::by_region

use std::time::{Duration, Instant};

use crate::exec::fused::{self, FusedPass, RegionPass};
use crate::exec::{Binning, ExecConfig, ExecMode};
use crate::framebuffer::Framebuffer;
use crate::geometry::Draw;
use crate::invocation::PassEnv;
use crate::kernel::FragmentKernel;
use crate::raster::Binned;
use crate::state::{EarlyTests, FragmentState};

use super::waves::{absorb, mode_of};
use super::{Device, PassError, PassReport, PassState, PassTime};

/// The full-screen pass to run tile by tile with a draw, and its report.
pub(super) struct Then<'a, R> {
    pub state: &'a FragmentState,
    pub kernel: &'a R,
    pub report: PassReport,
}

/// The binned geometry of a draw's instance, with its pass.
pub(super) struct GeometryPass<'a, K> {
    pub binned: &'a Binned,
    pub instance: u32,
    pub first: u32,
    pub single: bool,
    pub state: &'a FragmentState,
    pub kernel: &'a K,
}

impl Device {
    /// Runs a geometry pass ([`Device::draw`] with `state` and `kernel`), then a
    /// full-screen pass ([`Device::fullscreen`] with `fs_state` and `fs_kernel`), and
    /// returns their two reports. When `fs_kernel` declares by-region reads
    /// ([`KernelInfo::with_by_region_reads`]), the `ordered` and `parallel` executors run
    /// the two passes tile by tile (a tile's fragments, then its full-screen invocations,
    /// on one worker) if nothing orders the geometry pass beyond a tile: one instance, no
    /// interlock, no contention counting, no depth or stencil test, no condition, a
    /// full-screen pass of the fused path, and a draw that is binned anyway or has few
    /// triangles for its pixels (`MIN_PIXELS_PER_TRIANGLE`). Otherwise, and under the
    /// scheduled executor, the passes run one after the other. Each pass's invocations, ids, counts, target
    /// writes and errors are those of the two calls; only the interleaving of the two
    /// passes' invocations differs, so the images are the same and buffers differ only
    /// where invocations of different pixels took shared counters in another order. The
    /// fused passes' wall times are their workers' shares of the fused time.
    ///
    /// [`KernelInfo::with_by_region_reads`]: crate::KernelInfo::with_by_region_reads
    #[allow(clippy::too_many_arguments)] // the arguments of the two calls it stands for
    pub fn draw_then_fullscreen<K: FragmentKernel, R: FragmentKernel>(
        &self,
        fb: &mut Framebuffer,
        draw: &Draw<'_>,
        state: &PassState,
        kernel: &K,
        fs_state: &FragmentState,
        fs_kernel: &R,
        exec: &ExecConfig,
    ) -> Result<(PassReport, PassReport), PassError> {
        let (info, fs_info) = (kernel.info(), fs_kernel.info());
        let fixed = &state.fragment;
        let fuses = matches!(exec.mode, ExecMode::Ordered | ExecMode::Parallel)
            && !exec.contention
            && fs_info.by_region
            && info.interlock.is_none()
            && fs_info.interlock.is_none()
            && draw.instances.len() == 1
            && state.condition.is_none()
            && !fixed.depth.test
            && !fixed.stencil.enabled
            && fs_state.targets.len() <= fb.formats.len()
            && fused::fullscreen_fuses(fs_state, fb.samples.count() as u32)
            && binning_pays(draw, fb, exec);
        if !fuses {
            let geometry = self.draw(fb, draw, state, kernel, exec)?;
            let full = self.fullscreen(fb, fs_state, fs_kernel, exec)?;
            return Ok((geometry, full));
        }
        let mut report = PassReport::default();
        report.stats.fullscreen_passes = 1;
        let mut then = Some(Then {
            state: fs_state,
            kernel: fs_kernel,
            report,
        });
        let geometry = self.draw_with(fb, draw, state, kernel, exec, then.as_mut())?;
        let then = then.expect("kept");
        let mut full = then.report;
        full.passes.push(PassTime {
            kernel: fs_info.name,
            full_screen: true,
            wall: full.wall,
        });
        Ok((geometry, full))
    }

    /// The two passes of [`Device::draw_then_fullscreen`] over the binned geometry of one
    /// instance, tile by tile ([`fused::run_by_region`]); the full-screen pass's counts and
    /// share of the time go to `then.report`.
    pub(super) fn run_by_region<K: FragmentKernel, R: FragmentKernel>(
        &self,
        fb: &mut Framebuffer,
        geo: GeometryPass<'_, K>,
        then: &mut Then<'_, R>,
        exec: &ExecConfig,
        report: &mut PassReport,
    ) {
        let start = Instant::now();
        let (info, fs_info) = (geo.kernel.info(), then.kernel.info());
        let early = match geo.state.early {
            EarlyTests::ForceEarly => true,
            EarlyTests::ForceLate => false,
            EarlyTests::Auto => !info.may_discard && !info.writes_depth,
        };
        let parallel = exec.mode == ExecMode::Parallel;
        let env = |tris, no_interpolants| PassEnv {
            memory: &self.memory,
            tris,
            width: fb.width,
            height: fb.height,
            samples: fb.samples.count() as u32,
            interlock: None,
            interlock_mode: None,
            sample_tickets: &[],
            mode: mode_of(exec),
            max_steps: exec.max_steps,
            max_waits: exec.max_waits,
            spurious_cas: exec.spurious_cas_per_mille,
            contention: None,
            no_interpolants,
        };
        let geo_env = env(&geo.binned.tris[..], !info.interpolants);
        let fs_env = env(&[], !fs_info.interpolants);
        let (fw, fh) = (fb.width, fb.height);
        // The geometry pass marks its blocks; the full-screen pass reads the same mask,
        // a tile's blocks after the tile's fragments marked them.
        let touched = self.touched();
        let marks = touched.and_then(|t| t.for_marking(fw, fh));
        let fs_targets = then.state.targets.len();
        let untouched_output = fs_info.untouched_output.filter(|_| fs_targets <= 1);
        let reads = untouched_output
            .and(touched)
            .and_then(|t| t.for_reading(fw, fh));
        let pass = |state, early, targets, flat_depth| FusedPass {
            state,
            instance: 0,
            first: 0,
            single: false,
            early,
            targets,
            lanes: if parallel { exec.batch.max(1) } else { 1 },
            lockstep: parallel && exec.lockstep,
            threads: if parallel { exec.threads.max(1) } else { 1 },
            // One worker per tile: the full-screen pass writes the tile's targets.
            segment: None,
            seq_base: 0,
            flat_depth,
            touched: None,
            untouched_output: None,
        };
        let geo_pass = FusedPass {
            instance: geo.instance,
            first: geo.first,
            single: geo.single,
            touched: marks.as_deref(),
            ..pass(geo.state, early, geo.state.targets.len(), f32::NAN)
        };
        let fs_pass = FusedPass {
            touched: reads.as_deref(),
            untouched_output,
            ..pass(then.state, false, fs_targets, 0.5)
        };
        let (g, r, imbalance) = fused::run_by_region(
            RegionPass {
                kernel: geo.kernel,
                env: &geo_env,
                pass: &geo_pass,
            },
            geo.binned,
            RegionPass {
                kernel: then.kernel,
                env: &fs_env,
                pass: &fs_pass,
            },
            fb.tiles_mut(),
        );
        g.counts.add_to(&mut report.stats);
        absorb(report, g.outcome, &self.memory);
        let full = &mut then.report;
        full.imbalance += imbalance;
        r.counts.add_to(&mut full.stats);
        absorb(full, r.outcome, &self.memory);
        // The full-screen pass's share of the fused time (by its workers' busy time).
        let busy = g.busy + r.busy;
        let fused_wall = start.elapsed();
        full.wall = if busy.is_zero() {
            Duration::ZERO
        } else {
            fused_wall.mul_f64(r.busy.as_secs_f64() / busy.as_secs_f64())
        };
    }
}

/// Fewest pixels per drawn triangle for [`Device::draw_then_fullscreen`] to bin a geometry
/// pass that would otherwise run unbinned (`Binning::Auto` on the `parallel` executor):
/// fusing saves per fragment (the full-screen pass finds the tile's words in the cache),
/// binning costs per triangle. Alternating runs (docs/performance.md, "2026-11-28, early
/// morning"): the bunny at 2048 x 2048 (1142 pixels a triangle) gained a quarter of its
/// passes' time, the 871K dragon at 2048 x 2048 (4.8 pixels a triangle) nothing.
pub(super) const MIN_PIXELS_PER_TRIANGLE: u64 = 64;

/// Whether the geometry pass of a fused [`Device::draw_then_fullscreen`] costs no binning
/// it would not have had (ordered, or `Binning::Always`), or little for its pixels.
fn binning_pays(draw: &Draw<'_>, fb: &Framebuffer, exec: &ExecConfig) -> bool {
    let pixels = u64::from(fb.width) * u64::from(fb.height);
    exec.mode == ExecMode::Ordered
        || exec.binning == Binning::Always
        || draw.indices().len() as u64 * MIN_PIXELS_PER_TRIANGLE <= pixels
}
