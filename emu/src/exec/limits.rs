//! What an executor configuration may hold, checked before a run allocates anything
//! ([`ExecConfig::validate`]). Values out of range are refused, never clamped.

use super::{ExecConfig, ExecMode, Policy};

/// Most invocations in flight under the scheduled executor (`window`).
pub const MAX_WINDOW: usize = 1 << 20;
/// Most lanes of one warp of the parallel executor (`batch`, `--lanes`).
pub const MAX_LANES: usize = 1 << 16;
/// Most lanes of a lockstep warp under the scheduled executor (`simt`).
pub const MAX_SIMT: u32 = 1 << 16;

/// Most worker threads on this machine: eight per core, at least 32. The pool starts a
/// thread per worker and guarantees that they all run at once (interlock waits on them), so
/// far more threads than cores only time-slice; `--threads 100000` would start 100000.
pub fn max_threads() -> usize {
    (8 * super::default_threads()).max(32)
}

/// An executor setting out of its range.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum ExecConfigError {
    #[error("{name} = {value} is out of range: it must be from {min} to {max}{why}")]
    OutOfRange {
        /// The setting, as the command line and case files name it.
        name: &'static str,
        value: u64,
        min: u64,
        max: u64,
        /// Where the limit comes from (may be empty).
        why: String,
    },
}

fn range(
    name: &'static str,
    value: u64,
    min: u64,
    max: u64,
    why: impl Into<String>,
) -> Result<(), ExecConfigError> {
    if (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(ExecConfigError::OutOfRange {
            name,
            value,
            min,
            max,
            why: why.into(),
        })
    }
}

impl ExecConfig {
    /// Checks every setting against its range (and the thread count against this machine).
    pub fn validate(&self) -> Result<(), ExecConfigError> {
        let cores = super::default_threads();
        range(
            "threads (--threads)",
            self.threads as u64,
            1,
            max_threads() as u64,
            format!(" (eight per core, at least 32; this machine has {cores} cores)"),
        )?;
        range(
            "lanes per warp (--lanes, `batch` in case files)",
            self.batch as u64,
            1,
            MAX_LANES as u64,
            "",
        )?;
        range("max_steps", self.max_steps, 1, u64::MAX, "")?;
        range("max_waits", self.max_waits, 1, u64::MAX, "")?;
        range(
            "spurious_cas_per_mille (--spurious-cas)",
            u64::from(self.spurious_cas_per_mille),
            0,
            1000,
            " (per mille)",
        )?;
        range(
            "segment (--segment)",
            u64::from(self.segment),
            1,
            u64::from(u32::MAX),
            "",
        )?;
        if let ExecMode::Scheduled(s) = &self.mode {
            range(
                "block (--block)",
                u64::from(s.block),
                1,
                u64::from(crate::framebuffer::MAX_DIMENSION),
                " (pixels per side)",
            )?;
            range(
                "simt (--simt)",
                u64::from(s.simt),
                0,
                u64::from(MAX_SIMT),
                " (0: independent lanes)",
            )?;
            range(
                "window (--window)",
                s.window as u64,
                1,
                MAX_WINDOW as u64,
                " (invocations in flight)",
            )?;
            match s.policy {
                Policy::Pct { depth } => range(
                    "pct depth (--policy pct:D)",
                    u64::from(depth),
                    1,
                    u64::from(u32::MAX),
                    "",
                )?,
                Policy::Warp { lanes } => range(
                    "warp lanes (--policy warp:N)",
                    u64::from(lanes),
                    1,
                    u64::from(u32::MAX),
                    "",
                )?,
                _ => {}
            }
        }
        Ok(())
    }
}
