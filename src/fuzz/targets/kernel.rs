//! Every kernel against its oracle under arbitrary schedules (the `kernel_oracle` target).

use std::sync::OnceLock;

use arbitrary::Arbitrary;
use fragrace_emu::{ExecConfig, ExecMode, Policy, ScheduleConfig};
use fragrace_kernels::abuffer::LinkedList;
use fragrace_kernels::{Algorithm, HazardClass, Params};

use super::{decode, violation, Violation};
use crate::run::{self, RunSpec, SceneSpec};
use crate::scene::Camera;

/// The input of [`kernel_oracle`].
#[derive(Arbitrary, Clone, Debug)]
pub struct KernelInput {
    /// The algorithm: `algo % (n + 1)`-th of the registry's `n`; `n` selects the linked list
    /// with its planted bug ([`KernelInput::planted`] builds such an input).
    pub algo: u8,
    /// Viewport: 4 to 24 pixels each way.
    pub width: u8,
    pub height: u8,
    /// k of the k-buffers: 1 to 8.
    pub k: u8,
    /// Invocations in flight: 2 to 8.
    pub window: u8,
    /// Azimuth and elevation.
    pub camera: [i8; 2],
    /// Up to 9 vertices (coordinates / 16) and 6 triangles (indices modulo the vertices).
    pub vertices: Vec<[i8; 3]>,
    pub triangles: Vec<[u8; 3]>,
    /// The schedule: at step s, run the `schedule[s] % n`-th runnable invocation.
    pub schedule: Vec<u8>,
}

/// The algorithms the oracle target picks from (registry order).
pub fn oracle_algorithms() -> &'static [&'static str] {
    static NAMES: OnceLock<Vec<&'static str>> = OnceLock::new();
    NAMES.get_or_init(fragrace_kernels::names)
}

impl KernelInput {
    /// The selector value of the planted-bug mode.
    pub fn planted_selector() -> u8 {
        oracle_algorithms().len() as u8
    }
    /// Whether this input runs the planted bug.
    pub fn planted(&self) -> bool {
        self.algo as usize % (oracle_algorithms().len() + 1) == oracle_algorithms().len()
    }

    fn spec(&self, algo: &str) -> Option<RunSpec> {
        let nv = self.vertices.len().min(9);
        if nv < 3 || self.triangles.is_empty() {
            return None;
        }
        let positions = self.vertices[..nv]
            .iter()
            .map(|v| v.map(|c| c as f32 / 16.0))
            .collect();
        let indices = self
            .triangles
            .iter()
            .take(6)
            .map(|t| t.map(|i| (i as usize % nv) as u32))
            .collect();
        Some(RunSpec {
            scene: SceneSpec::Inline {
                positions,
                indices,
                radius: None,
            },
            camera: Camera::new(
                self.camera[0] as f32 * 1.5,
                self.camera[1] as f32 / 128.0 * 80.0,
            ),
            width: 4 + self.width as u32 % 21,
            height: 4 + self.height as u32 % 21,
            algo: algo.to_string(),
            params: Params {
                k: 1 + self.k as u32 % 8,
                ..Params::default()
            },
            exec: ExecConfig {
                mode: ExecMode::Scheduled(ScheduleConfig {
                    policy: Policy::Bytes(self.schedule.clone()),
                    seed: 0,
                    window: 2 + self.window as usize % 7,
                    record: false,
                    ..Default::default()
                }),
                threads: 1,
                max_steps: 1 << 16,
                ..ExecConfig::default()
            },
        })
    }
}

/// What [`kernel_oracle`] did.
#[derive(Clone, Debug, PartialEq)]
pub enum KernelOutcome {
    /// The input makes no scene (fewer than 3 vertices, no triangle, a degenerate mesh).
    Skipped,
    /// A registry algorithm ran and kept its hazard-class contract.
    Checked {
        algo: &'static str,
        class: HazardClass,
        epr: f64,
        /// Hazards, faults, failed checks or error pixels (allowed only to hazard-prone
        /// algorithms, and error pixels to approximate ones).
        anomalous: bool,
    },
    /// The linked list with its planted bug ran; `found`: the schedule exposed it (the
    /// detector saw a torn record, or the in-pass reader a half-written node).
    Planted { found: bool, torn: u64 },
}

/// The oracle target on raw bytes.
pub fn kernel_oracle(data: &[u8]) -> Result<KernelOutcome, Violation> {
    match decode::<KernelInput>(data) {
        Some(input) => kernel_oracle_input(&input),
        None => Ok(KernelOutcome::Skipped),
    }
}

/// The oracle target on a decoded input. The contract checked, by declared hazard class:
/// a hazard-free or needs-interlock algorithm has no failed invariant, no fault, no hazard,
/// and, unless it dropped fragments (capacity overflow: which ones is order-dependent), the
/// same error pixels against the truth under this schedule as under the `ordered`
/// executor (0 for the exact ones; approximations such as `wboit` may differ from the
/// truth, but identically). A hazard-prone algorithm may show anything but a panic.
pub fn kernel_oracle_input(input: &KernelInput) -> Result<KernelOutcome, Violation> {
    const T: &str = "kernel_oracle";
    let names = oracle_algorithms();
    let planted = input.planted();
    let name = if planted {
        "ll"
    } else {
        names[input.algo as usize % (names.len() + 1)]
    };
    let Some(spec) = input.spec(name) else {
        return Ok(KernelOutcome::Skipped);
    };
    let Ok(loaded) = run::load(&spec) else {
        return Ok(KernelOutcome::Skipped);
    };
    if planted {
        let bug = LinkedList::planted_bug();
        let r = bug
            .run(&loaded.frame(&spec), &spec.params, &spec.exec)
            .map_err(|e| violation(T, format!("ll planted bug: run failed: {e}")))?;
        let half = r
            .checks
            .iter()
            .any(|c| c.name.contains("half-written") && !c.passed);
        if let Some(c) = r
            .checks
            .iter()
            .find(|c| !c.passed && !c.name.contains("half-written"))
        {
            // The bug is latent after the pass: everything else must hold.
            return Err(violation(
                T,
                format!("ll planted bug broke `{}`: {} ({spec:?})", c.name, c.detail),
            ));
        }
        let torn = r.report.hazards.torn;
        return Ok(KernelOutcome::Planted {
            found: torn > 0 || half,
            torn,
        });
    }
    let truth = run::truth(&spec, &loaded)
        .map_err(|e| violation(T, format!("truth failed on a loadable scene: {e}")))?;
    let ordered_spec = RunSpec {
        exec: ExecConfig {
            threads: 1,
            ..ExecConfig::ordered()
        },
        ..spec.clone()
    };
    let Ok(reference) = run::check_with(&ordered_spec, &loaded, &truth) else {
        // The algorithm refuses these parameters (under every executor).
        return Ok(KernelOutcome::Skipped);
    };
    let checked = run::check_with(&spec, &loaded, &truth).map_err(|e| {
        violation(
            T,
            format!("{name} ran under `ordered` but failed under the schedule: {e} ({spec:?})"),
        )
    })?;
    let info = &checked.rendered.info;
    let result = &checked.rendered.result;
    if info.hazard != HazardClass::HazardProne {
        let class = info.hazard.name();
        let fail = |what: String| violation(T, format!("{name} ({class}): {what}; spec {spec:?}"));
        if let Some(c) = checked.failed_checks().first() {
            return Err(fail(format!("invariant `{}` failed: {}", c.name, c.detail)));
        }
        if result.report.stats.faulted > 0 {
            return Err(fail(format!("faulted: {:?}", result.report.faults.first())));
        }
        if checked.hazards().total() > 0 {
            return Err(fail(format!(
                "hazards {:?}, first {:?}",
                checked.hazards(),
                result.report.hazard_list.first()
            )));
        }
        let dropped = result.dropped > 0 || reference.rendered.result.dropped > 0;
        if !dropped && checked.metrics.error_pixels != reference.metrics.error_pixels {
            return Err(fail(format!(
                "{} error pixels (EPR {}) under the schedule, {} (EPR {}) under `ordered`; first {:?}",
                checked.metrics.error_pixels,
                checked.metrics.epr,
                reference.metrics.error_pixels,
                reference.metrics.epr,
                checked.metrics.first_error
            )));
        }
    }
    Ok(KernelOutcome::Checked {
        algo: info.name,
        class: info.hazard,
        epr: checked.metrics.epr,
        anomalous: checked.anomalous(),
    })
}
