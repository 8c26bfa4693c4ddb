//! Executors: who runs which kernel invocation when.
//!
//! - [`ExecMode::Ordered`]: one invocation at a time, in API order: the reference.
//! - [`ExecMode::Parallel`]: real worker threads and real atomics. A pass's fragments are
//!   cut into batches (warps) that workers take in API order, so fragments of one pixel
//!   run at the same time on different threads; within a batch the lanes advance in
//!   lockstep, one memory access each in turn (`lockstep`), as a SIMT warp does.
//! - [`ExecMode::Scheduled`]: one thread, a window of in-flight invocations, and a seeded
//!   [`Policy`] that picks who takes the next step (one memory access, interlock entry or
//!   exit). Same inputs and seed: bit-identical result. Every step goes through the
//!   [`crate::hazard::Detector`].
//! - [`run_on_threads`]: one thread per invocation; under `--cfg loom` these are loom
//!   threads, and loom explores the interleavings (the `loom` executor).
//!
//! Every shading loop lives here: `direct` (the ordered and parallel executors on fragment
//! lists), `scheduled` (the scheduled executor, and its admission of a rasterized pass's
//! waves: blocks, per-wave seeds, `bytes:` schedules that run on across waves), `fused`
//! (the ordered and parallel executors rasterizing, shading and writing one unit of tile
//! work at a time), `threads` (one thread per invocation); `slots` is what they share.
//!
//! This module knows no algorithm, and nothing of passes or devices: it is handed fragment
//! inputs in API order (or, on the fused path, set-up triangles and tiles) and a kernel, and
//! returns each fragment's outputs.

mod direct;
pub(crate) mod fused;
mod legacy;
mod limits;
mod policy;
mod scheduled;
mod simt;
mod slots;
mod threads;

pub(crate) use direct::{shade, shade_lists};
pub use limits::{max_threads, ExecConfigError, MAX_LANES, MAX_SIMT, MAX_WINDOW};
pub use policy::{Policy, PolicyParseError};
pub use scheduled::Execution;
pub(crate) use scheduled::{explore, Waves};
pub use slots::Fault;
pub(crate) use slots::{record_panic, Acc, FragOut, ShadeOutcome, Tally};
pub use threads::{run_on_threads, ThreadOutcome};

/// Configuration of the `scheduled` executor.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ScheduleConfig {
    pub policy: Policy,
    pub seed: u64,
    /// Invocations in flight at once (the GPU's occupancy).
    pub window: usize,
    /// Record the schedule (one byte per step) for replay with [`Policy::Bytes`].
    pub record: bool,
    /// Fragments of a rasterized pass are admitted block by block (`block` x `block`
    /// pixels, each block's fragments in API order), as a GPU's fine rasterizer hands out
    /// small screen tiles; so overlapping primitives of one block are in flight together.
    #[serde(default = "default_block")]
    pub block: u32,
    /// Interleave only where it can matter. When some runnable invocation's next access
    /// touches an address (or pixel) another in-flight invocation is about to touch, the
    /// policy chooses among those; otherwise the earliest runs on. Fragments of different
    /// pixels on different addresses commute, so the steps go where hazards can be.
    #[serde(default)]
    pub reduce: bool,
    /// Lockstep forward progress, as on GPUs without independent thread scheduling
    /// (pre-Volta SIMT). Invocations form warps of `simt` lanes in admission order, and
    /// within a warp, lanes that keep spinning in a loop run before lanes past it, so a lock
    /// holder whose warp-mates spin on its lock never gets to release it: a
    /// [`crate::FaultKind::SimtDeadlock`]. 0: lanes progress independently (the default).
    /// See `docs/verification.md` for the rule and what it cannot see.
    #[serde(default)]
    pub simt: u32,
}

impl Default for ScheduleConfig {
    fn default() -> Self {
        ScheduleConfig {
            policy: Policy::Random,
            seed: 0,
            window: 64,
            record: false,
            block: default_block(),
            reduce: false,
            simt: 0,
        }
    }
}

/// Which executor runs the invocations.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum ExecMode {
    Ordered,
    Parallel,
    Scheduled(ScheduleConfig),
}

impl ExecMode {
    pub fn name(&self) -> &'static str {
        match self {
            ExecMode::Ordered => "ordered",
            ExecMode::Parallel => "parallel",
            ExecMode::Scheduled(_) => "scheduled",
        }
    }
}

/// Executor configuration.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(from = "legacy::ExecConfigFile")]
pub struct ExecConfig {
    pub mode: ExecMode,
    /// Worker threads (rasterization and the parallel executor).
    pub threads: usize,
    /// Fragments per batch (warp) in the parallel executor.
    pub batch: usize,
    /// Parallel executor: lanes of a batch take turns at every memory access (SIMT
    /// lockstep); otherwise each lane runs to completion before the next starts.
    pub lockstep: bool,
    /// Watchdog: most steps one invocation may take.
    pub max_steps: u64,
    /// Watchdog: most times one invocation may find the interlock taken (direct modes).
    pub max_waits: u64,
    /// Measure per-address contention in the parallel executor (three extra atomics per
    /// access).
    pub contention: bool,
    /// Per-mille probability that a weak compare-exchange
    /// ([`crate::Frag::atomic_compare_exchange_weak`]) fails spuriously (decided by a hash
    /// of the invocation and its step count: deterministic for a given schedule).
    #[serde(default)]
    pub spurious_cas_per_mille: u32,
    /// Parallel executor: most triangles of one tile in one unit of work. A tile with more
    /// is cut into several units that different threads rasterize and shade at the same
    /// time, so fragments of one pixel run concurrently on different threads, as on a GPU
    /// (only in passes whose fixed-function results do not depend on order: no colour
    /// targets, no stencil, no depth writes; other passes keep a tile on one thread).
    #[serde(default = "default_segment")]
    pub segment: u32,
    /// Parallel executor: whether triangles are binned into tiles for every pass, or only
    /// where a pass needs the framebuffer (see [`Binning`]).
    // Left out of case files when it is the default: older files stay as they were.
    #[serde(default, skip_serializing_if = "Binning::is_auto")]
    pub binning: Binning,
}

/// How the parallel executor hands geometry to its workers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Binning {
    /// Passes that need nothing of the framebuffer (no depth or stencil test, no colour
    /// target: counting and capture passes) run unbinned: workers take chunks of triangles
    /// in turn and set up, rasterize and shade each chunk at once, so no bin lists are
    /// written or read. Fragments of one pixel from different chunks race across threads.
    /// Other passes are binned into tiles.
    #[default]
    Auto,
    /// Every pass is binned into tiles (the only way before unbinned passes existed; kept
    /// to compare the two).
    Always,
}

impl Binning {
    fn is_auto(&self) -> bool {
        *self == Binning::Auto
    }

    pub const ALL: [Binning; 2] = [Binning::Auto, Binning::Always];

    pub fn name(self) -> &'static str {
        match self {
            Binning::Auto => "auto",
            Binning::Always => "always",
        }
    }

    /// The binning a [`Binning::name`] names.
    pub fn from_name(name: &str) -> Option<Binning> {
        Binning::ALL.into_iter().find(|b| b.name() == name)
    }
}

pub(crate) fn default_segment() -> u32 {
    128
}

pub(crate) fn default_block() -> u32 {
    4
}

impl Default for ExecConfig {
    fn default() -> Self {
        ExecConfig {
            mode: ExecMode::Parallel,
            threads: default_threads(),
            batch: 64,
            lockstep: true,
            max_steps: 1 << 20,
            max_waits: 1 << 26,
            contention: false,
            spurious_cas_per_mille: 0,
            segment: default_segment(),
            binning: Binning::Auto,
        }
    }
}

impl ExecConfig {
    pub fn ordered() -> ExecConfig {
        ExecConfig {
            mode: ExecMode::Ordered,
            ..Default::default()
        }
    }
    pub fn parallel(threads: usize) -> ExecConfig {
        ExecConfig {
            mode: ExecMode::Parallel,
            threads: threads.max(1),
            ..Default::default()
        }
    }
    pub fn scheduled(policy: Policy, seed: u64) -> ExecConfig {
        ExecConfig {
            mode: ExecMode::Scheduled(ScheduleConfig {
                policy,
                seed,
                ..Default::default()
            }),
            ..Default::default()
        }
    }
}

/// All cores.
pub fn default_threads() -> usize {
    std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
}
