//! The options of one run (`render`, `check`, `bench`) as plain values, and the run they
//! describe ([`RunOptions::spec`]): every value checked and every option the executor or
//! the algorithm would ignore refused, before anything is loaded.

use std::path::PathBuf;

use fragrace_kernels::Params;

use super::error::{CliError, OptionError};
use super::parse::{parse_binning, parse_step, parse_thickness};
use crate::run::{self, RunSpec, SceneSpec};
use crate::scene::Camera;

/// The options of one run, which are also the command line's (`render`, `check` and
/// `bench` flatten them: each field is the option of the same name, `scene_file` is
/// `--scene-file`, and its doc comment is the option's help). A value is parsed but not
/// yet checked: [`RunOptions::spec`] checks it.
#[derive(Clone, Debug, clap::Args)]
pub struct RunOptions {
    /// A built-in scene (see `fragrace list`).
    #[arg(long, default_value_t = RunOptions::default().scene, conflicts_with_all = ["obj", "scene_file"])]
    pub scene: String,
    /// A scene file (JSON: OBJ objects with placements, colours and opacities, and a
    /// camera; README "Scene files").
    #[arg(long, value_name = "PATH", conflicts_with = "obj")]
    pub scene_file: Option<PathBuf>,
    /// An OBJ file (plain or .gz) instead of a built-in scene; repeated, a scene of several
    /// objects (one per file; see --geometry-culling).
    #[arg(long)]
    pub obj: Vec<PathBuf>,
    /// With several --obj: file i is moved by i times this vector (X,Y,Z, in the files'
    /// units), e.g. the same file three times in a row.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_step, requires = "obj")]
    pub obj_step: Option<[f32; 3]>,
    /// Where each --obj file goes: repeated once per file, in order (X,Y,Z in the files'
    /// units, added to --obj-step's move); --scene-file also rotates and scales.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_step, allow_negative_numbers = true, requires = "obj")]
    pub place: Vec<[f32; 3]>,
    /// Multi-pass peelers (front-to-back and dual): per iteration an occlusion query of each
    /// object's bounding box against what is left to peel, and conditional rendering of the
    /// objects (completely peeled ones are culled; depth-fighting paper, section 3.3).
    #[arg(long)]
    pub geometry_culling: bool,
    #[arg(long, default_value_t = RunOptions::default().algo)]
    pub algo: String,
    #[arg(long, default_value_t = RunOptions::default().width)]
    pub width: u32,
    #[arg(long, default_value_t = RunOptions::default().height)]
    pub height: u32,
    /// Degrees about +Y (0: eye on +Z, 90: on +X).
    #[arg(long, default_value_t = RunOptions::default().azimuth, allow_negative_numbers = true)]
    pub azimuth: f32,
    #[arg(long, default_value_t = RunOptions::default().elevation, allow_negative_numbers = true)]
    pub elevation: f32,
    /// Vertical field of view, degrees.
    #[arg(long, default_value_t = RunOptions::default().fov)]
    pub fov: f32,
    /// Distance from the eye to the point looked at (default: the bounding sphere fills
    /// 80 % of the view), in units of the normalised scene (largest extent 1).
    #[arg(long)]
    pub distance: Option<f32>,
    /// The point looked at (default the scene's centre, the origin).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_step, allow_negative_numbers = true)]
    pub look_at: Option<[f32; 3]>,
    /// Parallel projection instead of perspective.
    #[arg(long)]
    pub orthographic: bool,
    /// How --out shades kept fragments: lit (headlight, Lambert and Blinn-Phong, materials'
    /// colour and opacity), translucent (Beer-Lambert absorption through the layers),
    /// fresnel (translucent times Fresnel transmittance), id (the algorithm's own composite in
    /// the peer's hash colours at --alpha). Default: lit for `render` (id for the algorithms
    /// that keep only an image), id for `check`.
    #[arg(long)]
    pub shade: Option<crate::render::Shade>,
    /// Translucent and fresnel shading: absorption per unit of the normalised scene; a
    /// channel absorbs sigma (1 - its colour).
    #[arg(long, default_value_t = RunOptions::default().sigma)]
    pub sigma: f32,
    /// Colour R,G,B (each in [0, 1]) of every object, or repeated: of each object in order.
    #[arg(long, value_name = "R,G,B", value_parser = parse_step)]
    pub color: Vec<[f32; 3]>,
    /// Opacity in [0, 1] of every object, or repeated: of each object in order (lit shading).
    #[arg(long, allow_negative_numbers = true)]
    pub opacity: Vec<f32>,
    /// Render N views around the scene (azimuth + 360 i / N) to --out: an animated GIF
    /// when it ends in .gif, else numbered PNGs (NAME-000.png, ...).
    #[arg(long, value_name = "N", requires = "out")]
    pub turntable: Option<u32>,
    /// ordered | parallel | scheduled
    #[arg(long, default_value_t = RunOptions::default().exec)]
    pub exec: String,
    /// Scheduling policy: random, pct:D, warp:N, reverse, fifo, far-first, bytes:HEX.
    #[arg(long, default_value_t = RunOptions::default().policy)]
    pub policy: String,
    #[arg(long, default_value_t = RunOptions::default().seed)]
    pub seed: u64,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Invocations in flight under the scheduled executor.
    #[arg(long, default_value_t = RunOptions::default().window)]
    pub window: usize,
    /// Scheduled: pixels per side of the blocks fragments are admitted by.
    #[arg(long, default_value_t = RunOptions::default().block)]
    pub block: u32,
    /// Scheduled: interleave only invocations about to touch the same address or pixel.
    #[arg(long)]
    pub reduce: bool,
    /// Per-mille probability that a weak compare-exchange fails spuriously.
    #[arg(long, default_value_t = RunOptions::default().spurious_cas)]
    pub spurious_cas: u32,
    /// Parallel: lanes per warp (fragments shaded together by one thread).
    #[arg(long, default_value_t = RunOptions::default().lanes)]
    pub lanes: usize,
    /// Parallel: lanes run one after the other instead of in SIMT lockstep (one memory
    /// access each per turn). Faster; races then come only from other threads.
    #[arg(long)]
    pub no_lockstep: bool,
    /// Parallel: most triangles of one tile per unit of work; smaller units put more
    /// threads on one tile at once (when the pass's fixed-function results commute).
    #[arg(long, default_value_t = RunOptions::default().segment)]
    pub segment: u32,
    /// Parallel: `auto` runs passes that need nothing of the framebuffer (no depth or
    /// stencil test, no colour target: counting, captures) unbinned, chunks of triangles
    /// set up, rasterized and shaded by whichever thread takes them; `always` bins every
    /// pass into tiles.
    #[arg(long, default_value = "auto", value_parser = parse_binning)]
    pub binning: fragrace_emu::Binning,
    /// Scheduled: lockstep forward progress in warps of N lanes (no independent thread
    /// scheduling, as on pre-Volta GPUs): lanes spinning in a loop hold back their
    /// warp-mates past it, so a spinlock whose holder shares their warp deadlocks.
    /// 0: lanes progress independently.
    #[arg(long, default_value_t = RunOptions::default().simt)]
    pub simt: u32,
    /// kb-spinlock: lock attempts before a fragment gives up (4294967295: never).
    #[arg(long, default_value_t = RunOptions::default().spin_cap)]
    pub spin_cap: u32,
    /// k of the k-buffers.
    #[arg(long, default_value_t = RunOptions::default().k)]
    pub k: u32,
    /// Opacity of every fragment in the OIT composite.
    #[arg(long, default_value_t = RunOptions::default().alpha)]
    pub alpha: f32,
    #[command(flatten)]
    pub occupancy: OccupancyOptions,
    /// Merging algorithms: the z-thickness of every fragment, `NxP` (N times the z-resolution
    /// P(z) of a 24-bit depth buffer, equation 9; `NxP:BITS` for other precisions) or a
    /// fixed view depth (e.g. 0.01).
    #[arg(long, default_value = "2xP", value_parser = parse_thickness)]
    pub thickness: fragrace_kernels::merging::Thickness,
    /// Merging algorithms: beta of equation 4 (SFM: 0 exact optics, 1 linear), in [0, 1].
    #[arg(long, default_value_t = RunOptions::default().beta)]
    pub beta: f32,
    /// The presorted algorithms: lists written by `fragrace presort` for this mesh (without
    /// it, the mesh is preprocessed first, with 6 partitions).
    #[arg(long, value_name = "FILE")]
    pub presorted: Option<PathBuf>,
    /// Output PNG.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// For `count`: per-pixel counts as little-endian u32, row-major, top row first.
    #[arg(long)]
    pub raw_out: Option<PathBuf>,
    /// Directory for heatmaps (depth complexity, errors, hazards, image difference, culled,
    /// bucket collisions).
    #[arg(long)]
    pub heatmap: Option<PathBuf>,
    /// Print one JSON object on stdout.
    #[arg(long)]
    pub json: bool,
    /// Refuse runs whose estimated peak memory is above this (e.g. 8G, 512M; default: half
    /// of the physical memory).
    #[arg(long, value_name = "SIZE")]
    pub memory_limit: Option<String>,
}

/// The command line's defaults: `fragrace render` with no option. The options take their
/// defaults from here (`--binning auto` and `--thickness 2xP`, parsed by
/// [`super::parse`], are `Binning::default()` and `Thickness::default()`).
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
#[derive(Clone, Copy, Debug, Default, clap::Args)]
pub struct OccupancyOptions {
    /// Occupancy-map culling in front of the k-buffer's capture pass, with D words (32 D
    /// depth sub-intervals) per pixel, 1 to 64 and at least k/32 (`fragrace list` says
    /// which algorithms take it).
    #[arg(long, value_name = "D")]
    pub occupancy: Option<u32>,
    /// Occupancy culling, and the bucket schemes (bdp, bdp2, adp): the per-pixel depth
    /// range from the scene (`exact`), its bounding box (`bbox`) or its convex hull
    /// (`hull`). Default exact.
    #[arg(long)]
    pub range: Option<fragrace_kernels::occupancy::RangeSource>,
    /// Occupancy culling: set the map's bits with `atomic` OR (default), or with a `plain`
    /// load, OR and store (racy by design: bits are lost).
    #[arg(long)]
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
