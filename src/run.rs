//! One run of one algorithm on one scene, and its check against the truth: what `render`,
//! `check`, `replay`, `fuzz` and the tests all call.

use std::path::PathBuf;
use std::time::Instant;

use fragrace_emu::{ExecConfig, ExecMode, HazardCounts, Policy, ScheduleConfig};
use fragrace_kernels::oracle::{compare, Metrics};
use fragrace_kernels::{basic::Truth, AlgoInfo, AlgoResult, Frame, Params};
use serde::{Deserialize, Serialize};

use crate::scene::{Camera, Scene, SceneError};

/// Where the scene comes from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SceneSpec {
    /// A built-in scene by name (with parameters, e.g. `coplanar-stack:16`).
    Builtin(String),
    /// An OBJ file (plain or gzip); `sha256` of its bytes, checked on replay when present.
    Obj {
        path: PathBuf,
        sha256: Option<String>,
    },
    /// Several OBJ files (`--obj A --obj B ...`), one object each (geometry culling draws
    /// and culls them one by one), normalised together. File `i` is moved by `i x step` in
    /// the files' own units (`--obj-step X,Y,Z`: the same file three times in a row, as the
    /// depth-fighting paper's three dragons of Figure 10), and by `places[i]` when given
    /// (`--place X,Y,Z` once per file; empty: not moved).
    Objs {
        files: Vec<ObjFile>,
        #[serde(default)]
        step: [f32; 3],
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        places: Vec<[f32; 3]>,
    },
    /// A scene file (`--scene-file`, JSON: objects with placements and materials, and a
    /// camera; [`crate::scene::file`]); `sha256` of its bytes, checked on replay when
    /// present (the OBJ files it names are not hashed).
    File {
        path: PathBuf,
        sha256: Option<String>,
    },
    /// Triangles inline (fuzz and shrunk cases). With `radius`, the positions are taken as
    /// already normalised and the camera frames a sphere of that radius (so a subset of a
    /// scene's triangles renders exactly as they did in the whole scene); without it they
    /// are normalised like any mesh.
    Inline {
        positions: Vec<[f32; 3]>,
        indices: Vec<[u32; 3]>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        radius: Option<f32>,
    },
}

/// One file of [`SceneSpec::Objs`]: its path and the sha256 of its bytes (checked on
/// replay when present).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjFile {
    pub path: PathBuf,
    pub sha256: Option<String>,
}

/// Checks an OBJ file's bytes against the hash a case recorded.
fn check_hash(path: &PathBuf, sha256: &Option<String>) -> Result<(), RunError> {
    if let Some(want) = sha256 {
        let bytes = std::fs::read(path).map_err(|source| RunError::Io {
            path: path.clone(),
            source,
        })?;
        let got = crate::scene::obj::content_hash(&bytes);
        if &got != want {
            return Err(RunError::HashMismatch {
                path: path.clone(),
                want: want.clone(),
                got,
            });
        }
    }
    Ok(())
}

impl SceneSpec {
    /// Loads the scene (checking an OBJ's hash if one is given).
    pub fn load(&self) -> Result<Scene, RunError> {
        Ok(match self {
            SceneSpec::Builtin(name) => Scene::builtin(name).map_err(Box::new)?,
            SceneSpec::Obj { path, sha256 } => {
                check_hash(path, sha256)?;
                Scene::from_obj(path).map_err(Box::new)?
            }
            SceneSpec::Objs {
                files,
                step,
                places,
            } => {
                let mut parts = Vec::with_capacity(files.len());
                for (i, f) in files.iter().enumerate() {
                    check_hash(&f.path, &f.sha256)?;
                    let mut part = crate::scene::Part::from_obj(&f.path, i).map_err(Box::new)?;
                    let place = glam::Vec3::from_array(places.get(i).copied().unwrap_or_default());
                    part.placement = glam::Mat4::from_translation(
                        glam::Vec3::from_array(*step) * i as f32 + place,
                    );
                    parts.push(part);
                }
                Scene::from_parts(parts).map_err(Box::new)?
            }
            SceneSpec::File { path, sha256 } => {
                check_hash(path, sha256)?;
                let file = crate::scene::file::SceneFile::read(path).map_err(Box::new)?;
                let parts = file
                    .parts(&crate::scene::file::folder(path))
                    .map_err(Box::new)?;
                Scene::from_parts(parts).map_err(Box::new)?
            }
            SceneSpec::Inline {
                positions,
                indices,
                radius,
            } => {
                let mesh = fragrace_emu::Mesh {
                    positions: positions
                        .iter()
                        .map(|p| glam::Vec3::from_array(*p))
                        .collect(),
                    normals: None,
                    indices: indices.clone(),
                };
                match radius {
                    Some(r) if r.is_finite() && *r > 0.0 => {
                        mesh.validate().map_err(|source| {
                            Box::new(SceneError::InvalidMesh {
                                name: "inline".into(),
                                source,
                            })
                        })?;
                        Scene {
                            name: "inline".into(),
                            mesh,
                            radius: *r,
                            objects: Vec::new(),
                            surface: None,
                        }
                    }
                    _ => Scene::from_mesh("inline", mesh).map_err(Box::new)?,
                }
            }
        })
    }

    /// A short name for reports.
    pub fn name(&self) -> String {
        match self {
            SceneSpec::Builtin(n) => n.clone(),
            SceneSpec::Obj { path, .. } | SceneSpec::File { path, .. } => {
                path.display().to_string()
            }
            SceneSpec::Objs { files, .. } => files
                .iter()
                .map(|f| f.path.display().to_string())
                .collect::<Vec<_>>()
                .join("+"),
            SceneSpec::Inline { indices, .. } => format!("inline({} triangles)", indices.len()),
        }
    }
}

/// Everything that defines a run; serialisable, so a case file holds one.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunSpec {
    pub scene: SceneSpec,
    #[serde(default)]
    pub camera: Camera,
    pub width: u32,
    pub height: u32,
    pub algo: String,
    #[serde(default)]
    pub params: Params,
    pub exec: ExecConfig,
}

impl RunSpec {
    /// A run of `algo` on a built-in scene at 512x512 from the default camera, ordered.
    pub fn new(scene: SceneSpec, algo: &str) -> RunSpec {
        RunSpec {
            scene,
            camera: Camera::default(),
            width: 512,
            height: 512,
            algo: algo.to_string(),
            params: Params::default(),
            exec: ExecConfig::default(),
        }
    }

    /// The policy and seed, when scheduled.
    pub fn schedule(&self) -> Option<&ScheduleConfig> {
        match &self.exec.mode {
            ExecMode::Scheduled(s) => Some(s),
            _ => None,
        }
    }

    /// The same run with another seed.
    pub fn with_seed(&self, seed: u64) -> RunSpec {
        let mut s = self.clone();
        if let ExecMode::Scheduled(sc) = &mut s.exec.mode {
            sc.seed = seed;
        }
        s
    }

    /// A command line that reproduces this run, in the README's form (`cargo run --release
    /// -- VERB ...`, from the repository). An inline scene (fuzz and shrunk cases) has no
    /// command-line form: its case file replays it (`replay CASE.json`).
    pub fn command(&self, verb: &str) -> String {
        let scene = match &self.scene {
            SceneSpec::Builtin(n) => format!("--scene {n}"),
            SceneSpec::Obj { path, .. } => format!("--obj {}", path.display()),
            SceneSpec::File { path, .. } => format!("--scene-file {}", path.display()),
            SceneSpec::Objs {
                files,
                step,
                places,
            } => {
                let mut c: Vec<String> = files
                    .iter()
                    .enumerate()
                    .map(|(i, f)| match places.get(i) {
                        Some([x, y, z]) => {
                            format!("--obj {} --place {x},{y},{z}", f.path.display())
                        }
                        None => format!("--obj {}", f.path.display()),
                    })
                    .collect();
                if *step != [0.0; 3] {
                    c.push(format!("--obj-step {},{},{}", step[0], step[1], step[2]));
                }
                c.join(" ")
            }
            SceneSpec::Inline { .. } => return format!("{CLI} replay CASE.json"),
        };
        // `--k` and `--spin-cap` only where the algorithm reads them (elsewhere the command
        // line refuses them).
        let reads = |p| fragrace_kernels::algorithm(&self.algo).is_none_or(|a| a.reads(p));
        let k = if reads(fragrace_kernels::Param::K) {
            format!(" --k {}", self.params.k)
        } else {
            String::new()
        };
        let mut c = format!(
            "{CLI} {verb} {scene} --algo {} --width {} --height {} --azimuth {} --elevation {}{k} --exec {}",
            self.algo, self.width, self.height, self.camera.azimuth, self.camera.elevation,
            self.exec.mode.name()
        );
        if self.camera.fovy != Camera::default().fovy {
            c += &format!(" --fov {}", self.camera.fovy);
        }
        if let Some(d) = self.camera.distance {
            c += &format!(" --distance {d}");
        }
        if let Some([x, y, z]) = self.camera.look_at {
            c += &format!(" --look-at {x},{y},{z}");
        }
        if self.camera.projection == crate::scene::Projection::Orthographic {
            c += " --orthographic";
        }
        if self.params.spin_cap != Params::default().spin_cap
            && reads(fragrace_kernels::Param::SpinCap)
        {
            c += &format!(" --spin-cap {}", self.params.spin_cap);
        }
        if let Some(o) = self.params.occupancy {
            c += &format!(
                " --occupancy {} --range {} --occupancy-fill {}",
                o.d,
                o.range.name(),
                o.fill.name()
            );
        } else if self.params.range != Default::default() {
            // The bucket schemes' depth range (`Params::range`).
            c += &format!(" --range {}", self.params.range.name());
        }
        if !self.params.geometry_culling.is_off() {
            c += " --geometry-culling";
        }
        if self.params.merge != Params::default().merge {
            c += &format!(
                " --thickness {} --beta {}",
                self.params.merge.thickness, self.params.merge.beta
            );
        }
        if let Some(f) = &self.params.presorted {
            c += &format!(" --presorted {}", f.display());
        }
        if let Some(s) = self.schedule() {
            c += &format!(
                " --policy {} --seed {} --window {} --block {}",
                s.policy, s.seed, s.window, s.block
            );
            if s.reduce {
                c += " --reduce";
            }
            if self.exec.spurious_cas_per_mille > 0 {
                c += &format!(" --spurious-cas {}", self.exec.spurious_cas_per_mille);
            }
            if s.simt > 0 {
                c += &format!(" --simt {}", s.simt);
            }
        } else if self.exec.mode == ExecMode::Parallel {
            c += &format!(
                " --threads {} --lanes {} --segment {}",
                self.exec.threads, self.exec.batch, self.exec.segment
            );
            if !self.exec.lockstep {
                c += " --no-lockstep";
            }
            if self.exec.binning != fragrace_emu::Binning::Auto {
                c += &format!(" --binning {}", self.exec.binning.name());
            }
        }
        c
    }
}

/// How printed commands start: the README's way to run fragrace from the repository (after
/// `cargo install --path .`, `fragrace` alone does the same).
pub const CLI: &str = "cargo run --release --";

/// Why a run could not happen.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Scene(#[from] Box<SceneError>),
    #[error("unknown algorithm `{0}`; `fragrace list` shows them all")]
    UnknownAlgo(String),
    #[error(transparent)]
    Algo(#[from] fragrace_kernels::AlgoError),
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: sha256 is {got}, but the case was recorded with {want}", path.display())]
    HashMismatch {
        path: PathBuf,
        want: String,
        got: String,
    },
    #[error(transparent)]
    Spec(#[from] crate::validate::SpecError),
}

/// A loaded scene plus its frame.
pub struct Loaded {
    pub scene: Scene,
    pub view_proj: glam::Mat4,
}

impl Loaded {
    pub fn frame(&self, spec: &RunSpec) -> Frame<'_> {
        Frame {
            mesh: &self.scene.mesh,
            objects: &self.scene.objects,
            view_proj: self.view_proj,
            width: spec.width,
            height: spec.height,
        }
    }
}

/// Checks the spec ([`RunSpec::validate`]) and loads its scene.
pub fn load(spec: &RunSpec) -> Result<Loaded, RunError> {
    spec.validate()?;
    let scene = spec.scene.load()?;
    let view_proj = scene.view_proj(&spec.camera, spec.width, spec.height);
    Ok(Loaded { scene, view_proj })
}

/// One algorithm run.
pub struct Rendered {
    pub info: AlgoInfo,
    pub result: AlgoResult,
    /// The frame: clears, passes and resolve
    /// ([`run_frame`](fragrace_kernels::Algorithm::run_frame)).
    pub wall_ms: f64,
    /// The self-checks run after it ([`self_check`](fragrace_kernels::Algorithm::self_check);
    /// nearly zero for the algorithms whose checks are part of the frame).
    pub check_ms: f64,
}

/// Runs the algorithm of `spec` on an already loaded scene: its frame, then its
/// self-checks, timed apart.
pub fn render(spec: &RunSpec, loaded: &Loaded) -> Result<Rendered, RunError> {
    let algo = fragrace_kernels::algorithm(&spec.algo)
        .ok_or_else(|| RunError::UnknownAlgo(spec.algo.clone()))?;
    crate::culling::validate(spec, &*algo)?;
    if !spec.params.geometry_culling.is_off() && !algo.takes_geometry_culling() {
        return Err(RunError::Algo(fragrace_kernels::AlgoError::Invalid(
            format!(
                "--geometry-culling: {} does not take it; the peelers that do: {}",
                spec.algo,
                fragrace_kernels::algorithms()
                    .iter()
                    .filter(|a| a.takes_geometry_culling())
                    .map(|a| a.info().name)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )));
    }
    let info = algo.info();
    let frame = loaded.frame(spec);
    let t = Instant::now();
    let mut result = algo.run_frame(&frame, &spec.params, &spec.exec)?;
    let wall_ms = t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    algo.self_check(&mut result, &spec.exec);
    Ok(Rendered {
        info,
        result,
        wall_ms,
        check_ms: t.elapsed().as_secs_f64() * 1e3,
    })
}

/// The truth of a frame (computed once, shared by many checks).
pub fn truth(spec: &RunSpec, loaded: &Loaded) -> Result<AlgoResult, RunError> {
    Ok(Truth::capture(&loaded.frame(spec), spec.exec.threads)?)
}

/// A run checked against the truth.
pub struct Checked {
    pub rendered: Rendered,
    pub metrics: Metrics,
}

impl Checked {
    pub fn hazards(&self) -> HazardCounts {
        self.rendered.result.report.hazards
    }
    /// Hazards of the occupancy-culling stage's passes (none without culling).
    pub fn stage_hazards(&self) -> HazardCounts {
        self.rendered
            .result
            .culling
            .as_ref()
            .map(|c| c.stage_hazards)
            .unwrap_or_default()
    }
    /// Hazards of the algorithm's own passes: all of them less the culling stage's.
    pub fn algorithm_hazards(&self) -> HazardCounts {
        let (all, stage) = (self.hazards(), self.stage_hazards());
        HazardCounts {
            lost_updates: all.lost_updates - stage.lost_updates,
            races: all.races - stage.races,
            torn: all.torn - stage.torn,
        }
    }
    /// Invariants that failed.
    pub fn failed_checks(&self) -> Vec<&fragrace_kernels::Check> {
        self.rendered
            .result
            .checks
            .iter()
            .filter(|c| !c.passed)
            .collect()
    }
    /// Whether anything at all went wrong (error pixels, hazards, faults, failed invariants).
    pub fn anomalous(&self) -> bool {
        self.metrics.error_pixels > 0
            || self.hazards().total() > 0
            || self.rendered.result.report.stats.faulted > 0
            || !self.failed_checks().is_empty()
    }
}

/// Runs and checks one spec against a given truth.
pub fn check_with(
    spec: &RunSpec,
    loaded: &Loaded,
    truth: &AlgoResult,
) -> Result<Checked, RunError> {
    let rendered = render(spec, loaded)?;
    Ok(check_rendered(spec, rendered, truth))
}

/// The oracle alone: a rendered run compared with the truth (and the occupancy stage's
/// checks), as [`check_with`] does after rendering.
pub fn check_rendered(spec: &RunSpec, mut rendered: Rendered, truth: &AlgoResult) -> Checked {
    let metrics = compare(&rendered.info, &rendered.result, truth, &spec.params);
    let culling_checks = crate::culling::checks(&metrics, &rendered.result);
    rendered.result.checks.extend(culling_checks);
    Checked { rendered, metrics }
}

/// The summary of a run as one JSON object (the CLI's `--json`).
pub fn summary_json(
    spec: &RunSpec,
    loaded: &Loaded,
    checked: Option<&Checked>,
    rendered: &Rendered,
) -> serde_json::Value {
    let r = &rendered.result;
    let (policy, seed) = match spec.schedule() {
        Some(s) => (
            serde_json::json!(s.policy.to_string()),
            serde_json::json!(s.seed),
        ),
        None => (serde_json::Value::Null, serde_json::Value::Null),
    };
    let counts = r.counts.as_ref();
    let covered = checked
        .map(|c| c.metrics.covered_pixels)
        .or_else(|| counts.map(|c| c.iter().filter(|&&v| v > 0).count() as u64));
    let max_dc = checked
        .map(|c| c.metrics.max_depth_complexity)
        .or_else(|| counts.map(|c| c.iter().copied().max().unwrap_or(0)));
    let hz = r.report.hazards;
    let mut v = serde_json::json!({
        "algo": spec.algo,
        "scene": spec.scene.name(),
        "triangles": loaded.scene.mesh.triangle_count(),
        "width": spec.width,
        "height": spec.height,
        "azimuth": spec.camera.azimuth,
        "elevation": spec.camera.elevation,
        "exec": spec.exec.mode.name(),
        "policy": policy,
        "seed": seed,
        "threads": spec.exec.threads,
        "k": spec.params.k,
        // Rasterized fragments of the scene (truth's count when checked; otherwise per
        // geometry pass, as multipass algorithms rasterize the scene several times).
        "fragments": checked.map(|c| c.metrics.generated).unwrap_or(
            r.report.stats.fragments_generated / u64::from(r.report.stats.geometry_passes.max(1))
        ),
        "covered_pixels": covered,
        "max_depth_complexity": max_dc,
        "hazards": { "lost_updates": hz.lost_updates, "races": hz.races, "torn": hz.torn },
        "faults": r.report.stats.faulted,
        "dropped": r.dropped,
        // Bucket schemes: fragments that lost their bucket to another (total, worst pixel).
        "collisions": r.collisions.as_ref().map(|c| {
            serde_json::json!({
                "total": c.iter().map(|&x| u64::from(x)).sum::<u64>(),
                "max_per_pixel": c.iter().copied().max().unwrap_or(0),
                "pixels": c.iter().filter(|&&x| x > 0).count(),
            })
        }),
        "storage_bytes": r.storage_bytes,
        "bytes_per_pixel": r.storage_bytes as f64 / (spec.width as f64 * spec.height as f64),
        "passes": { "geometry": r.report.stats.geometry_passes, "fullscreen": r.report.stats.fullscreen_passes },
        // Geometry passes per frame (the bucket paper's Table 2 measure); also in `passes`.
        "geometry_passes": r.report.stats.geometry_passes,
        "stats": r.report.stats,
        "checks": r.checks,
        "hazard_class": rendered.info.hazard.name(),
        "wall_ms": rendered.wall_ms,
        "check_ms": rendered.check_ms,
        // Threads of the parallel executor waiting at the end of shading for the last one,
        // summed over threads (`PassReport::imbalance`).
        "imbalance_ms": r.report.imbalance.as_secs_f64() * 1e3,
        "epr": serde_json::Value::Null,
    });
    if let Some(c) = checked {
        v["epr"] = serde_json::json!(c.metrics.epr);
        v["error_pixels"] = serde_json::json!(c.metrics.error_pixels);
        v["robustness"] = serde_json::json!(c.metrics.robustness);
        v["coplanarity"] = serde_json::json!(c.metrics.coplanarity);
        v["first_error"] = serde_json::json!(c.metrics.first_error);
        v["image"] = serde_json::json!(c.metrics.image);
    }
    if let Some(g) = &r.geometry_culling {
        // Objects drawn and occlusion queries issued per iteration (depth-fighting paper,
        // section 3.3).
        v["geometry_culling"] = serde_json::json!(g);
    }
    if r.culling.is_some() {
        v["occupancy"] = crate::culling::summary(rendered, checked.map(|c| &c.metrics), None);
    }
    v
}

/// A digest (sha256, hex) of everything a run produced: captured fragments, counts, image
/// bits, hazards and faults. Equal digests = bit-identical runs.
pub fn digest(r: &AlgoResult) -> String {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    if let Some(c) = &r.capture {
        for o in &c.offsets {
            h.update(o.to_le_bytes());
        }
        for f in &c.frags {
            h.update(f.depth.to_bits().to_le_bytes());
            h.update(f.prim.to_le_bytes());
        }
    }
    if let Some(c) = &r.counts {
        for v in c {
            h.update(v.to_le_bytes());
        }
    }
    if let Some(img) = &r.image {
        for p in img {
            for c in p {
                h.update(c.to_bits().to_le_bytes());
            }
        }
    }
    let hz = r.report.hazards;
    h.update(format!(
        "{}/{}/{}/{}/{}",
        hz.lost_updates, hz.races, hz.torn, r.report.stats.faulted, r.dropped
    ));
    h.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

/// Parses an executor description from CLI-style parts (the values are checked by
/// [`RunSpec::validate`], not clamped here).
pub fn exec_config(
    exec: &str,
    policy: &str,
    seed: u64,
    threads: Option<usize>,
    window: usize,
) -> Result<ExecConfig, crate::validate::SpecError> {
    let threads = threads.unwrap_or_else(fragrace_emu::exec::default_threads);
    let mode = match exec {
        "ordered" => ExecMode::Ordered,
        "parallel" => ExecMode::Parallel,
        "scheduled" => {
            let policy: Policy = policy.parse()?;
            ExecMode::Scheduled(ScheduleConfig {
                policy,
                seed,
                window,
                record: false,
                ..Default::default()
            })
        }
        other => return Err(crate::validate::SpecError::UnknownExec(other.to_string())),
    };
    Ok(ExecConfig {
        mode,
        threads,
        ..ExecConfig::default()
    })
}
