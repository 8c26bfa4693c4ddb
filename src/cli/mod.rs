//! The commands of the binary, by file (`main.rs` keeps the options and the core commands).

pub(crate) mod bench;
pub(crate) mod fuzz;
pub(crate) mod outputs;
pub(crate) mod presort;
pub(crate) mod racebench;
pub(crate) mod report;
