//! The commands of the binary, by file (`main.rs` keeps the options, their parsing into a run and `list`).

pub(crate) mod bench;
pub(crate) mod fuzz;
pub(crate) mod outputs;
pub(crate) mod presort;
pub(crate) mod racebench;
pub(crate) mod report;
pub(crate) mod run;
