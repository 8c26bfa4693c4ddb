//! A command's memory budget (`--memory-limit`), checked before a run allocates, and stated
//! in its JSON summary.

use crate::budget::{self, BudgetError};
use crate::run::{Loaded, RunSpec};

/// The estimated peak memory of a run, refused when above the budget (`--memory-limit`);
/// as JSON fields for the summary.
pub fn within_budget(
    spec: &RunSpec,
    loaded: &Loaded,
    with_truth: bool,
    limit: Option<&str>,
) -> Result<serde_json::Value, BudgetError> {
    let (limit, source) = budget::limit(limit)?;
    let est = budget::estimate(spec, loaded, with_truth);
    budget::check(&est, limit, &source)?;
    Ok(serde_json::json!({
        "memory_estimate_bytes": est.bytes,
        "memory_estimate_parts": est.parts,
        "memory_limit_bytes": limit,
        "fragments_estimate": est.fragments,
    }))
}

/// Adds the fields of `extra` (an object) to `v`.
pub fn merge(v: &mut serde_json::Value, extra: &serde_json::Value) {
    if let (Some(v), Some(e)) = (v.as_object_mut(), extra.as_object()) {
        v.extend(e.iter().map(|(k, x)| (k.clone(), x.clone())));
    }
}
