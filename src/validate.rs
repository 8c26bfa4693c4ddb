//! Every field of a [`RunSpec`] checked against its range before a run allocates anything
//! ([`RunSpec::validate`], called by [`crate::run::load`]): a bad value from the command line
//! or a case file is refused with its name and range, never clamped or replaced.

use fragrace_emu::exec::ExecConfigError;
use fragrace_kernels::limits::ParamsError;

use crate::run::{RunSpec, SceneSpec};
use crate::scene::SceneError;

/// A field of a run out of its range.
#[derive(Debug, thiserror::Error)]
pub enum SpecError {
    #[error("viewport {0}x{1}: width and height must be from 1 to {max}", max = fragrace_emu::framebuffer::MAX_DIMENSION)]
    Viewport(u32, u32),
    #[error(transparent)]
    Camera(Box<SceneError>),
    #[error(transparent)]
    Exec(#[from] ExecConfigError),
    #[error(transparent)]
    Params(#[from] ParamsError),
    #[error("scene radius = {0} is out of range: it must be positive and finite")]
    Radius(f32),
    #[error("unknown executor `{0}`: expected ordered, parallel or scheduled")]
    UnknownExec(String),
    #[error(transparent)]
    Policy(#[from] fragrace_emu::exec::PolicyParseError),
    #[error("--{0} {1} is out of range: it must be at least 1")]
    AtLeastOne(&'static str, u64),
    #[error("unknown algorithm `{0}`; `fragrace list` shows them all")]
    UnknownAlgo(String),
    #[error(transparent)]
    Occupancy(Box<crate::run::RunError>),
    #[error(transparent)]
    Merge(#[from] fragrace_kernels::merging::MergeParamError),
    #[error("--presorted {file}: only the presorted algorithms read it, not `{algo}` (leave it out, or use --algo presorted)")]
    PresortedFile { file: String, algo: String },
}

impl RunSpec {
    /// Checks the viewport, camera, inline scene, executor settings and parameters.
    pub fn validate(&self) -> Result<(), SpecError> {
        let max = fragrace_emu::framebuffer::MAX_DIMENSION;
        if self.width == 0 || self.height == 0 || self.width > max || self.height > max {
            return Err(SpecError::Viewport(self.width, self.height));
        }
        self.camera
            .validate(self.width, self.height)
            .map_err(|e| SpecError::Camera(Box::new(e)))?;
        if let SceneSpec::Inline {
            radius: Some(r), ..
        } = &self.scene
        {
            if !(r.is_finite() && *r > 0.0) {
                return Err(SpecError::Radius(*r));
            }
        }
        let Some(algo) = fragrace_kernels::algorithm(&self.algo) else {
            return Err(SpecError::UnknownAlgo(self.algo.clone()));
        };
        self.exec.validate()?;
        self.params.validate()?;
        self.params.merge.validate()?;
        if let Some(f) = &self.params.presorted {
            if algo.info().family != "presorted" {
                return Err(SpecError::PresortedFile {
                    file: f.display().to_string(),
                    algo: self.algo.clone(),
                });
            }
        }
        // Occupancy culling: an algorithm that takes it, and a map size for its k.
        crate::culling::validate(self, &*algo).map_err(|e| SpecError::Occupancy(Box::new(e)))?;
        Ok(())
    }
}

/// Checks a count that must be at least one (`--schedules` of `check`, `--frames` of
/// `bench`).
pub fn at_least_one(option: &'static str, n: u64) -> Result<(), SpecError> {
    if n == 0 {
        return Err(SpecError::AtLeastOne(option, n));
    }
    Ok(())
}

/// Command-line options that only the scheduled executor reads.
pub const SCHEDULED_ONLY: &[&str] = &[
    "policy",
    "seed",
    "window",
    "block",
    "reduce",
    "simt",
    "schedules",
];
/// Command-line options that only the parallel executor reads.
pub const PARALLEL_ONLY: &[&str] = &["lanes", "no-lockstep", "segment", "binning"];

/// An option given on the command line that the chosen executor does not read.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("--{option} has no effect under --exec {exec}: it applies to --exec {applies} only (leave it out, or add --exec {applies})")]
pub struct NoEffect {
    pub option: String,
    pub exec: String,
    pub applies: &'static str,
}

/// Refuses options (named as on the command line, without `--`) that have no effect under
/// executor `exec`, instead of ignoring them.
pub fn options_for_exec<'a>(
    exec: &str,
    given: impl IntoIterator<Item = &'a str>,
) -> Result<(), NoEffect> {
    for option in given {
        let applies = if SCHEDULED_ONLY.contains(&option) {
            "scheduled"
        } else if PARALLEL_ONLY.contains(&option) {
            "parallel"
        } else {
            continue;
        };
        if exec != applies {
            return Err(NoEffect {
                option: option.to_string(),
                exec: exec.to_string(),
                applies,
            });
        }
    }
    Ok(())
}

/// An option given on the command line that the chosen algorithm does not read.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("--{option} has no effect on {algo}: it does not read it (leave it out); the algorithms that read --{option}: {readers}")]
pub struct NoEffectOnAlgo {
    pub option: &'static str,
    pub algo: String,
    pub readers: String,
}

/// Refuses the shared parameters given on the command line (`--k`, `--spin-cap`; named
/// without `--`) that algorithm `algo` does not read ([`fragrace_kernels::Algorithm::reads`]),
/// instead of ignoring them. An unknown algorithm passes (the run refuses it by name).
pub fn options_for_algo<'a>(
    algo: &str,
    given: impl IntoIterator<Item = &'a str>,
) -> Result<(), NoEffectOnAlgo> {
    use fragrace_kernels::Param;
    let Some(a) = fragrace_kernels::algorithm(algo) else {
        return Ok(());
    };
    let given: Vec<&str> = given.into_iter().collect();
    for p in [Param::K, Param::SpinCap] {
        if given.contains(&p.option()) && !a.reads(p) {
            let readers: Vec<&str> = fragrace_kernels::algorithms()
                .iter()
                .filter(|x| x.reads(p))
                .map(|x| x.info().name)
                .collect();
            return Err(NoEffectOnAlgo {
                option: p.option(),
                algo: algo.to_string(),
                readers: readers.join(", "),
            });
        }
    }
    Ok(())
}
