//! What a pass did, and why one could not run.

use std::time::Duration;

use crate::exec::Fault;
use crate::geometry::MeshError;
use crate::hazard::{Hazard, HazardCounts};
use crate::memory::MemoryError;
use crate::raster::RasterState;
use crate::state::FragmentState;
use crate::stats::Stats;

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
    /// Each pass this report covers, in the order they ran, with its wall time (one for a
    /// pass; a merged report lists the passes merged into it), so that a reader sees
    /// where a frame goes.
    pub passes: Vec<PassTime>,
}

/// The wall time of one pass, named by its kernel.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PassTime {
    /// The kernel's [`KernelInfo::name`](crate::KernelInfo::name).
    pub kernel: &'static str,
    /// A full-screen pass (otherwise a geometry pass).
    pub full_screen: bool,
    pub wall: Duration,
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
        self.passes.extend(o.passes.iter().cloned());
    }
}
