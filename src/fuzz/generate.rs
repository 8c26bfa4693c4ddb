//! Case generation: the run of each iteration of a campaign, a pure function of the
//! campaign's seed and the iteration's number, and the shards that split the iterations
//! between machines.

use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

use fragrace_emu::{ExecConfig, ExecMode, Policy, ScheduleConfig};
use fragrace_kernels::Params;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

use super::FuzzConfig;
use crate::run::{RunSpec, SceneSpec};
use crate::scene::Camera;

/// One of `count` disjoint slices of a campaign's iterations (`--shard INDEX/COUNT`, INDEX
/// from 1): iteration `i` belongs to shard `i % count + 1`. The shards of one seed together
/// run each iteration exactly once, so N machines (a Slurm array, a CI matrix, GNU
/// parallel) can each run one and `fuzz --merge` combine them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct Shard {
    /// From 1 to `count`.
    pub index: u64,
    pub count: u64,
}

/// Why a `--shard` value is refused.
#[derive(Debug, PartialEq, Eq, thiserror::Error)]
pub enum ShardError {
    #[error("--shard `{0}`: expected INDEX/COUNT, e.g. 1/4")]
    Syntax(String),
    #[error("--shard {index}/{count}: COUNT must be from 1 to {max}, and INDEX from 1 to COUNT")]
    OutOfRange { index: u64, count: u64, max: u64 },
}

impl Shard {
    /// The whole campaign (what a run without `--shard` is).
    pub const WHOLE: Shard = Shard { index: 1, count: 1 };
    /// Most shards of a campaign (iteration numbers stay far from overflowing).
    pub const MAX_COUNT: u64 = 1 << 20;

    /// Checks the ranges (never clamped).
    pub fn new(index: u64, count: u64) -> Result<Shard, ShardError> {
        if !(1..=Self::MAX_COUNT).contains(&count) || !(1..=count).contains(&index) {
            return Err(ShardError::OutOfRange {
                index,
                count,
                max: Self::MAX_COUNT,
            });
        }
        Ok(Shard { index, count })
    }

    /// The campaign's iteration run by this shard's `slot`-th run (its slots are 0, 1, 2...).
    pub fn iteration(self, slot: u64) -> u64 {
        slot * self.count + (self.index - 1)
    }

    /// Whether iteration `i` belongs to this shard.
    pub fn contains(self, i: u64) -> bool {
        i % self.count == self.index - 1
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl FromStr for Shard {
    type Err = ShardError;

    fn from_str(s: &str) -> Result<Shard, ShardError> {
        let syntax = || ShardError::Syntax(s.to_string());
        let (i, n) = s.split_once('/').ok_or_else(syntax)?;
        let i: u64 = i.trim().parse().map_err(|_| syntax())?;
        let n: u64 = n.trim().parse().map_err(|_| syntax())?;
        Shard::new(i, n)
    }
}

/// The run of iteration `i`.
pub fn iteration_spec(cfg: &FuzzConfig, algos: &[String], meshes: &[PathBuf], i: u64) -> RunSpec {
    let mut rng = SmallRng::seed_from_u64(cfg.seed ^ i.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let pick = rng.gen_range(0..10);
    let scene = if !cfg.scenes.is_empty() {
        SceneSpec::Builtin(cfg.scenes[pick % cfg.scenes.len()].clone())
    } else {
        match pick {
            0 => SceneSpec::Builtin("cubes".into()),
            1 => SceneSpec::Builtin(format!("coplanar-stack:{}", rng.gen_range(2..12))),
            2 => SceneSpec::Builtin("spheres".into()),
            3 => SceneSpec::Builtin("hairball".into()),
            4 if !meshes.is_empty() => SceneSpec::Obj {
                path: meshes[rng.gen_range(0..meshes.len())].clone(),
                sha256: None,
            },
            4 | 5 => SceneSpec::Builtin(["bunny", "teapot"][rng.gen_range(0..2)].into()),
            _ => SceneSpec::Builtin(format!(
                "random-triangles:{}:{}",
                rng.gen::<u32>(),
                rng.gen_range(1..48)
            )),
        }
    };
    let algo = algos[rng.gen_range(0..algos.len())].clone();
    let size = rng.gen_range(8..=cfg.max_size);
    let policies = Policy::all();
    let exec = if rng.gen_bool(0.85) {
        let policy = if rng.gen_bool(0.15) {
            Policy::Bytes((0..rng.gen_range(0..64)).map(|_| rng.gen()).collect())
        } else {
            policies[rng.gen_range(0..policies.len())].clone()
        };
        let window = [2, 4, 8, 16, 32, 64][rng.gen_range(0..6)];
        ExecConfig {
            mode: ExecMode::Scheduled(ScheduleConfig {
                policy,
                seed: rng.gen(),
                window,
                record: false,
                ..Default::default()
            }),
            threads: 1,
            ..ExecConfig::default()
        }
    } else {
        ExecConfig::parallel(2)
    };
    let k = [1, 2, 4, 8, 16][rng.gen_range(0..5)];
    let camera = Camera::new(rng.gen_range(0.0..360.0), rng.gen_range(-60.0..60.0));
    let mut exec = exec;
    // Drawn last, so the rest of every spec is what it was before the mode existed.
    if let ExecMode::Scheduled(s) = &mut exec.mode {
        if rng.gen_bool(0.1) {
            s.simt = [4, 32][rng.gen_range(0..2)];
        }
    }
    // Occupancy culling, for the algorithms that take it, when the campaign asks for it.
    let takes = fragrace_kernels::algorithm(&algo).is_some_and(|a| a.takes_occupancy());
    let occupancy = cfg.occupancy.filter(|_| takes);
    RunSpec {
        scene,
        camera,
        width: size,
        height: size,
        algo,
        params: Params {
            k,
            occupancy,
            ..Params::default()
        },
        exec,
    }
}

/// The run of execution `j` of iteration `i`, whose scene, view, algorithm and executor
/// settings are `base`'s (iteration `i`'s spec): execution 0 is `base` itself, and each later
/// one draws another schedule of the same run: another seed under the scheduled executor
/// (and another byte string, of another length, for `bytes:` schedules), a pure function of the campaign's seed,
/// `i` and `j`. Under the parallel executor the run is repeated as it is: its interleavings
/// are the threads' timing, another on every run.
pub fn execution_spec(campaign_seed: u64, base: &RunSpec, i: u64, j: u64) -> RunSpec {
    let mut spec = base.clone();
    if j == 0 {
        return spec;
    }
    let mut rng = SmallRng::seed_from_u64(
        campaign_seed
            ^ i.wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ j.wrapping_mul(0xD1B5_4A32_D192_ED03),
    );
    if let ExecMode::Scheduled(s) = &mut spec.exec.mode {
        s.seed = rng.gen();
        if let Policy::Bytes(b) = &mut s.policy {
            // As `iteration_spec` draws them: up to 63 bytes.
            let len = rng.gen_range(0..64);
            b.clear();
            b.extend((0..len).map(|_| rng.gen::<u8>()));
        }
    }
    spec
}

pub(super) fn policy_name(spec: &RunSpec) -> String {
    let name: String = match &spec.exec.mode {
        ExecMode::Scheduled(s) => match &s.policy {
            Policy::Bytes(_) => "bytes".into(),
            Policy::Pct { .. } => "pct".into(),
            Policy::Warp { .. } => "warp".into(),
            p => p.to_string(),
        },
        m => m.name().into(),
    };
    if spec.schedule().is_some_and(|s| s.simt > 0) {
        name + "+simt"
    } else {
        name
    }
}
