//! The `fragrace` command line: it only parses. Each command's options are the library's
//! option struct of that command ([`fragrace::cli`], where clap's derive gives each field
//! its option, help text and default), and the command itself is the library's; an error is
//! printed as `error: ...` with exit status 2.

#![forbid(unsafe_code)]

use anyhow::Result;
use clap::parser::ValueSource;
use clap::{ArgMatches, CommandFactory, FromArgMatches, Parser, Subcommand};
use fragrace::cli;

#[derive(Parser)]
#[command(
    name = "fragrace",
    version,
    about = "A software GPU that makes the race hazards of multi-fragment rendering visible, reproducible and measurable"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene with one algorithm (an OIT image, or a heatmap for `count`).
    Render(cli::RunOptions),
    /// Run an algorithm (over N schedules) and compare it with the exact ground truth.
    Check(cli::run::CheckOptions),
    /// List the algorithms (with --json: their declared properties) and built-in scenes.
    List {
        #[arg(long)]
        json: bool,
    },
    /// Measure throughput: fragments and triangles per second, scheduled steps per second.
    Bench(cli::bench::BenchOptions),
    /// Fuzz campaign: random scenes x algorithms x schedules, shrunk case files for findings.
    Fuzz(cli::fuzz::FuzzOptions),
    /// Rerun a case file and say whether its observation still holds, bit for bit.
    Replay(cli::run::ReplayOptions),
    /// Tables of measured EPR, R_h, bytes per pixel and time (markdown), and EPR over views.
    Report(cli::report::ReportOptions),
    /// The hazard detector measured on labelled racy and race-free kernels, per policy.
    Racebench(cli::racebench::RacebenchOptions),
    /// Preprocess a static mesh into depth-presorted triangle lists (`--algo presorted`).
    Presort(cli::presort::PresortOptions),
}

/// The options given on the command line (not defaulted), named as typed without `--`.
fn given(m: &ArgMatches) -> Vec<String> {
    m.ids()
        .filter(|id| m.value_source(id.as_str()) == Some(ValueSource::CommandLine))
        .map(|id| id.as_str().replace('_', "-"))
        .collect()
}

fn main() {
    if let Err(e) = real_main() {
        eprintln!("error: {e:#}");
        std::process::exit(2);
    }
}

fn real_main() -> Result<()> {
    let matches = Cli::command().get_matches();
    let parsed = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    let given = matches
        .subcommand()
        .map(|(_, m)| given(m))
        .unwrap_or_default();
    // A kernel panic is a reported fault, not a crash: keep the default hook's noise out.
    std::panic::set_hook(Box::new(|_| {}));
    match parsed.command {
        Command::Render(a) => cli::run::cmd_render(&a, &given)?,
        Command::Check(a) => cli::run::cmd_check(&a, &given)?,
        Command::List { json } => cli::list::cmd_list(json),
        Command::Bench(a) => cli::bench::cmd_bench(&a, &given)?,
        Command::Fuzz(a) => cli::fuzz::cmd_fuzz(&a)?,
        Command::Replay(a) => {
            let holds = cli::run::cmd_replay(&a)?;
            if !holds {
                std::process::exit(1);
            }
        }
        Command::Report(a) => cli::report::cmd_report(&a, &given)?,
        Command::Racebench(a) => cli::racebench::cmd_racebench(&a)?,
        Command::Presort(a) => cli::presort::cmd_presort(&a)?,
    }
    Ok(())
}
