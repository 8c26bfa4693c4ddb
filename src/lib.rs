//! # fragrace
//!
//! A software GPU that makes the race hazards of multi-fragment rendering visible,
//! reproducible and measurable. This crate is the product: scenes ([`scene`]), runs and
//! checks ([`run`]), images and heatmaps ([`output`]), case files, fuzzing and the commands
//! of the command line ([`cli`]; the binary only parses).
//! The GPU itself is [`fragrace_emu`]; the algorithms are [`fragrace_kernels`].

#![forbid(unsafe_code)]

pub mod budget;
pub mod case;
pub mod cli;
pub mod culling;
pub mod floor;
pub mod fuzz;
pub mod output;
pub mod plot;
pub mod racebench;
pub mod render;
pub mod report;
pub mod run;
pub mod scene;
pub mod validate;
pub mod verdict;

pub use fragrace_emu as emu;
pub use fragrace_kernels as kernels;
