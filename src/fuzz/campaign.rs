//! A campaign: its configuration, its persistent state, the workers that run its
//! iterations, how a run's outcome becomes a finding and its signature, and the case file
//! written for each new signature.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use fragrace_emu::{ExecConfig, Policy};
use fragrace_kernels::HazardClass;
use serde::{Deserialize, Serialize};

use super::generate::{execution_spec, iteration_spec, policy_name, Shard};
use crate::case::{self, Case, Observation};
use crate::run::{self, Checked, RunSpec, SceneSpec};

/// What a campaign runs.
#[derive(Clone, Debug)]
pub struct FuzzConfig {
    pub out: PathBuf,
    pub time: Option<Duration>,
    pub iterations: Option<u64>,
    /// Algorithms to fuzz (empty: every one but `truth`).
    pub algos: Vec<String>,
    pub jobs: usize,
    pub seed: u64,
    pub resume: bool,
    /// A directory of OBJ meshes to draw scenes from, besides the built-ins.
    pub meshes: Option<PathBuf>,
    /// Time allowed to shrink each new case.
    pub shrink_budget: Duration,
    /// Largest viewport side.
    pub max_size: u32,
    /// Built-in scenes to draw from only (empty: the random mix).
    pub scenes: Vec<String>,
    /// Occupancy culling for every algorithm that takes it (`--occupancy`); `None`: none.
    pub occupancy: Option<fragrace_kernels::occupancy::Occupancy>,
    /// The slice of the iterations this run takes ([`Shard::WHOLE`]: all of them).
    pub shard: Shard,
    /// Executions per iteration: each iteration's scene is loaded and its truth computed
    /// once, then this many schedules of its run are checked against it
    /// ([`execution_spec`]). A resumed campaign keeps its own (as it keeps its seed).
    pub schedules: u64,
}

/// Schedules per generated scene by default (`fuzz --schedules`): with its scene and truth
/// computed once, the scene's setup is then a small part of an execution's time on the
/// scenes the campaigns draw (docs/performance.md, "Fuzz campaigns").
pub const DEFAULT_SCHEDULES: u64 = 16;
/// Most schedules per scene (`fuzz --schedules`).
pub const MAX_SCHEDULES: u64 = 1 << 20;

/// Where a campaign's time went, summed over its workers, in seconds: drawing each
/// iteration's run, loading its scene, computing its truth, the runs themselves (the
/// algorithm's frame and self-checks), the oracle (the comparison with the truth, the
/// verdict, the signature and observation of findings), and shrinking and writing case
/// files.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Phases {
    pub generate_s: f64,
    pub load_s: f64,
    pub truth_s: f64,
    pub run_s: f64,
    pub oracle_s: f64,
    pub cases_s: f64,
}

impl Phases {
    /// Adds `other`'s times.
    pub fn add(&mut self, other: &Phases) {
        self.generate_s += other.generate_s;
        self.load_s += other.load_s;
        self.truth_s += other.truth_s;
        self.run_s += other.run_s;
        self.oracle_s += other.oracle_s;
        self.cases_s += other.cases_s;
    }

    /// The phases by name, in order.
    pub fn named(&self) -> [(&'static str, f64); 6] {
        [
            ("scene generation", self.generate_s),
            ("scene load", self.load_s),
            ("truth", self.truth_s),
            ("run", self.run_s),
            ("oracle", self.oracle_s),
            ("shrinking and case files", self.cases_s),
        ]
    }
}

/// Runs `f`, adding its time (seconds) to `acc`.
fn timed<T>(acc: &mut f64, f: impl FnOnce() -> T) -> T {
    let t = Instant::now();
    let v = f();
    *acc += t.elapsed().as_secs_f64();
    v
}

fn one() -> u64 {
    1
}

/// The campaign's persistent state (`DIR/campaign.json`).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct CampaignState {
    pub seed: u64,
    pub algos: Vec<String>,
    /// The shard's slots below this are done (slot `j` runs iteration
    /// [`Shard::iteration`]`(j)`: iteration `j` itself without `--shard`).
    pub next_iteration: u64,
    /// The slice of the iterations this campaign runs (`--shard`); `None`: all of them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shard: Option<Shard>,
    /// The shards combined into this campaign by `fuzz --merge`, in order (empty: not a
    /// merged campaign).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub merged_shards: Vec<Shard>,
    pub executions: u64,
    pub violations: u64,
    pub expected_findings: u64,
    /// Runs per finding signature ([`signature`]: algorithm, hazard class, kinds of hazard
    /// and their buffers); one case file per signature.
    pub signatures: BTreeMap<String, u64>,
    /// Runs per "algorithm x policy".
    pub coverage: BTreeMap<String, u64>,
    pub cases: Vec<String>,
    /// The case file of each signature (campaigns saved before signatures named their
    /// case have none).
    #[serde(default)]
    pub case_of: BTreeMap<String, String>,
    pub elapsed_s: f64,
    /// Executions per iteration ([`FuzzConfig::schedules`]; campaigns saved before it
    /// existed ran one).
    #[serde(default = "one")]
    pub schedules: u64,
    /// Where the time went ([`Phases`]; zero in campaigns saved before it was measured).
    #[serde(default)]
    pub phases: Phases,
    /// Workers of the run that saved this state (`--jobs`; 0: not recorded, as in
    /// campaigns saved before it was, and merged ones). Executions per second of
    /// `elapsed_s` are all the workers' together.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub jobs: usize,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// Why a campaign cannot run.
#[derive(Debug, thiserror::Error)]
pub enum FuzzError {
    #[error("{path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}: campaign state unreadable: {source}")]
    State {
        path: String,
        source: serde_json::Error,
    },
    #[error("unknown algorithm `{0}`")]
    UnknownAlgo(String),
    #[error("{path}: the campaign there ran {found}, not {asked}: resume it with its own --shard")]
    ShardMismatch {
        path: String,
        found: String,
        asked: String,
    },
    #[error("{path}: a merged campaign cannot be resumed (resume its shards, then merge again)")]
    ResumeMerged { path: String },
    #[error("fuzz --merge: {0}")]
    Merge(String),
    #[error("{name} = {value} is out of range: it must be from {min} to {max}")]
    OutOfRange {
        name: &'static str,
        value: u64,
        min: u64,
        max: u64,
    },
}

/// Most triangles of a fuzz scene (the hairball, the largest built-in), for the memory
/// estimate of a campaign.
const FUZZ_TRIANGLES: usize = 115_200;
/// Fragments per pixel assumed for the memory estimate of a campaign (the random scenes'
/// depth complexity is lower on average; the hairball's centre is deeper).
const FUZZ_FRAGMENTS_PER_PIXEL: u64 = 16;

impl FuzzConfig {
    /// The estimated peak memory of the campaign: `jobs` runs at once, each at most as large
    /// as the largest algorithm's run at `max_size` under the scheduled executor with
    /// k = 16, checked against the truth.
    pub fn memory_estimate(&self) -> crate::budget::MemoryEstimate {
        let algos: Vec<String> = if self.algos.is_empty() {
            fragrace_kernels::names()
                .into_iter()
                .map(String::from)
                .collect()
        } else {
            self.algos.clone()
        };
        let worst = algos
            .iter()
            .map(|a| {
                let mut spec = RunSpec::new(SceneSpec::Builtin("hairball".into()), a);
                spec.width = self.max_size;
                spec.height = self.max_size;
                spec.params.k = 16;
                spec.exec = ExecConfig::scheduled(Policy::Random, 0);
                let frags = u64::from(self.max_size).pow(2) * FUZZ_FRAGMENTS_PER_PIXEL;
                crate::budget::estimate_for(&spec, frags, FUZZ_TRIANGLES, true)
            })
            .max_by_key(|e| e.bytes)
            .expect("at least one algorithm");
        let jobs = self.jobs as u64;
        crate::budget::MemoryEstimate {
            bytes: worst.bytes.saturating_mul(jobs),
            fragments: worst.fragments,
            parts: vec![(
                format!(
                    "{} jobs x {} for the largest run at --max-size {}",
                    self.jobs,
                    crate::budget::human(worst.bytes),
                    self.max_size
                ),
                worst.bytes.saturating_mul(jobs),
            )],
        }
    }

    /// Workers when `--jobs` is not given: one per CPU the process may use
    /// (`std::thread::available_parallelism`, as `cargo test` runs its tests), as many as
    /// the campaign's memory estimate allows within `limit` (bytes), and at least one (a
    /// campaign too large for one is then refused by its estimate, as before).
    pub fn default_jobs(&self, limit: u64) -> usize {
        let one = FuzzConfig {
            jobs: 1,
            ..self.clone()
        }
        .memory_estimate()
        .bytes
        .max(1);
        let fit = usize::try_from(limit / one).unwrap_or(usize::MAX);
        fragrace_emu::exec::default_threads().min(fit).max(1)
    }

    /// Checks the workers and the viewport size against their ranges (never clamped).
    pub fn validate(&self) -> Result<(), FuzzError> {
        let range = |name, value: u64, min: u64, max: u64| {
            if (min..=max).contains(&value) {
                Ok(())
            } else {
                Err(FuzzError::OutOfRange {
                    name,
                    value,
                    min,
                    max,
                })
            }
        };
        range(
            "jobs (--jobs)",
            self.jobs as u64,
            1,
            fragrace_emu::exec::max_threads() as u64,
        )?;
        range(
            "max_size (--max-size)",
            self.max_size.into(),
            8,
            fragrace_emu::framebuffer::MAX_DIMENSION.into(),
        )?;
        range("schedules (--schedules)", self.schedules, 1, MAX_SCHEDULES)
    }
}

pub(super) fn io(path: &Path) -> impl Fn(std::io::Error) -> FuzzError + '_ {
    move |source| FuzzError::Io {
        path: path.display().to_string(),
        source,
    }
}

/// Progress, for the CLI's bar.
pub struct Progress {
    pub executions: AtomicU64,
    pub cases: AtomicU64,
    pub violations: AtomicU64,
}

/// Runs a campaign until its time or iteration budget is spent or `stop` is set.
pub fn campaign(
    cfg: &FuzzConfig,
    stop: &AtomicBool,
    progress: &Progress,
) -> Result<CampaignState, FuzzError> {
    cfg.validate()?;
    std::fs::create_dir_all(&cfg.out).map_err(io(&cfg.out))?;
    let state_path = cfg.out.join("campaign.json");
    let state = if cfg.resume && state_path.exists() {
        let bytes = std::fs::read(&state_path).map_err(io(&state_path))?;
        serde_json::from_slice::<CampaignState>(&bytes).map_err(|source| FuzzError::State {
            path: state_path.display().to_string(),
            source,
        })?
    } else {
        let algos = if cfg.algos.is_empty() {
            fragrace_kernels::names()
                .into_iter()
                .filter(|n| *n != "truth")
                .map(String::from)
                .collect()
        } else {
            cfg.algos.clone()
        };
        CampaignState {
            seed: cfg.seed,
            algos,
            shard: (cfg.shard != Shard::WHOLE).then_some(cfg.shard),
            schedules: cfg.schedules,
            ..Default::default()
        }
    };
    if !state.merged_shards.is_empty() {
        return Err(FuzzError::ResumeMerged {
            path: state_path.display().to_string(),
        });
    }
    let shard = state.shard.unwrap_or(Shard::WHOLE);
    let describe = |s: Shard| {
        if s == Shard::WHOLE {
            "the whole campaign".to_string()
        } else {
            format!("--shard {s}")
        }
    };
    if shard != cfg.shard {
        return Err(FuzzError::ShardMismatch {
            path: state_path.display().to_string(),
            found: describe(shard),
            asked: describe(cfg.shard),
        });
    }
    for a in &state.algos {
        if fragrace_kernels::algorithm(a).is_none() {
            return Err(FuzzError::UnknownAlgo(a.clone()));
        }
    }
    let cfg = FuzzConfig {
        seed: state.seed,
        schedules: state.schedules.max(1),
        ..cfg.clone()
    };
    let state = CampaignState {
        jobs: cfg.jobs,
        ..state
    };
    let meshes: Vec<PathBuf> = match &cfg.meshes {
        Some(dir) => std::fs::read_dir(dir)
            .map_err(io(dir))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.to_string_lossy().contains(".obj"))
            .collect(),
        None => Vec::new(),
    };
    progress
        .executions
        .store(state.executions, Ordering::Relaxed);
    progress
        .cases
        .store(state.cases.len() as u64, Ordering::Relaxed);
    let start = Instant::now();
    let elapsed_before = state.elapsed_s;
    let next = AtomicU64::new(state.next_iteration);
    // `--iterations n` counts the campaign's iterations, not the shard's: the shards of
    // `--iterations n` together run iterations `first..first + n` once each.
    let first_iteration = state.next_iteration * shard.count;
    let shared = Mutex::new((state, std::collections::BTreeSet::<u64>::new()));
    let save = |st: &CampaignState| -> Result<(), FuzzError> {
        let json = serde_json::to_vec_pretty(st).expect("state serialises");
        crate::output::write_atomic(&state_path, &json).map_err(io(&state_path))
    };
    let jobs = cfg.jobs;
    // `jobs` workers each take the next slot until the time or the iterations are spent:
    // a queue of unknown length (the time budget) and one lock for the state, so plain
    // scoped threads rather than a work-stealing pool (there is nothing to steal).
    let result: Result<(), FuzzError> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..jobs)
            .map(|_| {
                s.spawn(|| -> Result<(), FuzzError> {
                    let stopped = || {
                        stop.load(Ordering::Relaxed)
                            || cfg.time.is_some_and(|t| start.elapsed() >= t)
                    };
                    // This worker's times since it last added them to the state.
                    let mut phases = Phases::default();
                    loop {
                        if stopped() {
                            return Ok(());
                        }
                        let slot = next.fetch_add(1, Ordering::Relaxed);
                        let i = shard.iteration(slot);
                        if cfg.iterations.is_some_and(|n| i >= first_iteration + n) {
                            return Ok(());
                        }
                        let algos = shared
                            .lock()
                            .unwrap_or_else(|e| e.into_inner())
                            .0
                            .algos
                            .clone();
                        let base = timed(&mut phases.generate_s, || {
                            iteration_spec(&cfg, &algos, &meshes, i)
                        });
                        // The scene and its truth once, for every schedule of the iteration.
                        let loaded = timed(&mut phases.load_s, || run::load(&base).ok());
                        let truth = timed(&mut phases.truth_s, || {
                            loaded.as_ref().and_then(|l| run::truth(&base, l).ok())
                        });
                        for j in 0..cfg.schedules {
                            // A time budget may end an iteration between its schedules.
                            if j > 0 && stopped() {
                                break;
                            }
                            let spec = timed(&mut phases.generate_s, || {
                                execution_spec(cfg.seed, &base, i, j)
                            });
                            let outcome = match (&loaded, &truth) {
                                (Some(l), Some(t)) => run_one(&spec, l, t, &mut phases),
                                _ => None,
                            };
                            let mut guard = shared.lock().unwrap_or_else(|e| e.into_inner());
                            let (st, _) = &mut *guard;
                            st.executions += 1;
                            st.phases.add(&std::mem::take(&mut phases));
                            progress.executions.fetch_add(1, Ordering::Relaxed);
                            *st.coverage
                                .entry(format!("{} x {}", spec.algo, policy_name(&spec)))
                                .or_default() += 1;
                            let Some((obs, verdict, violation, key)) = outcome else {
                                continue;
                            };
                            let first = !st.signatures.contains_key(&key);
                            *st.signatures.entry(key.clone()).or_default() += 1;
                            if violation {
                                st.violations += 1;
                                progress.violations.fetch_add(1, Ordering::Relaxed);
                            } else {
                                st.expected_findings += 1;
                            }
                            if !first {
                                continue;
                            }
                            drop(guard);
                            // Shrink outside the lock, then write the case atomically.
                            let written = timed(&mut phases.cases_s, || {
                                write_case(&cfg, &spec, &obs, &verdict, i, j)
                            })?;
                            let mut guard = shared.lock().unwrap_or_else(|e| e.into_inner());
                            guard.0.case_of.insert(key, written.clone());
                            guard.0.cases.push(written);
                            progress.cases.fetch_add(1, Ordering::Relaxed);
                            guard.0.elapsed_s = elapsed_before + start.elapsed().as_secs_f64();
                            save(&guard.0)?;
                        }
                        // The state's next slot is the first one not yet finished.
                        let mut guard = shared.lock().unwrap_or_else(|e| e.into_inner());
                        let (st, done) = &mut *guard;
                        st.phases.add(&std::mem::take(&mut phases));
                        done.insert(slot);
                        while done.remove(&st.next_iteration) {
                            st.next_iteration += 1;
                        }
                    }
                })
            })
            .collect();
        // Save the state every second while the workers run.
        while handles.iter().any(|h| !h.is_finished()) {
            std::thread::sleep(Duration::from_millis(200));
            let mut g = shared.lock().unwrap_or_else(|e| e.into_inner());
            g.0.elapsed_s = elapsed_before + start.elapsed().as_secs_f64();
            save(&g.0)?;
        }
        for h in handles {
            h.join().unwrap_or(Ok(()))?;
        }
        Ok(())
    });
    result?;
    let (mut state, _) = shared.into_inner().unwrap_or_else(|e| e.into_inner());
    state.elapsed_s = elapsed_before + start.elapsed().as_secs_f64();
    save(&state)?;
    Ok(state)
}

/// The signature a finding is deduplicated by: the algorithm, its hazard class and what
/// was seen, whatever policy or seed found it. With hazards, the access pattern: the most
/// telling kind of hazard seen (a lost update, else a torn record, else a race) and the
/// buffer of its first occurrence (`lost-update on kb-depth`); the other hazards of the
/// same run are its consequences more often than not. Without hazards, the kinds of anomaly
/// (error pixels, faults, failed invariants).
pub fn signature(c: &Checked, obs: &Observation) -> String {
    use fragrace_emu::HazardKind;
    let info = &c.rendered.info;
    let list = &c.rendered.result.report.hazard_list;
    let principal = [HazardKind::LostUpdate, HazardKind::Torn, HazardKind::Race]
        .into_iter()
        .find_map(|k| list.iter().find(|h| h.kind == k));
    let what = match principal {
        Some(h) => format!("{} on {}", h.kind.name(), h.buffer),
        None => obs.signature().join("+"),
    };
    // A culled run is its own variant (`NAME+occupancy`): the stage can add hazards.
    let culled = if c.rendered.result.culling.is_some() {
        "+occupancy"
    } else {
        ""
    };
    format!("{}{culled} ({}): {what}", info.name, info.hazard.name())
}

/// Runs one spec on its loaded scene and checks it against the truth;
/// `Some((observation, verdict, is_violation, signature))` when anything is anomalous. The
/// run's time goes to `phases.run_s`, the oracle's to `phases.oracle_s`.
fn run_one(
    spec: &RunSpec,
    loaded: &run::Loaded,
    truth: &fragrace_kernels::AlgoResult,
    phases: &mut Phases,
) -> Option<(Observation, String, bool, String)> {
    let rendered = timed(&mut phases.run_s, || run::render(spec, loaded).ok())?;
    timed(&mut phases.oracle_s, || {
        classify(spec, run::check_rendered(spec, rendered, truth))
    })
}

/// The verdict on a checked run (see [`run_one`]).
fn classify(spec: &RunSpec, c: Checked) -> Option<(Observation, String, bool, String)> {
    let class = c.rendered.info.hazard;
    let approximate = c.rendered.info.capacity == fragrace_kernels::Capacity::Image
        || c.rendered.result.dropped > 0;
    // Only findings need their observation (its digest hashes the whole result).
    let observe = || Observation::of(&c);
    // The plain occupancy fill races by design (it loses bits, which only moves the bound
    // farther): its hazards are expected whatever the algorithm behind it; the atomic one's
    // would be a violation.
    let plain_fill = spec
        .params
        .occupancy
        .is_some_and(|o| o.fill == fragrace_kernels::occupancy::FillMode::Plain);
    let stage_hazard = c.stage_hazards().total() > 0;
    let hazard = c.algorithm_hazards().total() > 0 || (stage_hazard && !plain_fill);
    let errors = c.metrics.error_pixels > 0 && !approximate;
    let faults = c.rendered.result.report.stats.faulted > 0;
    let broken = !c.failed_checks().is_empty();
    match class {
        HazardClass::HazardProne => (hazard
            || c.metrics.error_pixels > 0
            || faults
            || broken
            || c.rendered.result.dropped > 0)
            .then(|| {
                let obs = observe();
                let sig = signature(&c, &obs);
                (
                    obs,
                    format!("{} shows its hazard (expected: hazard-prone)", spec.algo),
                    faults || broken,
                    sig,
                )
            }),
        _ if !(hazard || errors || faults || broken) && stage_hazard => {
            let obs = observe();
            let sig = signature(&c, &obs);
            Some((
                obs,
                format!(
                    "{} behind the plain occupancy fill: the fill loses bits (expected: racy \
                     by design; Lemma 2.1 held)",
                    spec.algo
                ),
                false,
                sig,
            ))
        }
        _ => (hazard || errors || faults || broken).then(|| {
            let why = if broken {
                "invariant violated"
            } else if faults {
                "faulted"
            } else if errors {
                "differs from the truth"
            } else {
                "hazard detected"
            };
            let obs = observe();
            let sig = signature(&c, &obs);
            (
                obs,
                format!("VIOLATION: {} is {} but {why}", spec.algo, class.name()),
                true,
                sig,
            )
        }),
    }
}

fn write_case(
    cfg: &FuzzConfig,
    spec: &RunSpec,
    obs: &Observation,
    verdict: &str,
    i: u64,
    j: u64,
) -> Result<String, FuzzError> {
    let shrunk = super::shrink::shrink(spec, obs, cfg.shrink_budget);
    let case = match shrunk {
        Some(s) => Case {
            version: case::VERSION,
            verdict: verdict.into(),
            spec: s.spec,
            observed: s.observed,
            original_size: Some(s.before),
            shrunk_size: Some(s.after),
        },
        None => Case {
            version: case::VERSION,
            verdict: verdict.into(),
            spec: spec.clone(),
            observed: obs.clone(),
            original_size: None,
            shrunk_size: None,
        },
    };
    // Iteration `i`'s first execution keeps the name it had when an iteration ran one.
    let execution = if j == 0 {
        String::new()
    } else {
        format!(".{j}")
    };
    let name = format!(
        "{}-{}-{i}{execution}.json",
        spec.algo,
        obs.signature().join("+")
    );
    let path = cfg.out.join(&name);
    case::write(&path, &case).map_err(|e| FuzzError::Io {
        path: path.display().to_string(),
        source: std::io::Error::other(e.to_string()),
    })?;
    Ok(name)
}
