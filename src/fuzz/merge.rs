//! `fuzz --merge`: the campaigns of several case directories (the shards of one campaign, run
//! anywhere) combined into one, as if one run had made them: counts added, and for each
//! finding signature the smallest of the shards' case files kept.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::campaign::{io, CampaignState, FuzzError};
use super::generate::Shard;
use crate::case::{self, Case};

/// What makes one case smaller than another: fewer triangles, then fewer pixels, a shorter
/// schedule, fewer invocations in flight (the shrunk size when the case was shrunk), then
/// the file name, so that the choice does not depend on the order of the directories.
fn size_key(c: &Case, name: &str) -> (usize, u64, usize, usize, String) {
    match c.shrunk_size.as_ref().or(c.original_size.as_ref()) {
        Some(s) => (
            s.triangles,
            s.pixels,
            s.schedule_steps,
            s.window,
            name.to_string(),
        ),
        None => (
            usize::MAX,
            u64::from(c.spec.width) * u64::from(c.spec.height),
            usize::MAX,
            usize::MAX,
            name.to_string(),
        ),
    }
}

fn read_state(dir: &Path) -> Result<CampaignState, FuzzError> {
    let path = dir.join("campaign.json");
    let bytes = std::fs::read(&path).map_err(io(&path))?;
    serde_json::from_slice(&bytes).map_err(|source| FuzzError::State {
        path: path.display().to_string(),
        source,
    })
}

/// Checks that `states` are disjoint slices of one campaign: one seed, one list of
/// algorithms, and either one whole campaign or shards of one count, each at most once.
/// The shards present, in order.
fn check_disjoint(dirs: &[PathBuf], states: &[CampaignState]) -> Result<Vec<Shard>, FuzzError> {
    let err = |m: String| Err(FuzzError::Merge(m));
    let (first_dir, first) = (&dirs[0], &states[0]);
    let mut algos = first.algos.clone();
    algos.sort();
    let mut seen: BTreeMap<Shard, &PathBuf> = BTreeMap::new();
    for (dir, st) in dirs.iter().zip(states) {
        if !st.merged_shards.is_empty() {
            return err(format!(
                "{} is itself a merged campaign: merge the shard directories",
                dir.display()
            ));
        }
        if st.seed != first.seed {
            return err(format!(
                "{} ran seed {} and {} seed {}: the shards of one campaign share its seed",
                dir.display(),
                st.seed,
                first_dir.display(),
                first.seed
            ));
        }
        let mut a = st.algos.clone();
        a.sort();
        if a != algos {
            return err(format!(
                "{} fuzzed {} and {} fuzzed {}: the shards of one campaign fuzz the same algorithms",
                dir.display(),
                st.algos.join(","),
                first_dir.display(),
                first.algos.join(",")
            ));
        }
        if st.schedules != first.schedules {
            return err(format!(
                "{} ran {} schedules per scene and {} {}: the shards of one campaign run the same",
                dir.display(),
                st.schedules,
                first_dir.display(),
                first.schedules
            ));
        }
        let shard = st.shard.unwrap_or(Shard::WHOLE);
        if let Some(other) = seen.insert(shard, dir) {
            return err(format!(
                "{} and {} both ran {}: their iterations overlap",
                other.display(),
                dir.display(),
                if shard == Shard::WHOLE {
                    "the whole campaign".to_string()
                } else {
                    format!("shard {shard}")
                }
            ));
        }
    }
    let counts: std::collections::BTreeSet<u64> = seen.keys().map(|s| s.count).collect();
    if counts.len() > 1 {
        return err(format!(
            "shards of different counts ({}): their iterations overlap; merge the shards of one --shard I/N split",
            counts
                .iter()
                .map(|c| format!("/{c}"))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    Ok(seen.into_keys().collect())
}

/// Merges the campaigns in `dirs` into `out` (a new directory, or one without a
/// `campaign.json`): the counts of executions, findings, signatures and coverage added,
/// and for each signature the smallest case file among the shards' (copied into `out`).
/// Refuses campaigns whose iterations overlap (another seed, other algorithms, a shard
/// twice, shards of different counts). Returns the merged state, also written to
/// `out/campaign.json`.
pub fn merge(dirs: &[PathBuf], out: &Path) -> Result<CampaignState, FuzzError> {
    if dirs.is_empty() {
        return Err(FuzzError::Merge("no directory to merge".into()));
    }
    let states = dirs
        .iter()
        .map(|d| read_state(d))
        .collect::<Result<Vec<_>, _>>()?;
    let shards = check_disjoint(dirs, &states)?;
    let out_state = out.join("campaign.json");
    if out_state.exists() {
        return Err(FuzzError::Merge(format!(
            "{} already holds a campaign: merge into a new directory",
            out.display()
        )));
    }
    std::fs::create_dir_all(out).map_err(io(out))?;

    let mut merged = CampaignState {
        seed: states[0].seed,
        algos: states[0].algos.clone(),
        schedules: states[0].schedules,
        merged_shards: shards,
        ..Default::default()
    };
    // The smallest case of each signature: (its size, the directory, the file name).
    let mut best: BTreeMap<String, (Case, PathBuf, String)> = BTreeMap::new();
    for (dir, st) in dirs.iter().zip(&states) {
        merged.executions += st.executions;
        merged.violations += st.violations;
        merged.expected_findings += st.expected_findings;
        merged.elapsed_s += st.elapsed_s;
        merged.phases.add(&st.phases);
        for (sig, n) in &st.signatures {
            *merged.signatures.entry(sig.clone()).or_default() += n;
        }
        for (pair, n) in &st.coverage {
            *merged.coverage.entry(pair.clone()).or_default() += n;
        }
        for (sig, name) in &st.case_of {
            let path = dir.join(name);
            let c = case::read(&path).map_err(|e| FuzzError::Io {
                path: path.display().to_string(),
                source: std::io::Error::other(e.to_string()),
            })?;
            let smaller = best
                .get(sig)
                .is_none_or(|(b, _, bn)| size_key(&c, name) < size_key(b, bn));
            if smaller {
                best.insert(sig.clone(), (c, dir.clone(), name.clone()));
            }
        }
    }
    for (sig, (_, dir, name)) in best {
        let from = dir.join(&name);
        let to = out.join(&name);
        let bytes = std::fs::read(&from).map_err(io(&from))?;
        crate::output::write_atomic(&to, &bytes).map_err(io(&to))?;
        merged.case_of.insert(sig, name.clone());
        merged.cases.push(name);
    }
    let json = serde_json::to_vec_pretty(&merged).expect("state serialises");
    crate::output::write_atomic(&out_state, &json).map_err(io(&out_state))?;
    Ok(merged)
}
