//! The options of one run (`render`, `check`, `bench`) as plain values, and the run they
//! describe ([`RunOptions::spec`]): every value checked and every option the executor or
//! the algorithm would ignore refused, before anything is loaded.

use std::path::PathBuf;

use fragrace_kernels::Params;

use super::error::{CliError, OptionError};
use crate::run::{self, RunSpec, SceneSpec};
use crate::scene::Camera;

/// The options of one run. Each field is the command line's option of the same name
/// (`scene_file` is `--scene-file`; `fragrace render --help` says what each means), with
/// the value parsed but not yet checked: [`RunOptions::spec`] checks it.
#[derive(Clone, Debug)]
pub struct RunOptions {
    pub scene: String,
    pub scene_file: Option<PathBuf>,
    pub obj: Vec<PathBuf>,
    pub obj_step: Option<[f32; 3]>,
    pub place: Vec<[f32; 3]>,
    pub geometry_culling: bool,
    pub algo: String,
    pub width: u32,
    pub height: u32,
    pub azimuth: f32,
    pub elevation: f32,
    pub fov: f32,
    pub distance: Option<f32>,
    pub look_at: Option<[f32; 3]>,
    pub orthographic: bool,
    pub shade: Option<crate::render::Shade>,
    pub sigma: f32,
    pub color: Vec<[f32; 3]>,
    pub opacity: Vec<f32>,
    pub turntable: Option<u32>,
    pub exec: String,
    pub policy: String,
    pub seed: u64,
    pub threads: Option<usize>,
    pub window: usize,
    pub block: u32,
    pub reduce: bool,
    pub spurious_cas: u32,
    pub lanes: usize,
    pub no_lockstep: bool,
    pub segment: u32,
    pub binning: fragrace_emu::Binning,
    pub simt: u32,
    pub spin_cap: u32,
    pub k: u32,
    pub alpha: f32,
    pub occupancy: OccupancyOptions,
    pub thickness: fragrace_kernels::merging::Thickness,
    pub beta: f32,
    pub presorted: Option<PathBuf>,
    pub out: Option<PathBuf>,
    pub raw_out: Option<PathBuf>,
    pub heatmap: Option<PathBuf>,
    pub json: bool,
    pub memory_limit: Option<String>,
}

/// The command line's defaults: `fragrace render` with no option. The binary's options
/// take their defaults from here (`--binning auto` and `--thickness 2xP`, parsed by the
/// binary, are `Binning::default()` and `Thickness::default()`).
impl Default for RunOptions {
    fn default() -> RunOptions {
        let params = Params::default();
        RunOptions {
            scene: "cubes".to_string(),
            scene_file: None,
            obj: Vec::new(),
            obj_step: None,
            place: Vec::new(),
            geometry_culling: false,
            algo: "truth".to_string(),
            width: 512,
            height: 512,
            azimuth: 0.0,
            elevation: 0.0,
            fov: 60.0,
            distance: None,
            look_at: None,
            orthographic: false,
            shade: None,
            sigma: crate::render::Look::default().sigma,
            color: Vec::new(),
            opacity: Vec::new(),
            turntable: None,
            exec: "parallel".to_string(),
            policy: "random".to_string(),
            seed: 0,
            threads: None,
            window: 64,
            block: 4,
            reduce: false,
            spurious_cas: 0,
            lanes: 64,
            no_lockstep: false,
            segment: 128,
            binning: fragrace_emu::Binning::default(),
            simt: 0,
            spin_cap: params.spin_cap,
            k: 8,
            alpha: 0.3,
            occupancy: OccupancyOptions::default(),
            thickness: fragrace_kernels::merging::Thickness::default(),
            beta: 0.0,
            presorted: None,
            out: None,
            raw_out: None,
            heatmap: None,
            json: false,
            memory_limit: None,
        }
    }
}

/// The occupancy-culling options of `render`, `check`, `bench`, `fuzz` and `report`:
/// `--occupancy D`, `--range`, `--occupancy-fill`.
#[derive(Clone, Copy, Debug, Default)]
pub struct OccupancyOptions {
    pub occupancy: Option<u32>,
    pub range: Option<fragrace_kernels::occupancy::RangeSource>,
    pub occupancy_fill: Option<fragrace_kernels::occupancy::FillMode>,
}

impl OccupancyOptions {
    /// The stage's parameters; `--range` and `--occupancy-fill` mean nothing without
    /// `--occupancy` and are refused alone (`--range` alone is the depth range of the
    /// algorithms that take one, the bucket schemes: [`takes_range`]).
    pub fn get(
        &self,
        takes_range: bool,
    ) -> Result<Option<fragrace_kernels::occupancy::Occupancy>, OptionError> {
        match self.occupancy {
            Some(d) => Ok(Some(fragrace_kernels::occupancy::Occupancy {
                d,
                range: self.range.unwrap_or_default(),
                fill: self.occupancy_fill.unwrap_or_default(),
            })),
            None if (self.range.is_some() && !takes_range) || self.occupancy_fill.is_some() => {
                Err(OptionError::OccupancyPartWithoutD)
            }
            None => Ok(None),
        }
    }
}

/// Whether any of `algos` (comma-separated) takes a depth range of its own (`--range`
/// without `--occupancy`).
pub fn takes_range(algos: &str) -> bool {
    algos
        .split(',')
        // `NAME@EXEC` (report's view sweeps) names the algorithm before the `@`.
        .map(|n| n.split('@').next().unwrap_or(n))
        .any(|n| fragrace_kernels::algorithm(n).is_some_and(|x| x.takes_range()))
}

impl RunOptions {
    /// The run the options describe, every value checked ([`RunSpec::validate`]) and every
    /// option that the executor would ignore refused, before anything is loaded. `given`
    /// names the options given on the command line (not defaulted), as typed without `--`.
    pub fn spec(&self, given: &[String]) -> Result<RunSpec, CliError> {
        let a = self;
        crate::validate::options_for_exec(&a.exec, given.iter().map(String::as_str))?;
        let mut files = Vec::with_capacity(a.obj.len());
        for p in &a.obj {
            if !p.exists() {
                return Err(CliError::NotFound { path: p.clone() });
            }
            let bytes = std::fs::read(p).map_err(CliError::read(p))?;
            files.push(run::ObjFile {
                path: p.clone(),
                sha256: Some(crate::scene::obj::content_hash(&bytes)),
            });
        }
        if !a.place.is_empty() && a.place.len() != files.len() {
            return Err(OptionError::PlaceCount {
                given: a.place.len(),
                files: files.len(),
            }
            .into());
        }
        if a.obj_step.is_some() && files.len() < 2 {
            return Err(OptionError::ObjStepWithoutTwo.into());
        }
        let mut camera = Camera {
            fovy: a.fov,
            distance: a.distance,
            look_at: a.look_at,
            projection: if a.orthographic {
                crate::scene::Projection::Orthographic
            } else {
                crate::scene::Projection::Perspective
            },
            ..Camera::new(a.azimuth, a.elevation)
        };
        // The scene file's content, read once: its camera and its hash.
        let mut scene_file = None;
        if let Some(path) = &a.scene_file {
            // The file's camera, where the command line says nothing.
            let bytes = std::fs::read(path).map_err(CliError::read(path))?;
            let file = crate::scene::file::SceneFile::parse(&bytes, path)?;
            let from_file = file.camera(camera);
            let set = |name: &str| given.iter().any(|g| g == name);
            camera = Camera {
                azimuth: if set("azimuth") {
                    camera.azimuth
                } else {
                    from_file.azimuth
                },
                elevation: if set("elevation") {
                    camera.elevation
                } else {
                    from_file.elevation
                },
                fovy: if set("fov") {
                    camera.fovy
                } else {
                    from_file.fovy
                },
                distance: camera.distance.or(from_file.distance),
                look_at: camera.look_at.or(from_file.look_at),
                ..from_file
            };
            scene_file = Some((path.clone(), bytes));
        }
        let scene = match (files.len(), scene_file) {
            (0, Some((path, bytes))) => SceneSpec::File {
                sha256: Some(crate::scene::obj::content_hash(&bytes)),
                path,
            },
            (0, None) => SceneSpec::Builtin(a.scene.clone()),
            (1, _) if a.place.is_empty() => {
                let f = files.remove(0);
                SceneSpec::Obj {
                    path: f.path,
                    sha256: f.sha256,
                }
            }
            _ => SceneSpec::Objs {
                files,
                step: a.obj_step.unwrap_or_default(),
                places: a.place.clone(),
            },
        };
        let mut exec = run::exec_config(&a.exec, &a.policy, a.seed, a.threads, a.window)?;
        // The scheduled executor's own settings (refused above under the other executors).
        if let fragrace_emu::ExecMode::Scheduled(s) = &mut exec.mode {
            s.block = a.block;
            s.reduce = a.reduce;
            s.simt = a.simt;
        }
        exec.spurious_cas_per_mille = a.spurious_cas;
        exec.batch = a.lanes;
        exec.lockstep = !a.no_lockstep;
        exec.segment = a.segment;
        exec.binning = a.binning;
        if fragrace_kernels::algorithm(&a.algo).is_none() {
            return Err(OptionError::UnknownAlgorithm {
                name: a.algo.clone(),
                known: fragrace_kernels::names(),
                preprocessed: fragrace_kernels::registry::preprocessed()
                    .iter()
                    .map(|x| x.info().name)
                    .collect(),
            }
            .into());
        }
        let spec = RunSpec {
            scene,
            camera,
            width: a.width,
            height: a.height,
            algo: a.algo.clone(),
            params: Params {
                k: a.k,
                alpha: a.alpha,
                spin_cap: a.spin_cap,
                occupancy: a.occupancy.get(takes_range(&a.algo))?,
                range: a.occupancy.range.unwrap_or_default(),
                geometry_culling: if a.geometry_culling {
                    fragrace_kernels::peeling::GeometryCulling::Queries
                } else {
                    fragrace_kernels::peeling::GeometryCulling::Off
                },
                merge: {
                    let merge = fragrace_kernels::merging::MergeParams {
                        thickness: a.thickness,
                        beta: a.beta,
                    };
                    merge.validate()?;
                    merge
                },
                presorted: a.presorted.clone(),
                ..Params::default()
            },
            exec,
        };
        spec.validate()?;
        // After the ranges: `--k 0` is out of range whatever the algorithm.
        crate::validate::options_for_algo(&a.algo, given.iter().map(String::as_str))?;
        Ok(spec)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn range_alone_is_refused_unless_an_algorithm_takes_it() {
        let range = OccupancyOptions {
            range: Some(fragrace_kernels::occupancy::RangeSource::default()),
            ..OccupancyOptions::default()
        };
        assert!(matches!(
            range.get(false),
            Err(OptionError::OccupancyPartWithoutD)
        ));
        assert!(matches!(range.get(true), Ok(None)));
        let d = OccupancyOptions {
            occupancy: Some(2),
            ..range
        };
        assert_eq!(d.get(false).expect("with D").map(|o| o.d), Some(2));
    }

    #[test]
    fn takes_range_reads_the_name_before_the_executor() {
        let bucket = fragrace_kernels::algorithms()
            .into_iter()
            .find(|a| a.takes_range())
            .expect("a bucket scheme takes a depth range")
            .info()
            .name;
        assert!(takes_range(&format!("count,{bucket}@scheduled")));
        assert!(!takes_range("count,truth"));
    }

    #[test]
    fn the_defaults_describe_a_valid_run() {
        let spec = RunOptions::default().spec(&[]).expect("the defaults run");
        assert_eq!(spec.algo, "truth");
        assert_eq!((spec.width, spec.height), (512, 512));
        assert_eq!(
            fragrace_kernels::merging::Thickness::default(),
            "2xP"
                .parse()
                .expect("the binary's default thickness parses")
        );
        assert_eq!(
            Some(fragrace_emu::Binning::default()),
            fragrace_emu::Binning::from_name("auto")
        );
    }

    #[test]
    fn spec_refuses_a_bad_option_by_name_before_loading() {
        let unknown = RunOptions {
            algo: "no-such-algorithm".into(),
            ..RunOptions::default()
        };
        let e = unknown.spec(&[]).expect_err("an unknown algorithm");
        assert!(
            e.to_string()
                .starts_with("unknown algorithm `no-such-algorithm`; known: count, "),
            "{e}"
        );
        let zero_k = RunOptions {
            algo: "kb-rmw".into(),
            k: 0,
            ..RunOptions::default()
        };
        let e = zero_k.spec(&["k".into()]).expect_err("k = 0");
        assert!(matches!(e, CliError::Spec(_)), "{e:?}");
        assert!(e.to_string().contains("(--k) = 0 is out of range"), "{e}");
        let lanes = RunOptions {
            exec: "scheduled".into(),
            ..RunOptions::default()
        };
        let e = lanes
            .spec(&["lanes".into()])
            .expect_err("--lanes under scheduled");
        assert!(matches!(e, CliError::NoEffect(_)), "{e:?}");
        let step = RunOptions {
            obj_step: Some([1.0, 0.0, 0.0]),
            ..RunOptions::default()
        };
        assert!(matches!(
            step.spec(&[]),
            Err(CliError::Option(OptionError::ObjStepWithoutTwo))
        ));
    }
}
