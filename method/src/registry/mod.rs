//! The cases a service can run, behind one object-safe interface, so the
//! coordinator and the worker handle every case with the same code: a case is
//! opened by name with a preset and an exposure source, vehicles are given as
//! JSON specifications, libraries are files in the case's own format, and a
//! campaign's tests are run (worker) and checked (coordinator) by index.
//! Adding a case means one arm in [`open_case`].

mod adaptive_tests;
pub mod cells;
pub(crate) mod picture;
pub(crate) mod vut;

pub use picture::PictureMap;

use crate::adaptive::{AdaptiveError, AdaptiveResult, AdaptiveSettings, TestResult};
use crate::descriptor::CaseDescriptor;
use crate::estimator::StoppingRule;
use crate::exact::ExactReport;
use crate::external::{DriverError, ExternalVehicle, ExternalVut};
pub use crate::library::LibrarySearch;
use crate::library::{LibraryFileError, Threshold};
use crate::progress::Progress;
use crate::sampling::{OutsideSpread, SamplingError, Split};
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use thiserror::Error;

/// Where a case's exposure `P(x)` comes from.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ExposureSource {
    /// The case's documented built-in exposure model.
    Builtin,
    /// A table in the layout of SPEC §4 (see [`crate::ndd_table`]).
    Table {
        /// The table's name, shown with campaigns and libraries.
        name: String,
        /// The table's CSV text.
        text: String,
    },
}

/// Why a case, a vehicle or a library could not be used.
#[derive(Debug, Error, PartialEq)]
pub enum CaseError {
    /// No case of that name.
    #[error("unknown case `{name}`; known cases: {known}")]
    UnknownCase {
        /// The name asked for.
        name: String,
        /// The cases there are, comma-separated.
        known: String,
    },
    /// No preset of that name for the case.
    #[error("{0}")]
    Preset(String),
    /// An exposure table that fails validation.
    #[error("exposure table `{name}` rejected: {reason}")]
    Exposure {
        /// The table's name.
        name: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A vehicle specification the case cannot run.
    #[error("invalid vehicle for case {case}: {reason}")]
    Vehicle {
        /// The case.
        case: &'static str,
        /// What is wrong with the vehicle.
        reason: String,
    },
    /// A library request the case cannot build.
    #[error("invalid library request for case {case}: {reason}")]
    Request {
        /// The case.
        case: &'static str,
        /// What is wrong with the request.
        reason: String,
    },
    /// A grid library file that cannot be used.
    #[error(transparent)]
    Library(#[from] LibraryFileError),
    /// A policy library file (car-following) that cannot be used.
    #[error("{0}")]
    PolicyFile(String),
    /// A test distribution that cannot be built.
    #[error(transparent)]
    Sampling(#[from] SamplingError),
    /// The case has no exact answer for this request (e.g. car-following).
    #[error("{0}")]
    NoExactAnswer(String),
    /// The surrogate search failed.
    #[error("the library could not be built: {0}")]
    Build(String),
    /// An adaptive campaign that cannot run.
    #[error(transparent)]
    Adaptive(#[from] AdaptiveError),
    /// What this case does not do.
    #[error("{0}")]
    Unsupported(String),
    /// A user-defined case's name already holds another definition.
    #[error("case {0} is already defined, differently: a case keeps its definition; name the new one otherwise")]
    AlreadyDefined(String),
}

/// A build request; what is `None` takes the case's default.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BuildRequest {
    /// The criticality threshold; the case's default when `None`.
    pub threshold: Option<Threshold>,
    /// The search or solver; the case's default when `None`.
    pub search: Option<LibrarySearch>,
}

/// A built library: its file in the case's format and its summary.
#[derive(Debug, Clone, PartialEq)]
pub struct BuiltLibrary {
    /// The library file's bytes.
    pub file: Vec<u8>,
    /// The file's media type (JSON for grid cases, binary for car-following).
    pub media_type: &'static str,
    /// `N(Φ)`: library cells, or states with `P(S|s) > 0`.
    pub size: usize,
    /// Surrogate simulations the search used.
    pub sm_evaluations: usize,
    /// `μ_S = Σ_x V(x)`: the surrogate's event rate under the exposure (exact for exhaustive search, a lower bound otherwise).
    pub mu_s: f64,
    /// `W`: the criticality mass inside the library.
    pub w: f64,
}

/// What a library file holds, as `tslg library show` prints it.
#[derive(Debug, Clone, PartialEq)]
pub struct LibrarySummary {
    /// The case and preset it was built for.
    pub case: String,
    /// The case's preset.
    pub preset: String,
    /// The surrogate, as its specification.
    pub surrogate: serde_json::Value,
    /// The exposure's name and fingerprint.
    pub exposure: crate::library::ExposureRef,
    /// `N(Φ)`: its cells or states.
    pub size: usize,
    /// `N(X)`: the case's scenarios (grid cells or states).
    pub total: usize,
    /// `μ_S`.
    pub mu_s: f64,
    /// `W = Σ_{x∈Φ} V(x)`.
    pub w: f64,
    /// The threshold γ (grid cases).
    pub gamma: Option<f64>,
    /// How it was searched or learned, in words.
    pub search: String,
    /// Surrogate simulations the search used.
    pub sm_evaluations: usize,
    /// The share of the exhaustive library's criticality a multistart
    /// search found, when measured.
    pub recall: Option<f64>,
}

/// What one test gave.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TestOutcome {
    /// Whether the test had the event `A`.
    pub event: bool,
    /// The importance weight `P/q` of the whole test.
    pub weight: f64,
}

/// A test whose scenario and weight are fixed before it runs (grid cases).
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedTest {
    /// The scenario's grid cell.
    pub cell: usize,
    /// The scenario's parameters.
    pub scenario: Vec<f64>,
    /// The importance weight `P(x)/q(x)`.
    pub weight: f64,
}

/// Every test of one campaign, reproducible from its index (SPEC §7): the
/// coordinator and the worker build the same object from the same plan.
pub trait CampaignTests: Send + Sync {
    /// The external program the campaign's vehicle under test is, if it is
    /// one.
    fn external(&self) -> Option<&ExternalVut>;
    /// Runs test `index` with `program` as the vehicle under test (sent a
    /// `reset` first), or on the campaign's built-in model when `program`
    /// is `None`. An error is the program's fault: the test has no valid
    /// outcome. A built-in vehicle that panics is the caller's to catch.
    fn run_with(
        &self,
        index: u64,
        program: Option<&mut dyn ExternalVehicle>,
    ) -> Result<TestOutcome, DriverError>;
    /// Runs test `index` on the campaign's built-in model.
    ///
    /// # Panics
    /// When the campaign's vehicle is an external program.
    fn run(&self, index: u64) -> TestOutcome {
        self.run_with(index, None).unwrap_or_else(|e| panic!("{e}"))
    }
    /// The outcomes of tests `from..to`, in order, when the campaign's
    /// vehicle is built in and its case runs many scenarios at once
    /// ([`crate::case::Case::events`]): the same outcomes as [`Self::run`]
    /// one by one. `None`: run them one by one.
    fn run_span(&self, from: u64, to: u64) -> Option<Vec<TestOutcome>> {
        let _ = (from, to);
        None
    }
    /// The outcomes of tests `indices` (any order) on the campaign's
    /// built-in vehicle, in batches where the case runs tests that way
    /// (the coordinator's replay of the tests a report adds); `None`:
    /// replay them one by one ([`Self::replay`]).
    fn replay_many(&self, indices: &[u64]) -> Option<Vec<TestOutcome>> {
        let _ = indices;
        None
    }
    /// Checks a reported event against the campaign's own test `index`: a
    /// mismatch means the reporter samples differently (another version,
    /// another library) and its results must not enter the estimate. What
    /// depends on an external program's behaviour cannot be checked here.
    fn check_event(&self, index: u64, weight: f64) -> Result<(), String>;
    /// The scenario and weight of test `index` when they are fixed before the
    /// test runs; `None` for sequential scenarios sampled while they run.
    fn planned(&self, index: u64) -> Option<PlannedTest>;
    /// The coordinator's own outcome of test `index`, to check what a
    /// worker reported: the test run again on the campaign's built-in
    /// model (a grid case runs each cell once and remembers it, since a
    /// built-in vehicle's outcome depends on the cell alone). `None` when
    /// the vehicle is an external program, which only workers can run.
    fn replay(&self, index: u64) -> Option<TestOutcome>;
    /// [`Self::replay`] with [`Self::explores`] of the same test, from one
    /// draw where the case can (a grid case's exploring tests are those
    /// whose cell lies outside the library).
    fn replay_explored(&self, index: u64) -> Option<(TestOutcome, bool)> {
        self.replay(index)
            .map(|outcome| (outcome, self.explores(index)))
    }
    /// [`Self::replay_explored`] of each test of `from..to`, in order, in
    /// batches where the case draws that way; `None` when a test cannot be
    /// replayed here.
    fn replay_explored_span(&self, from: u64, to: u64) -> Option<Vec<(TestOutcome, bool)>> {
        (from..to)
            .map(|index| self.replay_explored(index))
            .collect()
    }
    /// Whether test `index` draws its scenario outside the library.
    fn explores(&self, _index: u64) -> bool {
        false
    }
    /// The exploring share the estimate stratifies on: ε of a library
    /// campaign of a grid case under the stratified split
    /// ([`crate::prefix::PrefixFold::strata`]); `None` otherwise.
    fn strata(&self) -> Option<f64> {
        None
    }
    /// The fill that bounds the failure mass outside the library
    /// ([`crate::outside`]); `None` for the NDD and for cases whose
    /// exploration is per decision (car-following).
    fn outside_mass(&self) -> Option<&crate::outside::OutsideMass> {
        None
    }
    /// Whether the library's surrogate has no event in the scenario of test
    /// `index`: asked of exploring tests where the vehicle had one, it
    /// counts the vehicle failing where the surrogate does not.
    fn surrogate_misses(&self, _index: u64) -> bool {
        false
    }
    /// Runs the vehicle (built-in, or `program`) on scenario `cell` as test
    /// `index`, the cell given by the lease (an adaptive campaign's stages
    /// are planned by the coordinator): the event and how close it came
    /// ([`crate::case::Case::criticality`]; `None` when a program does not
    /// say). Grid cases only.
    fn run_cell(
        &self,
        _index: u64,
        _cell: usize,
        _program: Option<&mut dyn ExternalVehicle>,
    ) -> Result<(bool, Option<f64>), DriverError> {
        Err(DriverError(
            "this case's scenarios are not grid cells a lease can name".into(),
        ))
    }
    /// An adaptive campaign's stages, as the coordinator plans them.
    fn adaptive(&self) -> Option<&dyn AdaptiveStages> {
        None
    }
}

/// The stages of an adaptive campaign ([`crate::adaptive`]) as a
/// coordinator keeps them between reports: the running stage, and the step
/// that resolves it once every one of its tests has a result.
pub trait AdaptiveStages: Send + Sync {
    /// The running stage's tests `start..end`; `None` once the campaign
    /// has finished.
    fn running(&self) -> Option<(u64, u64)>;
    /// The campaign's settings.
    fn settings(&self) -> AdaptiveSettings;
    /// The event and criticality of tests `from..to` (inside the running
    /// stage) on the built-in vehicle, run here; `None` for a program.
    fn replay_stage(&self, from: u64, to: u64) -> Option<Vec<(bool, f64)>>;
    /// Resolves the running stage with one result per test
    /// ([`crate::adaptive::Planner::resolve`]).
    fn resolve(&self, results: &[TestResult]);
    /// Where the campaign stands.
    fn progress(&self) -> AdaptiveProgress;
    /// The kind of the stage test `index` belongs to (`"library"`,
    /// `"search"`, `"estimate"`), once planned: only estimation tests enter
    /// the estimate.
    fn stage_kind(&self, index: u64) -> Option<&'static str>;
}

/// What an adaptive campaign run in this process did, whatever the case
/// ([`ScenarioCase::adaptive_campaign`]).
#[derive(Debug, Clone, PartialEq)]
pub struct AdaptiveRun {
    /// The estimate over the estimation tests; `indices` counts every
    /// index the campaign used.
    pub result: crate::campaign::result::CampaignResult,
    /// Tests of the library stage.
    pub library_tests: u64,
    /// What learning where the vehicle fails took: search tests (grid
    /// cases) or states probed (car-following).
    pub search_tests: u64,
    /// Stages run.
    pub stages: u64,
    /// The vehicle's driving, in tests' worth: every test, and the probes'
    /// decisions over a test's (car-following).
    pub driving: f64,
    /// The cells the last estimation stage sampled besides its exploring
    /// share (grid cases; empty otherwise).
    pub support: Vec<usize>,
    /// What its interval assumes, in a sentence.
    pub assumes: &'static str,
    /// What its search tests do: `searching` (cells) or `probing` (states).
    pub search_kind: &'static str,
}

impl AdaptiveRun {
    /// A grid case's run ([`crate::adaptive::run_adaptive`]).
    pub fn from_grid(run: AdaptiveResult) -> Self {
        Self {
            driving: run.result.indices as f64,
            result: run.result,
            library_tests: run.library_tests,
            search_tests: run.search_tests,
            stages: run.stages,
            support: run.support,
            assumes: "the vehicle's failures outside the library are reachable from the \
                      scenarios its tests met through failures and near misses \
                      (docs/adaptive-design.md)",
            search_kind: "searching",
        }
    }
}

/// An adaptive campaign's state, as a coordinator persists and shows it.
#[derive(Debug, Clone, PartialEq)]
pub struct AdaptiveProgress {
    /// The estimation tests' fold.
    pub fold: crate::prefix::PrefixFold,
    /// The running stage's tests `start..end` and its kind; `None` once
    /// finished.
    pub running: Option<(u64, u64, &'static str)>,
    /// Tests of the library stage.
    pub library_tests: u64,
    /// Tests of the search stages.
    pub search_tests: u64,
    /// Stages resolved.
    pub stages: u64,
    /// Cells of the support the estimation samples besides its exploring
    /// share.
    pub support: usize,
    /// The result, once the campaign stopped.
    pub finished: Option<AdaptiveResult>,
}

/// A case opened for a service: everything the coordinator and the worker
/// need, without knowing which case it is.
pub trait ScenarioCase: Send + Sync {
    /// `cut-in`, …
    fn name(&self) -> &'static str;
    /// The simulation preset in force.
    fn preset(&self) -> String;
    /// The exposure's name (`builtin` or the table's name).
    fn exposure_name(&self) -> &str;
    /// A fingerprint of the exposure; libraries and campaigns must share it.
    fn exposure_fingerprint(&self) -> String;
    /// `N(X)`: the grid's scenarios (for car-following, its initial states).
    fn total_scenarios(&self) -> usize;
    /// Everything the service and the command line know about the case.
    fn descriptor(&self) -> &CaseDescriptor;
    /// What the user should know about how the exposure was read (a table
    /// renormalised to sum to 1), if anything.
    fn exposure_note(&self) -> Option<String> {
        None
    }
    /// Why a vehicle this process ran itself failed (a program run through
    /// a [`crate::external::ProgramHost`]), if one did: results computed
    /// since are void.
    fn failure(&self) -> Option<String> {
        None
    }
    /// How a campaign spreads ε when the request does not say.
    fn default_outside(&self) -> OutsideSpread {
        self.descriptor().default_outside
    }
    /// The vehicle specification validated and written out in full (every
    /// parameter with its value), as it is stored. An external program is
    /// `{"external": NAME, "mode": "step" | "episode"}`.
    fn normalise_vehicle(&self, spec: &serde_json::Value) -> Result<serde_json::Value, CaseError>;
    /// Checks a build request before it is queued.
    fn check_request(&self, request: &BuildRequest) -> Result<(), CaseError>;
    /// Builds a library of `surrogate` (CPU-heavy: call off any async runtime).
    fn build_library(
        &self,
        surrogate: &serde_json::Value,
        request: &BuildRequest,
    ) -> Result<BuiltLibrary, CaseError> {
        self.build_library_observed(surrogate, request, &Progress::default())
    }
    /// [`ScenarioCase::build_library`], counting the search's work in
    /// `progress` as it goes.
    fn build_library_observed(
        &self,
        surrogate: &serde_json::Value,
        request: &BuildRequest,
        progress: &Progress,
    ) -> Result<BuiltLibrary, CaseError>;
    /// The tests of a campaign of `vut`: from the library `file` with
    /// exploration `epsilon` spread by `outside` and tests split by `split`
    /// (grid cases; car-following explores per decision), or from the NDD
    /// when `file` is `None`.
    fn campaign(
        &self,
        file: Option<&[u8]>,
        vut: &serde_json::Value,
        epsilon: f64,
        outside: OutsideSpread,
        split: Split,
        seed: u64,
    ) -> Result<Arc<dyn CampaignTests>, CaseError>;
    /// A library build's surrogate runs as a campaign's tests, so workers
    /// run them (programs included) under the leases, checks and restarts
    /// of any campaign: test `i` runs `surrogate` on the `i`-th cell with
    /// exposure, in cell order, weight 1. Grid cases only.
    fn enumeration(
        &self,
        surrogate: &serde_json::Value,
    ) -> Result<Arc<dyn CampaignTests>, CaseError> {
        let _ = surrogate;
        Err(CaseError::Unsupported(format!(
            "case {}: its libraries are not built by enumerating scenarios",
            self.name()
        )))
    }
    /// The number of tests of [`ScenarioCase::enumeration`]: the cells
    /// with exposure.
    fn enumeration_len(&self) -> u64 {
        0
    }
    /// The exhaustive library of `surrogate` from its enumeration: the test
    /// indices where it had the event.
    fn library_from_enumeration(
        &self,
        surrogate: &serde_json::Value,
        threshold: Option<Threshold>,
        events: &[u64],
    ) -> Result<BuiltLibrary, CaseError> {
        let _ = (surrogate, threshold, events);
        Err(CaseError::Unsupported(format!(
            "case {}: its libraries are not built by enumerating scenarios",
            self.name()
        )))
    }
    /// What library `file` holds (read without checking that it was built
    /// on this case's exposure).
    fn library_summary(&self, file: &[u8]) -> Result<LibrarySummary, CaseError>;
    /// A library `file` built elsewhere (by a worker) for `surrogate`,
    /// checked as well as this process can without building it again: the
    /// file reads as this case's library, and a grid case runs a built-in
    /// surrogate again on up to `sample` of its cells, spread evenly, each
    /// of which must carry the criticality `P(S|x)·P(x)` it records. What
    /// [`ScenarioCase::build_library_observed`] would return for it.
    fn built_elsewhere(
        &self,
        file: &[u8],
        surrogate: &serde_json::Value,
        sample: usize,
    ) -> Result<BuiltLibrary, CaseError>;
    /// The picture of a library file: the exposure beside the library's
    /// sampling distribution (ε = 0), projected onto two axes.
    fn library_picture(&self, file: &[u8]) -> Result<Vec<PictureMap>, CaseError>;
    /// Runs an adaptive campaign of built-in vehicle `vut` on the library
    /// `file`, in this process: [`crate::adaptive`] with `settings` on a
    /// grid case, [`crate::cases::carfollow::adaptive`] with its own on
    /// car-following.
    fn adaptive_campaign(
        &self,
        file: &[u8],
        vut: &serde_json::Value,
        epsilon: f64,
        settings: AdaptiveSettings,
        rule: &StoppingRule,
        seed: u64,
    ) -> Result<AdaptiveRun, CaseError>;
    /// The tests of a service adaptive campaign of `vut` on the library
    /// `file`: the coordinator's copy plans its stages
    /// ([`CampaignTests::adaptive`]). Grid cases only.
    fn adaptive_tests(
        &self,
        file: &[u8],
        vut: &serde_json::Value,
        epsilon: f64,
        settings: AdaptiveSettings,
        rule: &StoppingRule,
        seed: u64,
    ) -> Result<Arc<dyn CampaignTests>, CaseError>;
    /// The exact `P(A)` of a vehicle by enumeration of the grid.
    fn exact_event_probability(&self, vehicle: &serde_json::Value) -> Result<f64, CaseError>;
    /// `P(x)` of every grid cell, in cell order: with a vehicle's outcome
    /// on every cell (an external program's, run once per cell) it gives
    /// the exact `P(A)`. Grid cases only.
    fn cell_exposures(&self) -> Result<Vec<f64>, CaseError>;
    /// The names of a scenario's parameters, in the order
    /// [`PlannedTest::scenario`] lists them (a grid case's axes); empty for
    /// sequential cases, whose scenarios are drawn while they run.
    fn dimension_names(&self) -> Vec<String> {
        Vec::new()
    }
    /// Grid cell `cell`'s parameters, in [`Self::dimension_names`]' order;
    /// `None` past the grid or for sequential cases.
    fn cell_values(&self, cell: usize) -> Option<Vec<f64>> {
        let _ = cell;
        None
    }
    /// The criticality `V(x)` of every cell of library `file`, by cell
    /// (grid cases; empty for others).
    fn library_criticalities(
        &self,
        file: &[u8],
    ) -> Result<std::collections::HashMap<usize, f64>, CaseError> {
        let _ = file;
        Ok(Default::default())
    }
    /// Grid cell `cell` as an OpenSCENARIO 1.0 file another simulator can
    /// replay ([`crate::openscenario`]); `None` for cases without one.
    fn openscenario(&self, cell: usize) -> Option<String> {
        let _ = cell;
        None
    }
    /// `P(A)` with the expected tests of a library campaign and of the NDD
    /// baseline to relative half-width `beta` at `confidence`: the analytic
    /// acceleration ratio (SPEC §3).
    fn exact_report(
        &self,
        vehicle: &serde_json::Value,
        file: &[u8],
        epsilon: f64,
        outside: OutsideSpread,
        beta: f64,
        confidence: f64,
    ) -> Result<ExactReport, CaseError>;
}
