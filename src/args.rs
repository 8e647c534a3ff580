//! Argument groups several commands share: how to reach a coordinator,
//! which case, how a library is searched, how a campaign explores outside
//! its library, and its stopping rule. A command's own arguments live in
//! its module under `commands/`.
//!
//! Numeric flags take a leading minus (`--beta -0.1`), so that the range
//! check answers with what the range is, not clap with "unexpected
//! argument '-0'".

use clap::builder::TypedValueParser as _;
use clap::{Args, ValueEnum};
use std::path::PathBuf;
use tslg_api::{AdaptiveSearch, Method};

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
    #[arg(
        long = "vut-timeout",
        env = "TSLG_VUT_TIMEOUT",
        default_value_t = 60.0,
        allow_negative_numbers = true
    )]
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
    #[arg(long, default_value_t = 0.1, allow_negative_numbers = true)]
    pub alpha: f64,
    /// Threshold γ = m·μ_S/N(X) with this m (grid cases; default 1).
    #[arg(long, allow_negative_numbers = true)]
    pub threshold_m: Option<f64>,
    /// An absolute threshold γ instead (grid cases).
    #[arg(long, conflicts_with = "threshold_m", allow_negative_numbers = true)]
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

/// `--method`: the methods a client may ask for, by their names
/// ([`Method::requestable`]), each with how it draws its tests in the
/// help: a new method in `tslg_api::Method` is offered here without an
/// edit.
pub fn method_parser() -> impl clap::builder::TypedValueParser<Value = Method> {
    let names = Method::requestable()
        .map(|m| clap::builder::PossibleValue::new(m.as_str()).help(m.spec().summary));
    clap::builder::PossibleValuesParser::new(names)
        .map(|name: String| Method::parse(&name).expect("the parser offers methods' names alone"))
}

/// `--adaptive-search`: the searches of `tslg_api::AdaptiveSearch`, by
/// their names (`grid`, `lattice`).
pub fn search_parser() -> impl clap::builder::TypedValueParser<Value = AdaptiveSearch> {
    clap::builder::PossibleValuesParser::new(AdaptiveSearch::ALL.map(AdaptiveSearch::as_str)).map(
        |name: String| {
            AdaptiveSearch::parse(&name).expect("the parser offers searches' names alone")
        },
    )
}

/// `--adaptive-search` checked against the method: only a method that runs
/// in stages searches.
pub fn search_for_method(
    search: Option<AdaptiveSearch>,
    method: Method,
) -> anyhow::Result<Option<AdaptiveSearch>> {
    anyhow::ensure!(
        search.is_none() || method.in_stages(),
        "--adaptive-search chooses how an adaptive campaign searches around its failures; use it \
         with --method adaptive"
    );
    Ok(search)
}

/// How a library campaign explores outside the library.
#[derive(Debug, Clone, Copy, Args)]
pub struct ExplorationArgs {
    /// Share ε of library tests drawn outside the library.
    #[arg(long, default_value_t = 0.1, allow_negative_numbers = true)]
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
    #[arg(long, default_value_t = 0.2, allow_negative_numbers = true)]
    pub beta: f64,
    /// Two-sided confidence level of the interval.
    #[arg(long, default_value_t = 0.9, allow_negative_numbers = true)]
    pub confidence: f64,
    /// Never stop before this many tests. Default: 30, and for a library
    /// campaign of a grid case max(30, ⌈10/ε⌉), so that about ten exploring
    /// tests are expected first (docs/statistics.md).
    #[arg(long, allow_negative_numbers = true)]
    pub n_min: Option<u64>,
    /// Never stop before this many events.
    #[arg(
        long,
        default_value_t = tslg_method::estimator::DEFAULT_MIN_EVENTS,
        allow_negative_numbers = true
    )]
    pub min_events: u64,
    /// Give up after this many tests (status `exhausted`).
    #[arg(
        long,
        default_value_t = tslg_api::DEFAULT_MAX_TESTS,
        allow_negative_numbers = true
    )]
    pub max_tests: u64,
    /// Also require the failure mass outside the library to be bounded:
    /// its upper confidence bound may exceed the outside part of the
    /// estimate by at most β × the estimate (library campaigns of grid
    /// cases). The outside spread then defaults to `ndd`, and once the
    /// library stratum is known 95 % of the tests explore: about
    /// ln(1/(1 − c))/(βμ) tests when no failure lies outside. An adaptive
    /// campaign bounds the mass outside its support K the same way, its
    /// estimation stages exploring the share that needs fewest tests once
    /// its estimate meets β. On by default for a noisy vehicle
    /// (docs/statistics.md, "Noisy vehicles").
    #[arg(long, conflicts_with = "no_guard_outside")]
    pub guard_outside: bool,
    /// Run without the guard even for a noisy vehicle; its answer is then
    /// still the guarded interval, as wide as its few exploring tests leave
    /// it.
    #[arg(long)]
    pub no_guard_outside: bool,
    /// The interval the rule reads and the answer reports: `wald` (valid at
    /// the stop) or `anytime` (a confidence sequence, valid at every number
    /// of tests: watch, stop, extend or gate at any time; about three
    /// times the tests). Grid cases' library and NDD campaigns.
    #[arg(long, default_value = "wald")]
    pub interval: tslg_method::estimator::Interval,
}

impl RuleArgs {
    /// The guard as asked for: on, off, or (`None`) the default, on for a
    /// noisy vehicle.
    pub fn guard_request(&self) -> Option<bool> {
        match (self.guard_outside, self.no_guard_outside) {
            (true, _) => Some(true),
            (_, true) => Some(false),
            _ => None,
        }
    }
}

/// A value given by its name on the wire (`running`, `ready`).
pub fn wire_name<T: serde::de::DeserializeOwned>(text: &str) -> Result<T, String> {
    serde_json::from_value(serde_json::Value::String(text.to_owned())).map_err(|e| e.to_string())
}
