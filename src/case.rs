//! Case files: a complete run (scene, camera, resolution, algorithm and parameters,
//! executor, policy, seed, and the schedule itself when recorded) plus what was observed,
//! as JSON. `fragrace replay CASE` reruns it and says whether the observation still holds,
//! bit for bit. Cases are written atomically: a reader never sees half a file.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::run::{self, Checked, RunError, RunSpec};

/// Current case-file format version.
pub const VERSION: u32 = 1;

/// What a run showed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Observation {
    pub epr: f64,
    pub error_pixels: u64,
    pub lost_updates: u64,
    pub races: u64,
    pub torn: u64,
    pub faults: u64,
    pub dropped: u64,
    /// Names of the invariants that failed.
    pub failed_checks: Vec<String>,
    /// First pixel that differs from the truth.
    pub first_error: Option<(u32, u32)>,
    /// First hazard, described.
    pub first_hazard: Option<String>,
    /// sha256 of the whole result (see [`run::digest`]).
    pub digest: String,
}

impl Observation {
    pub fn of(c: &Checked) -> Observation {
        let r = &c.rendered.result;
        let hz = r.report.hazards;
        Observation {
            epr: c.metrics.epr,
            error_pixels: c.metrics.error_pixels,
            lost_updates: hz.lost_updates,
            races: hz.races,
            torn: hz.torn,
            faults: r.report.stats.faulted,
            dropped: r.dropped,
            failed_checks: c.failed_checks().iter().map(|c| c.name.clone()).collect(),
            first_error: c.metrics.first_error,
            first_hazard: r.report.hazard_list.first().map(|h| {
                format!(
                    "{} on {}[{}] at step {}: pixel ({}, {}), primitive {} vs {}",
                    h.kind.name(),
                    h.buffer,
                    h.index,
                    h.step,
                    h.victim.x,
                    h.victim.y,
                    h.victim.primitive,
                    h.other.primitive
                )
            }),
            digest: run::digest(r),
        }
    }

    /// The kinds of anomaly present (what shrinking must keep).
    pub fn signature(&self) -> Vec<&'static str> {
        let mut s = Vec::new();
        if self.error_pixels > 0 {
            s.push("error-pixels");
        }
        if self.lost_updates > 0 {
            s.push("lost-update");
        }
        if self.races > 0 {
            s.push("race");
        }
        if self.torn > 0 {
            s.push("torn");
        }
        if self.faults > 0 {
            s.push("fault");
        }
        if !self.failed_checks.is_empty() {
            s.push("invariant");
        }
        s
    }
}

/// Sizes before and after shrinking.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Size {
    pub triangles: usize,
    pub pixels: u64,
    pub window: usize,
    /// Steps of the recorded schedule (0 when not scheduled).
    pub schedule_steps: usize,
}

/// A case file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Case {
    pub version: u32,
    /// Why it was written (e.g. "hazard-free algorithm differs from the truth").
    pub verdict: String,
    pub spec: RunSpec,
    pub observed: Observation,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub original_size: Option<Size>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shrunk_size: Option<Size>,
}

/// Why a case file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum CaseError {
    /// The file could not be read or written. The cause is part of the message, not a
    /// `source`: a chain printer (`{:#}`) would print it twice.
    #[error("{path}: {error}")]
    Io { path: String, error: std::io::Error },
    #[error("{path}: not a fragrace case file: {source}")]
    Parse {
        path: String,
        source: serde_json::Error,
    },
    #[error("{path}: case file version {found}, this fragrace reads version {VERSION}")]
    Version { path: String, found: u32 },
    #[error(transparent)]
    Run(#[from] RunError),
}

/// Parses a case from bytes (any bytes: never panics).
pub fn parse(bytes: &[u8], path: &str) -> Result<Case, CaseError> {
    let case: Case = serde_json::from_slice(bytes).map_err(|source| CaseError::Parse {
        path: path.into(),
        source,
    })?;
    if case.version != VERSION {
        return Err(CaseError::Version {
            path: path.into(),
            found: case.version,
        });
    }
    Ok(case)
}

pub fn read(path: &Path) -> Result<Case, CaseError> {
    let p = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|error| CaseError::Io {
        path: p.clone(),
        error,
    })?;
    parse(&bytes, &p)
}

/// Writes a case atomically.
pub fn write(path: &Path, case: &Case) -> Result<(), CaseError> {
    let json = serde_json::to_vec_pretty(case).expect("a case always serialises");
    crate::output::write_atomic(path, &json).map_err(|error| CaseError::Io {
        path: path.display().to_string(),
        error,
    })
}

/// The outcome of a replay.
pub struct Replay {
    pub observed: Observation,
    /// Bit-identical result (same digest).
    pub exact: bool,
    /// The same kinds of anomaly are present.
    pub holds: bool,
    pub checked: Checked,
}

/// Reruns a case.
pub fn replay(case: &Case) -> Result<Replay, CaseError> {
    let loaded = run::load(&case.spec)?;
    let truth = run::truth(&case.spec, &loaded)?;
    let checked = run::check_with(&case.spec, &loaded, &truth)?;
    let observed = Observation::of(&checked);
    Ok(Replay {
        exact: observed.digest == case.observed.digest,
        holds: observed.signature() == case.observed.signature(),
        observed,
        checked,
    })
}
