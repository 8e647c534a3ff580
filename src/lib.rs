//! The `tslg` command: build scenario libraries, run in-process evaluation
//! campaigns, print exact answers, drive a coordinator (`campaign`,
//! `library create`) and run the whole service locally (`demo`). Each
//! subcommand lives in its own module under `commands/`; this file holds the
//! argument types. `service` runs the coordinator and workers, for the two
//! service binaries and the demo.

#[macro_use]
mod output;
mod commands;
mod inputs;
pub mod service;

pub use commands::gate::GateFailed;

use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

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
    Case(CaseCommand),
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
    Library(LibraryCommand),
    /// Run one evaluation campaign in this process and print the estimate.
    Evaluate(EvaluateArgs),
    /// Print the exact P(A) of each built-in vehicle and the expected number of tests.
    Exact(ExactArgs),
    /// Start a local coordinator and workers, build a library and run a library
    /// campaign and the NDD baseline through them; print both beside the exact answer.
    Demo(DemoArgs),
    /// Start, watch or cancel campaigns on a running coordinator.
    #[command(subcommand)]
    Campaign(CampaignCommand),
    /// Check that a coordinator answers and its database works (exit 0 if so).
    Health(ServerArgs),
    /// Copy a coordinator's SQLite database to a new file, consistently,
    /// while the coordinator runs (SQLite's `VACUUM INTO`).
    Backup(BackupArgs),
    /// Learn the car-following library of a surrogate and print its action
    /// distribution at one state beside the naturalistic one.
    Policy(PolicyArgs),
    /// Load a coordinator with many simulated workers; print the lease and
    /// result latencies and check that no test was lost or counted twice.
    LoadTest(commands::load::LoadArgs),
    /// Run replicate campaigns in this process against the exact answer:
    /// coverage of the plain and the guarded interval, tests to stop, bias.
    Validate(commands::validate::ValidateArgs),
    /// Run the paper's three cases through a local coordinator and workers;
    /// print and write (Markdown, CSV) the tests each method needed beside
    /// the paper's numbers, the estimates and the exact answers.
    Reproduce(commands::reproduce::ReproduceArgs),
}

#[derive(Debug, Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum SolverArg {
    /// Backward dynamic programming.
    Dp,
    /// The paper's TD(0) (α 0.1, until every |δ| < 1e-10).
    Td,
}

#[derive(Debug, Args)]
pub struct PolicyArgs {
    /// The state `v_BV,R,Ṙ` (m/s, m, m/s); looked up at the nearest grid state.
    #[arg(long, default_value = "38,6,-2", allow_hyphen_values = true)]
    pub state: String,
    /// The surrogate: `idm` or `acc-aeb` (highway versions, docs/models.md).
    #[arg(long, default_value = "idm")]
    pub surrogate: String,
    /// How the Q-values are computed.
    #[arg(long, value_enum, default_value = "dp")]
    pub solver: SolverArg,
}

#[derive(Debug, Args)]
pub struct BackupArgs {
    /// The database to copy, as the coordinator's `--database-url`.
    #[arg(
        long,
        env = "TSLG_DATABASE_URL",
        default_value = "sqlite://tslg.sqlite"
    )]
    pub database_url: String,
    /// The backup file to write; it must not exist.
    #[arg(long)]
    pub out: std::path::PathBuf,
}

/// How to reach a coordinator.
#[derive(Debug, Clone, Args)]
pub struct ServerArgs {
    /// The coordinator's base URL.
    #[arg(long, env = "TSLG_SERVER", default_value = "http://127.0.0.1:8080")]
    pub server: String,
    /// The admin token (needed to start or cancel when the coordinator has
    /// one); for reading only, the read token will do.
    #[arg(long, env = "TSLG_ADMIN_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
}

#[derive(Debug, Subcommand)]
pub enum CaseCommand {
    /// Define a user-defined case from its case file (and the exposure table
    /// it names) on a coordinator; libraries and campaigns then name it.
    Create {
        /// The case file (TOML; docs/bring-your-own.md).
        file: PathBuf,
        #[command(flatten)]
        server: ServerArgs,
    },
    /// List the cases a coordinator runs, its user-defined ones included.
    List {
        #[command(flatten)]
        server: ServerArgs,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
}

#[derive(Debug, Subcommand)]
pub enum CampaignCommand {
    /// Start a campaign.
    Start(CampaignStartArgs),
    /// Print a campaign's state and estimate.
    Status {
        /// The campaign's id.
        id: i64,
        #[command(flatten)]
        server: ServerArgs,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Show a progress bar toward β until the campaign stops, then its state.
    Watch {
        /// The campaign's id.
        id: i64,
        #[command(flatten)]
        server: ServerArgs,
        /// The gate of `campaign start --wait --fail-above P`: exit 3 when
        /// the campaign converged with its upper bound above P, 4 when it
        /// stopped without converging.
        #[arg(long, value_name = "P", allow_negative_numbers = true)]
        fail_above: Option<f64>,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Write the campaign's figures (SVG) and numbers (CSV, JSON) to a directory.
    Report {
        /// The campaign's id.
        id: i64,
        #[command(flatten)]
        server: ServerArgs,
        /// The directory to write estimate.svg, relative-half-width.svg,
        /// history.csv and campaign.json to (created if missing).
        #[arg(long)]
        out: PathBuf,
        /// History points in the figures and the CSV (2 to 5000), spaced
        /// logarithmically in the number of tests; the dashboard shows 300.
        #[arg(long, default_value_t = 300)]
        points: usize,
    },
    /// Export the campaign's events (its resolved prefix): test index,
    /// weight, the library's criticality and the scenario by dimension, as
    /// CSV or JSON on stdout, or one OpenSCENARIO file per event (grid
    /// cases) in a directory.
    Events {
        /// The campaign's id.
        id: i64,
        #[command(flatten)]
        server: ServerArgs,
        /// `csv`, `json` or `xosc` (OpenSCENARIO 1.0, needs --out).
        #[arg(long, value_enum, default_value = "csv")]
        format: EventFormat,
        /// The directory for the xosc files and their road
        /// (tslg_straight_road.xodr); created if missing.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Export at most this many events (the first by test index).
        #[arg(long)]
        max: Option<u64>,
    },
    /// Cancel a pending or running campaign.
    Cancel {
        /// The campaign's id.
        id: i64,
        #[command(flatten)]
        server: ServerArgs,
    },
    /// Delete a stopped campaign and everything recorded for it.
    Delete {
        /// The campaign's id.
        id: i64,
        #[command(flatten)]
        server: ServerArgs,
    },
    /// List the coordinator's campaigns, newest first, a line each.
    List {
        #[command(flatten)]
        server: ServerArgs,
        /// Only those in this state: pending, running, converged,
        /// exhausted, cancelled or failed.
        #[arg(long, value_parser = wire_name::<tslg_api::CampaignStatus>)]
        status: Option<tslg_api::CampaignStatus>,
        /// Print JSON (as `GET /api/v1/campaigns` answers).
        #[arg(long)]
        json: bool,
    },
}

/// A value given by its name on the wire (`running`, `ready`).
fn wire_name<T: serde::de::DeserializeOwned>(text: &str) -> Result<T, String> {
    serde_json::from_value(serde_json::Value::String(text.to_owned())).map_err(|e| e.to_string())
}

#[derive(Debug, Args)]
pub struct CampaignStartArgs {
    #[command(flatten)]
    pub server: ServerArgs,
    /// The case (default: the library's, with `--library-id`; else
    /// `cut-in`).
    #[arg(long)]
    pub case: Option<String>,
    /// `library`, `adaptive` (stages that learn where this vehicle fails,
    /// from the library; grid cases) or `ndd`.
    #[arg(long, value_enum, default_value = "library")]
    pub method: MethodArg,
    /// The library (on the coordinator) to sample from; for `ndd`, the exposure to use.
    #[arg(long)]
    pub library_id: Option<i64>,
    /// The vehicle under test: a built-in name or a JSON specification.
    #[arg(long)]
    pub vut: String,
    #[command(flatten)]
    pub exploration: ExplorationArgs,
    #[command(flatten)]
    pub rule: RuleArgs,
    /// Campaign seed: test i is determined by (seed, i).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// A paired regression campaign: test this vehicle too (a built-in name
    /// or a JSON specification, as --vut) on the same tests, and estimate
    /// the difference of the rates (--vut's minus this one's) from the same
    /// draws; methods library and ndd (docs/statistics.md).
    #[arg(long, value_name = "VUT")]
    pub paired_with: Option<String>,
    /// Wait until the campaign stops, showing progress.
    #[arg(long)]
    pub wait: bool,
    /// With --wait, a gate for continuous integration: exit 3 when the
    /// campaign converged with its upper bound (the guarded one where the
    /// campaign has it) above this probability, 4 when it stopped without
    /// converging, 0 when it converged at or below it.
    #[arg(
        long,
        value_name = "P",
        requires = "wait",
        allow_negative_numbers = true
    )]
    pub fail_above: Option<f64>,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
pub struct LibraryCreateArgs {
    #[command(flatten)]
    pub server: ServerArgs,
    #[command(flatten)]
    pub case: CaseArgs,
    /// The surrogate model: a built-in name or a JSON specification
    /// (default: the case's).
    #[arg(long)]
    pub surrogate: Option<String>,
    #[command(flatten)]
    pub search: SearchArgs,
    /// Wait until the build is done.
    #[arg(long)]
    pub wait: bool,
    /// Print JSON (as `GET /api/v1/libraries/{id}` answers).
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Subcommand)]
pub enum LibraryCommand {
    /// Search the critical scenarios of a surrogate model and write a library file.
    Build(BuildArgs),
    /// Print a summary of a library file.
    Show {
        /// The library file.
        file: PathBuf,
    },
    /// Ask a running coordinator to build a library.
    Create(LibraryCreateArgs),
    /// Delete a library no campaign uses from a coordinator (with its file).
    Delete {
        /// The library's id.
        id: i64,
        #[command(flatten)]
        server: ServerArgs,
    },
    /// List the coordinator's libraries, newest first, a line each.
    List {
        #[command(flatten)]
        server: ServerArgs,
        /// Only those in this state: building, ready or failed.
        #[arg(long, value_parser = wire_name::<tslg_api::LibraryStatus>)]
        status: Option<tslg_api::LibraryStatus>,
        /// Print JSON (as `GET /api/v1/libraries` answers).
        #[arg(long)]
        json: bool,
    },
}

/// Which case, exposure and simulation preset.
#[derive(Debug, Clone, Args, Default)]
pub struct CaseArgs {
    /// The case: `cut-in` (the default), `highway-exit` or `car-following`
    /// (`tslg cases` describes them). Commands given a library file take
    /// its case when this is left out.
    #[arg(long, conflicts_with = "case_file")]
    pub case: Option<String>,
    /// A user-defined case: its case file (TOML; docs/bring-your-own.md).
    /// The command starts the case's program itself.
    #[arg(long, value_name = "FILE")]
    pub case_file: Option<PathBuf>,
    /// More programs this command runs for a user-defined case (vehicles
    /// under test besides the case's own program), as `tslg-worker
    /// --vut-exec`; repeatable.
    #[arg(long, value_name = "NAME=COMMAND", requires = "case_file")]
    pub vut_exec: Vec<String>,
    /// Seconds a program may take for one scenario before it is killed and
    /// tried once more (user-defined cases; as `tslg-worker --vut-timeout`).
    #[arg(long = "vut-timeout", env = "TSLG_VUT_TIMEOUT", default_value_t = 60.0)]
    pub vut_timeout_seconds: f64,
    /// An exposure table in the case's format (docs/bring-your-own.md;
    /// `tslg table --case CASE` prints the built-in model in it): cut-in the
    /// authors' layout of P(R, Ṙ), highway-exit P(v1, R, v2) rows,
    /// car-following P(s) and P(u | v) rows. Default: the built-in model.
    #[arg(long, env = "TSLG_NDD_TABLE")]
    pub ndd_table: Option<PathBuf>,
    /// Simulation preset (`tslg cases` lists each case's; default: the
    /// case's first). cut-in: `paper-code` or `paper-table`; highway-exit:
    /// `paper` or `coarse`; car-following: `paper` or `risky`.
    #[arg(long)]
    pub preset: Option<String>,
}

impl CaseArgs {
    /// The case named, or cut-in.
    pub fn name(&self) -> &str {
        self.case.as_deref().unwrap_or("cut-in")
    }

    /// The named case's descriptor (a user-defined case's from its file).
    pub fn descriptor(&self) -> anyhow::Result<tslg_method::cases::CaseDescriptor> {
        match &self.case_file {
            Some(path) => Ok(tslg_method::cases::user::descriptor::descriptor(
                &crate::inputs::read_case_file(path)?.0,
            )),
            None => Ok(tslg_method::cases::descriptor(self.name())?),
        }
    }

    /// `given`, or the case's default surrogate.
    pub fn vehicle_or_default<'a>(&self, given: &'a Option<String>) -> anyhow::Result<&'a str> {
        Ok(match given {
            Some(v) => v.as_str(),
            None => self.descriptor()?.default_surrogate,
        })
    }
}

/// How a library is searched, as `library build` and `library create` take
/// it; what is left out takes the case's default (its descriptor).
#[derive(Debug, Clone, Args)]
pub struct SearchArgs {
    /// Search strategy (default: the case's: multistart on cut-in,
    /// exhaustive on highway-exit, dynamic-programming on car-following).
    #[arg(long, value_enum)]
    pub search: Option<SearchArg>,
    /// Starting points of the multistart search (default: the case's, 50
    /// on cut-in, 100 on highway-exit).
    #[arg(long)]
    pub starts: Option<usize>,
    /// Seed of the multistart starting points or of the TD update order.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Learning rate of temporal-difference learning.
    #[arg(long, default_value_t = 0.1)]
    pub alpha: f64,
    /// Threshold γ = m·μ_S/N(X) with this m (grid cases; default 1).
    #[arg(long)]
    pub threshold_m: Option<f64>,
    /// An absolute threshold γ instead (grid cases).
    #[arg(long, conflicts_with = "threshold_m")]
    pub gamma: Option<f64>,
}

impl SearchArgs {
    /// The search asked for on `case`; `None` for the case's default.
    pub fn search(
        &self,
        case: &tslg_method::cases::CaseDescriptor,
    ) -> Option<tslg_method::library::LibrarySearch> {
        self.search_with(case.multistart_starts)
    }

    /// The search asked for, `default_starts` starting points for a
    /// multistart search that does not say; `None` for the case's default.
    pub fn search_with(
        &self,
        default_starts: usize,
    ) -> Option<tslg_method::library::LibrarySearch> {
        use tslg_method::library::{LibrarySearch, PolicySolver, SearchMethod};
        self.search.map(|search| match search {
            SearchArg::Exhaustive => LibrarySearch::Cells(SearchMethod::Exhaustive),
            SearchArg::Multistart => LibrarySearch::Cells(SearchMethod::Multistart {
                starts: self.starts.unwrap_or(default_starts),
                seed: self.seed,
            }),
            SearchArg::DynamicProgramming => {
                LibrarySearch::Policy(PolicySolver::DynamicProgramming)
            }
            SearchArg::TemporalDifference => {
                LibrarySearch::Policy(PolicySolver::TemporalDifference {
                    alpha: self.alpha,
                    seed: self.seed,
                })
            }
        })
    }

    /// The threshold asked for; `None` for the case's default.
    pub fn threshold(&self) -> Option<tslg_method::library::Threshold> {
        use tslg_method::library::Threshold;
        match (self.gamma, self.threshold_m) {
            (Some(gamma), _) => Some(Threshold::Absolute { gamma }),
            (None, Some(m)) => Some(Threshold::Relative { m }),
            (None, None) => None,
        }
    }
}

#[derive(Debug, Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum SearchArg {
    /// Grid cases: every cell.
    Exhaustive,
    /// Grid cases: local searches and a flood fill.
    Multistart,
    /// Car-following: Q-values by backward dynamic programming.
    DynamicProgramming,
    /// Car-following: Q-values by TD(0).
    TemporalDifference,
}

#[derive(Debug, Args)]
pub struct BuildArgs {
    #[command(flatten)]
    pub case: CaseArgs,
    /// The surrogate model: a built-in name (`tslg cases` lists each case's)
    /// or a JSON specification such as '{"model":"idm","v0":25}' (default:
    /// the case's).
    #[arg(long)]
    pub surrogate: Option<String>,
    #[command(flatten)]
    pub search: SearchArgs,
    /// Also run the exhaustive search and report the recall of a multistart
    /// search (grid cases).
    #[arg(long)]
    pub recall: bool,
    /// Where to write the library (JSON for grid cases, the binary policy
    /// format for car-following; docs/library-format.md).
    #[arg(long, short)]
    pub out: PathBuf,
}

/// How `tslg campaign events` writes the events.
#[derive(Debug, Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum EventFormat {
    Csv,
    Json,
    Xosc,
}

#[derive(Debug, Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum MethodArg {
    Library,
    Adaptive,
    Ndd,
}

/// How `tslg evaluate` draws its tests.
#[derive(Debug, Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum EvaluateMethodArg {
    Library,
    Adaptive,
    Ndd,
}

#[derive(Debug, Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum OutsideArg {
    Uniform,
    Ndd,
}

impl OutsideArg {
    pub fn spread(self) -> tslg_method::sampling::OutsideSpread {
        match self {
            OutsideArg::Uniform => tslg_method::sampling::OutsideSpread::Uniform,
            OutsideArg::Ndd => tslg_method::sampling::OutsideSpread::Ndd,
        }
    }

    pub fn wire(self) -> tslg_api::Outside {
        match self {
            OutsideArg::Uniform => tslg_api::Outside::Uniform,
            OutsideArg::Ndd => tslg_api::Outside::Ndd,
        }
    }
}

/// How a library campaign explores outside the library.
#[derive(Debug, Clone, Copy, Args)]
pub struct ExplorationArgs {
    /// Share ε of library tests drawn outside the library.
    #[arg(long, default_value_t = 0.1)]
    pub epsilon: f64,
    /// How ε is spread outside the library: `uniform` (the paper's) or `ndd`
    /// (in proportion to P(x), so weights outside the library stay bounded).
    /// Default: the case's, uniform for grid cases, ndd for car-following.
    #[arg(long, value_enum)]
    pub outside: Option<OutsideArg>,
    /// How tests are split between the library and the outside (grid
    /// cases): `stratified` (test i explores exactly when ⌊(i+1)ε⌋ > ⌊iε⌋,
    /// each stratum weighted by its share) or `random` (the paper's: each
    /// test explores with probability ε).
    #[arg(long, value_enum, default_value_t = SplitArg::Stratified)]
    pub split: SplitArg,
}

#[derive(Debug, Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum SplitArg {
    Stratified,
    Random,
}

impl SplitArg {
    pub fn split(self) -> tslg_method::sampling::Split {
        match self {
            SplitArg::Stratified => tslg_method::sampling::Split::Stratified,
            SplitArg::Random => tslg_method::sampling::Split::Random,
        }
    }

    pub fn wire(self) -> tslg_api::Split {
        tslg_client::wire::wire_split(self.split())
    }
}

#[derive(Debug, Clone, Args)]
pub struct RuleArgs {
    /// Stop when the relative half-width of the interval is at most β.
    #[arg(long, default_value_t = 0.2)]
    pub beta: f64,
    /// Two-sided confidence level of the interval.
    #[arg(long, default_value_t = 0.9)]
    pub confidence: f64,
    /// Never stop before this many tests. Default: 30, and for a library
    /// campaign of a grid case max(30, ⌈10/ε⌉), so that about ten exploring
    /// tests are expected first (docs/statistics.md).
    #[arg(long)]
    pub n_min: Option<u64>,
    /// Never stop before this many events.
    #[arg(long, default_value_t = tslg_method::estimator::DEFAULT_MIN_EVENTS)]
    pub min_events: u64,
    /// Give up after this many tests (status `exhausted`).
    #[arg(long, default_value_t = tslg_api::DEFAULT_MAX_TESTS)]
    pub max_tests: u64,
    /// Also require the failure mass outside the library to be bounded:
    /// its upper confidence bound may exceed the outside part of the
    /// estimate by at most β × the estimate (library campaigns of grid
    /// cases; pair it with `--outside ndd`).
    #[arg(long)]
    pub guard_outside: bool,
}

#[derive(Debug, Args)]
pub struct EvaluateArgs {
    #[command(flatten)]
    pub case: CaseArgs,
    /// The vehicle under test: a built-in name or a JSON specification.
    #[arg(long)]
    pub vut: String,
    /// `library` (importance sampling from a library), `adaptive` (search
    /// from the library's failures and the near misses, then sample the
    /// failures found; docs/adaptive-design.md) or `ndd` (the naturalistic
    /// baseline).
    #[arg(long, value_enum, default_value = "library")]
    pub method: EvaluateMethodArg,
    /// The library file (methods `library` and `adaptive`), as `tslg
    /// library build` writes it: the campaign runs on its case and preset
    /// (with `ndd`, the baseline runs on them too).
    #[arg(long)]
    pub library: Option<PathBuf>,
    #[command(flatten)]
    pub exploration: ExplorationArgs,
    #[command(flatten)]
    pub rule: RuleArgs,
    /// Campaign seed: test i is determined by (seed, i).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// A paired regression campaign: test this vehicle too (a built-in name
    /// or a JSON specification) on the same tests, and estimate the
    /// difference of the two rates (--vut's minus this one's) from the
    /// same draws (methods library and ndd; docs/statistics.md).
    #[arg(long, value_name = "VUT")]
    pub paired_with: Option<String>,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
pub struct ExactArgs {
    #[command(flatten)]
    pub case: CaseArgs,
    /// The surrogate whose library the expected library tests refer to
    /// (default: the case's).
    #[arg(long)]
    pub surrogate: Option<String>,
    /// ε of the library distribution.
    #[arg(long, default_value_t = 0.1)]
    pub epsilon: f64,
    /// Target relative half-width.
    #[arg(long, default_value_t = 0.2)]
    pub beta: f64,
    /// Confidence level.
    #[arg(long, default_value_t = 0.9)]
    pub confidence: f64,
}

#[derive(Debug, Args)]
pub struct DemoArgs {
    #[command(flatten)]
    pub case: CaseArgs,
    /// The surrogate model the library is built from (default: idm for cut-in
    /// and car-following, mobil for highway-exit).
    #[arg(long)]
    pub surrogate: Option<String>,
    /// The vehicle under test: a built-in name or a JSON specification
    /// (default: on cut-in with its default surrogate, fvdm, a vehicle that
    /// fails where the IDM's library does not look; else the surrogate's
    /// model).
    #[arg(long)]
    pub vut: Option<String>,
    /// Target relative half-width.
    #[arg(long, default_value_t = 0.2)]
    pub beta: f64,
    #[command(flatten)]
    pub exploration: ExplorationArgs,
    /// Campaign seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Test budget of each campaign.
    #[arg(long, default_value_t = 10_000_000)]
    pub max_tests: u64,
    /// Local workers to start.
    #[arg(long, default_value_t = 2)]
    pub workers: usize,
    /// Keep the coordinator's database in this file (default: a scratch file, removed after).
    #[arg(long)]
    pub database: Option<PathBuf>,
}

/// Runs a parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Cases { json } => commands::cases::run(json),
        Command::Case(CaseCommand::Create { file, server }) => {
            commands::cases::create(&file, &server)
        }
        Command::Case(CaseCommand::List { server, json }) => commands::cases::list(&server, json),
        Command::Table { case, preset } => {
            out!(
                "{}",
                tslg_method::cases::builtin_table(&case, preset.as_deref())?
            );
            Ok(())
        }
        Command::Library(LibraryCommand::Build(args)) => commands::library::build(&args),
        Command::Library(LibraryCommand::Show { file }) => commands::library::show(&file),
        Command::Evaluate(args) => commands::evaluate::run(&args),
        Command::Exact(args) => commands::exact::run(&args),
        Command::Library(LibraryCommand::Create(args)) => commands::campaign::create_library(&args),
        Command::Library(LibraryCommand::Delete { id, server }) => {
            commands::campaign::delete_library(&server, id)
        }
        Command::Campaign(CampaignCommand::Delete { id, server }) => {
            commands::campaign::delete_campaign(&server, id)
        }
        Command::Campaign(CampaignCommand::List {
            server,
            status,
            json,
        }) => commands::listing::campaigns(&server, status, json),
        Command::Library(LibraryCommand::List {
            server,
            status,
            json,
        }) => commands::listing::libraries(&server, status, json),
        Command::Demo(args) => commands::demo::run(&args),
        Command::Campaign(CampaignCommand::Start(args)) => commands::campaign::start(&args),
        Command::Campaign(CampaignCommand::Status { id, server, json }) => {
            commands::campaign::status(&server, id, json)
        }
        Command::Campaign(CampaignCommand::Watch {
            id,
            server,
            fail_above,
            json,
        }) => commands::campaign::watch_command(&server, id, fail_above, json),
        Command::Campaign(CampaignCommand::Report {
            id,
            server,
            out,
            points,
        }) => commands::campaign::report(&server, id, &out, points),
        Command::Campaign(CampaignCommand::Events {
            id,
            server,
            format,
            out,
            max,
        }) => commands::events::export(&server, id, format, out.as_deref(), max),
        Command::Campaign(CampaignCommand::Cancel { id, server }) => {
            commands::campaign::cancel(&server, id)
        }
        Command::Health(server) => commands::campaign::health(&server),
        Command::Policy(args) => commands::policy::run(&args),
        Command::LoadTest(args) => commands::load::run(&args),
        Command::Validate(args) => commands::validate::run(&args),
        Command::Reproduce(args) => commands::reproduce::run(&args),
        Command::Backup(args) => commands::remote::block_on(async {
            let bytes = tslg_server::backup(&args.database_url, &args.out).await?;
            outln!(
                "backed up {} to {} ({bytes} bytes)",
                args.database_url,
                args.out.display()
            );
            Ok(())
        }),
    }
}
