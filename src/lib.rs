//! The `tslg` command: build scenario libraries, run in-process evaluation
//! campaigns, print exact answers, drive a coordinator (`campaign`,
//! `library create`) and run the whole service locally (`demo`).
//!
//! Layout, from the top down (no file imports one above it):
//!
//! - `lib.rs`: the command line's top level ([`Cli`]) and its dispatch;
//! - `commands/`: one module per subcommand, each with its own arguments,
//!   and the helpers they share (`remote`: talking to a coordinator;
//!   `local`: a coordinator and workers in this process; `progress`: bars;
//!   `gate`: `--fail-above`; `listing`, `paired`, `held_out`);
//! - `inputs.rs`: reading what the user names (tables, case files, library
//!   files, vehicles) and opening cases;
//! - `args.rs`: argument groups several commands share;
//! - `output.rs`: printing that survives a closed pipe;
//! - `service.rs`: the coordinator and workers, for the two service
//!   binaries and the demo.

#[macro_use]
mod output;
mod args;
mod commands;
mod inputs;
pub mod service;

pub use commands::gate::GateFailed;
pub use output::error_text;

use args::ServerArgs;
use clap::{Parser, Subcommand};
use commands::{
    backup, campaign, cases, demo, evaluate, exact, library, load, policy, reproduce, validate,
    worker,
};

/// Testing scenario library generation for automated vehicles.
#[derive(Debug, Parser)]
#[command(name = "tslg", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// List the cases with their presets, vehicles and defaults.
    Cases {
        /// Print JSON (as `GET /api/v1/cases` answers).
        #[arg(long)]
        json: bool,
    },
    /// Define user-defined cases on a running coordinator, or list its cases.
    #[command(subcommand)]
    Case(cases::CaseCommand),
    /// Print a case's built-in exposure model as the table the case accepts
    /// (`--ndd-table`): the format to fill with your own naturalistic data.
    Table {
        /// The case.
        #[arg(long, default_value = "cut-in")]
        case: String,
        /// The preset (default: the case's).
        #[arg(long)]
        preset: Option<String>,
    },
    /// Build or inspect scenario libraries.
    #[command(subcommand)]
    Library(library::LibraryCommand),
    /// Run one evaluation campaign in this process and print the estimate.
    Evaluate(evaluate::EvaluateArgs),
    /// Print the exact P(A) of each built-in vehicle and the expected number of tests.
    Exact(exact::ExactArgs),
    /// Start a local coordinator and workers, build a library and run a library
    /// campaign, an adaptive campaign (grid cases) and the NDD baseline through
    /// them; print them beside the exact answer, and what to take away.
    Demo(demo::DemoArgs),
    /// Start, watch or cancel campaigns on a running coordinator.
    #[command(subcommand)]
    Campaign(campaign::CampaignCommand),
    /// Enrol workers' principals on a coordinator run with `--enrolment
    /// required`.
    #[command(subcommand)]
    Worker(worker::WorkerCommand),
    /// Check that a coordinator answers and its database works (exit 0 if so).
    Health(ServerArgs),
    /// Copy a coordinator's SQLite database to a new file, consistently,
    /// while the coordinator runs (SQLite's `VACUUM INTO`).
    Backup(backup::BackupArgs),
    /// Learn the car-following library of a surrogate and print its action
    /// distribution at one state beside the naturalistic one.
    Policy(policy::PolicyArgs),
    /// Load a coordinator with many simulated workers; print the lease and
    /// result latencies and check that no test was lost or counted twice.
    LoadTest(load::LoadArgs),
    /// Run replicate campaigns in this process against the exact answer:
    /// coverage of the plain and the guarded interval, tests to stop, bias.
    Validate(validate::ValidateArgs),
    /// Run the paper's three cases through a local coordinator and workers;
    /// print and write (Markdown, CSV) the tests each method needed beside
    /// the paper's numbers, the estimates and the exact answers.
    Reproduce(reproduce::ReproduceArgs),
}

/// Runs a parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Cases { json } => cases::run(json),
        Command::Case(command) => cases::run_case(command),
        Command::Table { case, preset } => cases::table(&case, preset.as_deref()),
        Command::Library(command) => library::run(command),
        Command::Evaluate(args) => evaluate::run(&args),
        Command::Exact(args) => exact::run(&args),
        Command::Demo(args) => demo::run(&args),
        Command::Campaign(command) => campaign::run(command),
        Command::Worker(command) => worker::run(command),
        Command::Health(server) => campaign::health(&server),
        Command::Backup(args) => backup::run(&args),
        Command::Policy(args) => policy::run(&args),
        Command::LoadTest(args) => load::run(&args),
        Command::Validate(args) => validate::run(&args),
        Command::Reproduce(args) => reproduce::run(&args),
    }
}
