//! The commands of the `fragrace` binary, one file per command: what `fragrace render`,
//! `check`, `bench`, ... do once their options are parsed.
//!
//! # What a command is
//!
//! A command is a function `cmd_NAME(&Options, ...) -> Result<_, CliError>` that checks its
//! options, runs, prints its summary on stdout (text, or one JSON object with `json`),
//! writes its files and returns. Its input is an options struct of this library
//! ([`RunOptions`], [`run::CheckOptions`], [`bench::BenchOptions`], [`fuzz::FuzzOptions`],
//! [`report::ReportOptions`], [`racebench::RacebenchOptions`],
//! [`presort::PresortOptions`], [`run::ReplayOptions`]): one field per option of the command
//! line, with the option's name, parsed (a number is a number) but not yet checked. The
//! command checks the values and refuses what does not go together before any computation,
//! with a typed error ([`CliError`]; the command line's own mistakes are [`OptionError`]s)
//! whose message names the value and its valid range.
//!
//! Commands that build one run (`render`, `check`, `bench`) also take `given`: the options
//! written on the command line rather than defaulted, named as typed without `--`. An
//! option that the chosen executor or algorithm would ignore is refused only when given
//! ([`RunOptions::spec`]), and a scene file's camera yields to the options given.
//!
//! # How the binary calls it
//!
//! `main.rs` only parses: each options struct derives `clap::Args`, so a field's attribute
//! is its option (name, default, value parser from [`parse`]) and its doc comment is the
//! option's `--help` text, written once. `main` parses into these structs, calls the
//! command, and prints an error as `error: ...` (the error and its sources, joined by
//! `: `) on stderr with exit status 2. `replay` returns whether the case's observation
//! still holds; the binary exits with status 1 when it does not.
//!
//! The structs are still plain values to the library: a test, a benchmark or another front
//! end builds them with struct syntax (`RunOptions { algo: "ll".into(),
//! ..RunOptions::default() }`) and calls the command; no parser runs. `RunOptions::default()`
//! is the command line's defaults, which its `default_value_t`s read.

pub mod bench;
pub mod error;
pub mod fuzz;
pub mod list;
pub mod memory;
pub mod options;
pub mod outputs;
pub mod parse;
pub mod presort;
pub mod progress;
pub mod racebench;
pub mod report;
pub mod run;

pub use error::{CliError, OptionError};
pub use options::{OccupancyOptions, RunOptions};
