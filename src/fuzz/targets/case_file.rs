//! The case-file parser on arbitrary bytes, and arbitrary cases (the `case_parser` target).

use arbitrary::{Arbitrary, Unstructured};
use fragrace_emu::{ExecConfig, ExecMode, Policy, ScheduleConfig};
use fragrace_kernels::Params;

use super::{violation, Violation};
use crate::case::{self, Case, Observation, Size};
use crate::run::{RunSpec, SceneSpec};
use crate::scene::Camera;

/// What [`case_parser`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CaseOutcome {
    /// The bytes parsed as a case (and round-tripped).
    pub parsed: bool,
    /// A case built from the bytes round-tripped.
    pub built: bool,
}

/// Serialises a case as [`case::write`] does and parses it back; it must come back equal.
pub fn case_round_trip(c: &Case) -> Result<(), Violation> {
    const T: &str = "case_parser";
    let json = serde_json::to_vec_pretty(c).map_err(|e| violation(T, format!("serialise: {e}")))?;
    match case::parse(&json, "<round-trip>") {
        Ok(back) if &back == c => Ok(()),
        Ok(back) => Err(violation(
            T,
            format!("round trip changed the case: {c:?} became {back:?}"),
        )),
        Err(e) => Err(violation(
            T,
            format!(
                "a parsed case does not parse back after serialising: {e}; file:\n{}",
                String::from_utf8_lossy(&json)
            ),
        )),
    }
}

/// The case-file target: [`case::parse`] never panics, a case it accepts round-trips, and a
/// case built from the same bytes ([`arbitrary_case`]) round-trips.
pub fn case_parser(data: &[u8]) -> Result<CaseOutcome, Violation> {
    let mut out = CaseOutcome {
        parsed: false,
        built: false,
    };
    if let Ok(c) = case::parse(data, "<fuzz>") {
        case_round_trip(&c)?;
        out.parsed = true;
    }
    if let Ok(c) = arbitrary_case(&mut Unstructured::new(data)) {
        case_round_trip(&c)?;
        out.built = true;
    }
    Ok(out)
}

/// A finite f32 from the bytes (JSON has no NaN or infinity; a case never holds one).
fn finite_f32(u: &mut Unstructured<'_>) -> arbitrary::Result<f32> {
    let v = f32::arbitrary(u)?;
    Ok(if v.is_finite() { v } else { 0.0 })
}

fn finite_f64(u: &mut Unstructured<'_>) -> arbitrary::Result<f64> {
    let v = f64::arbitrary(u)?;
    Ok(if v.is_finite() { v } else { 0.0 })
}

/// A case with every field drawn from `u` (finite floats; any strings, numbers, policies).
#[allow(clippy::needless_update)] // `..default()` is for fields added to ExecConfig later
pub fn arbitrary_case(u: &mut Unstructured<'_>) -> arbitrary::Result<Case> {
    let scene = match u.int_in_range(0..=2)? {
        0 => SceneSpec::Builtin(String::arbitrary(u)?),
        1 => SceneSpec::Obj {
            path: String::arbitrary(u)?.into(),
            sha256: Option::<String>::arbitrary(u)?,
        },
        _ => {
            let n = u.int_in_range(0..=6)?;
            let mut positions = Vec::with_capacity(n);
            for _ in 0..n {
                positions.push([finite_f32(u)?, finite_f32(u)?, finite_f32(u)?]);
            }
            let m = u.int_in_range(0..=4)?;
            let mut indices = Vec::with_capacity(m);
            for _ in 0..m {
                indices.push(<[u32; 3]>::arbitrary(u)?);
            }
            let radius = if bool::arbitrary(u)? {
                Some(finite_f32(u)?)
            } else {
                None
            };
            SceneSpec::Inline {
                positions,
                indices,
                radius,
            }
        }
    };
    let policy = match u.int_in_range(0..=6)? {
        0 => Policy::Random,
        1 => Policy::Pct {
            depth: u32::arbitrary(u)?,
        },
        2 => Policy::Warp {
            lanes: u32::arbitrary(u)?,
        },
        3 => Policy::Reverse,
        4 => Policy::Fifo,
        5 => Policy::FarFirst,
        _ => Policy::Bytes(Vec::<u8>::arbitrary(u)?),
    };
    let mode = match u.int_in_range(0..=2)? {
        0 => ExecMode::Ordered,
        1 => ExecMode::Parallel,
        _ => ExecMode::Scheduled(ScheduleConfig {
            policy,
            seed: u64::arbitrary(u)?,
            window: usize::arbitrary(u)?,
            record: bool::arbitrary(u)?,
            ..Default::default()
        }),
    };
    let spec = RunSpec {
        scene,
        camera: Camera {
            azimuth: finite_f32(u)?,
            elevation: finite_f32(u)?,
            fovy: finite_f32(u)?,
            fill: finite_f32(u)?,
            ..Camera::default()
        },
        width: u32::arbitrary(u)?,
        height: u32::arbitrary(u)?,
        algo: String::arbitrary(u)?,
        params: Params {
            k: u32::arbitrary(u)?,
            alpha: finite_f32(u)?,
            pool_per_pixel: if bool::arbitrary(u)? {
                Some(finite_f32(u)?)
            } else {
                None
            },
            spin_cap: u32::arbitrary(u)?,
            buckets: u32::arbitrary(u)?,
            fab_capacity: u32::arbitrary(u)?,
            background: [finite_f32(u)?, finite_f32(u)?, finite_f32(u)?],
            occupancy: if bool::arbitrary(u)? {
                Some(fragrace_kernels::occupancy::Occupancy {
                    d: u32::arbitrary(u)?,
                    range: [
                        fragrace_kernels::occupancy::RangeSource::Exact,
                        fragrace_kernels::occupancy::RangeSource::Bbox,
                        fragrace_kernels::occupancy::RangeSource::Hull,
                    ][u.int_in_range(0..=2)?],
                    fill: if bool::arbitrary(u)? {
                        fragrace_kernels::occupancy::FillMode::Plain
                    } else {
                        fragrace_kernels::occupancy::FillMode::Atomic
                    },
                })
            } else {
                None
            },
            merge: fragrace_kernels::merging::MergeParams {
                thickness: if bool::arbitrary(u)? {
                    fragrace_kernels::merging::Thickness::Fixed(finite_f32(u)?)
                } else {
                    fragrace_kernels::merging::Thickness::ZResolution {
                        multiple: finite_f32(u)?,
                        bits: u32::arbitrary(u)?,
                    }
                },
                beta: finite_f32(u)?,
            },
            range: [
                fragrace_kernels::occupancy::RangeSource::Exact,
                fragrace_kernels::occupancy::RangeSource::Bbox,
                fragrace_kernels::occupancy::RangeSource::Hull,
            ][u.int_in_range(0..=2)?],
            // Not drawn from the input (so that existing corpora decode as before).
            geometry_culling: Default::default(),
            // A file path drawn at random would read arbitrary files: never fuzzed.
            presorted: None,
        },
        exec: {
            let mut exec = ExecConfig {
                mode,
                threads: usize::arbitrary(u)?,
                batch: usize::arbitrary(u)?,
                lockstep: bool::arbitrary(u)?,
                max_steps: u64::arbitrary(u)?,
                max_waits: u64::arbitrary(u)?,
                contention: bool::arbitrary(u)?,
                // Fields added later keep their defaults (and still round-trip).
                ..ExecConfig::default()
            };
            // Drawn where it was drawn before it moved into the schedule.
            let block = u32::arbitrary(u)?;
            if let ExecMode::Scheduled(s) = &mut exec.mode {
                s.block = block;
            }
            exec
        },
    };
    let observed = Observation {
        epr: finite_f64(u)?,
        error_pixels: u64::arbitrary(u)?,
        lost_updates: u64::arbitrary(u)?,
        races: u64::arbitrary(u)?,
        torn: u64::arbitrary(u)?,
        faults: u64::arbitrary(u)?,
        dropped: u64::arbitrary(u)?,
        failed_checks: Vec::<String>::arbitrary(u)?,
        first_error: Option::<(u32, u32)>::arbitrary(u)?,
        first_hazard: Option::<String>::arbitrary(u)?,
        digest: String::arbitrary(u)?,
    };
    let size = |u: &mut Unstructured<'_>| -> arbitrary::Result<Option<Size>> {
        Ok(if bool::arbitrary(u)? {
            Some(Size {
                triangles: usize::arbitrary(u)?,
                pixels: u64::arbitrary(u)?,
                window: usize::arbitrary(u)?,
                schedule_steps: usize::arbitrary(u)?,
            })
        } else {
            None
        })
    };
    Ok(Case {
        version: case::VERSION,
        verdict: String::arbitrary(u)?,
        spec,
        observed,
        original_size: size(u)?,
        shrunk_size: size(u)?,
    })
}
