//! Reading executor configurations saved before the scheduled executor's own settings
//! (`block`, `reduce`, `simt`) moved from [`ExecConfig`] into [`ScheduleConfig`]: a case
//! file of that time keeps them next to the mode. They are moved into the schedule when
//! the mode is `scheduled` (the only executor that read them), so an old case replays as
//! it was recorded; under other modes they had no effect and are dropped.

use super::{default_segment, Binning, ExecConfig, ExecMode};

/// [`ExecConfig`] as files hold it, old or new.
#[derive(serde::Deserialize)]
pub(super) struct ExecConfigFile {
    mode: ExecMode,
    threads: usize,
    batch: usize,
    lockstep: bool,
    max_steps: u64,
    max_waits: u64,
    contention: bool,
    #[serde(default)]
    spurious_cas_per_mille: u32,
    #[serde(default = "default_segment")]
    segment: u32,
    #[serde(default)]
    binning: Binning,
    /// The settings saved beside the mode before they moved into it.
    #[serde(default)]
    block: Option<u32>,
    #[serde(default)]
    reduce: Option<bool>,
    #[serde(default)]
    simt: Option<u32>,
}

impl From<ExecConfigFile> for ExecConfig {
    fn from(f: ExecConfigFile) -> ExecConfig {
        let mut mode = f.mode;
        if let ExecMode::Scheduled(s) = &mut mode {
            if let Some(b) = f.block {
                s.block = b;
            }
            if let Some(r) = f.reduce {
                s.reduce = r;
            }
            if let Some(m) = f.simt {
                s.simt = m;
            }
        }
        ExecConfig {
            mode,
            threads: f.threads,
            batch: f.batch,
            lockstep: f.lockstep,
            max_steps: f.max_steps,
            max_waits: f.max_waits,
            contention: f.contention,
            spurious_cas_per_mille: f.spurious_cas_per_mille,
            segment: f.segment,
            binning: f.binning,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{ExecConfig, ExecMode, Policy, ScheduleConfig};

    /// A case file's executor from before the move, and the same settings as saved now:
    /// both read to the same configuration.
    #[test]
    fn old_files_keep_their_scheduled_settings() {
        let old = r#"{"mode":{"Scheduled":{"policy":"Random","seed":7,"window":8,"record":false}},
            "threads":1,"batch":64,"lockstep":true,"max_steps":1048576,"max_waits":67108864,
            "contention":false,"block":2,"reduce":true,"spurious_cas_per_mille":0,
            "segment":128,"simt":32}"#;
        let read: ExecConfig = serde_json::from_str(old).unwrap();
        let want = ExecConfig {
            mode: ExecMode::Scheduled(ScheduleConfig {
                policy: Policy::Random,
                seed: 7,
                window: 8,
                block: 2,
                reduce: true,
                simt: 32,
                ..Default::default()
            }),
            threads: 1,
            ..Default::default()
        };
        assert_eq!(read, want);
        let now = serde_json::to_string(&want).unwrap();
        // Saved now, they sit in the schedule.
        assert!(
            now.contains(r#""record":false,"block":2,"reduce":true,"simt":32}"#),
            "{now}"
        );
        assert_eq!(serde_json::from_str::<ExecConfig>(&now).unwrap(), want);
        // Under another executor they had no effect: dropped.
        let parallel = old.replace(
            r#"{"Scheduled":{"policy":"Random","seed":7,"window":8,"record":false}}"#,
            r#""Parallel""#,
        );
        let read: ExecConfig = serde_json::from_str(&parallel).unwrap();
        assert_eq!(read.mode, ExecMode::Parallel);
    }
}
