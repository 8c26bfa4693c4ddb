//! fragrace: a software GPU that makes the race hazards of multi-fragment rendering visible.

pub mod scene;
