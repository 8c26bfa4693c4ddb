//! Fuzzing, in one module by concept:
//!
//! - [`campaign`]: `fragrace fuzz`: random scenes x random algorithms and parameters x
//!   random executors, policies and seeds, each run checked against the truth and against
//!   the algorithm's declared hazard class. A hazard-free algorithm that differs from the
//!   truth, shows a hazard, faults or breaks an invariant is a *violation*; a hazard-prone
//!   one showing its hazard is an *expected finding*. Findings are deduplicated by
//!   signature ([`signature`]); the first run of each new signature is shrunk and written as
//!   a case file. Campaigns lose nothing when killed: cases and the campaign state are
//!   written atomically as they happen, and `--resume` continues where the state file says.
//! - [`generate`]: the run of each iteration, a pure function of (campaign seed, iteration),
//!   the schedules run on each iteration's scene (its scene and truth computed once), and
//!   the [`Shard`]s that split a campaign's iterations into disjoint slices.
//! - [`merge`](mod@merge): `fuzz --merge`: shards' case directories combined into one campaign.
//! - [`shrink`](mod@shrink): reducing a failing run while it fails the same way.
//! - [`targets`]: the logic of the cargo-fuzz targets in `fuzz/` (libFuzzer, ClusterFuzzLite).

pub mod campaign;
pub mod generate;
pub mod merge;
pub mod shrink;
pub mod targets;

pub use campaign::{
    campaign, signature, CampaignState, FuzzConfig, FuzzError, Phases, Progress, DEFAULT_SCHEDULES,
    MAX_SCHEDULES,
};
pub use generate::{execution_spec, iteration_spec, Shard, ShardError};
pub use merge::merge;
