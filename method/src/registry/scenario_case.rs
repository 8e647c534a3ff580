//! A case opened for a service: everything the coordinator, the worker and
//! the command line need, without knowing which case it is. The interface
//! is split by who calls it, and a caller takes the part it uses (trait
//! upcasting turns an `&dyn ScenarioCase` into any of them):
//!
//! - [`CaseIdentity`]: what the case is (its name, preset, exposure,
//!   descriptor) and the vehicles it runs, which every part builds on;
//! - [`LibraryBuilder`]: building and reading libraries (the coordinator's
//!   builds, `tslg library`, a worker's whole build);
//! - [`CampaignSampler`]: a campaign's tests, their draws and weights (the
//!   estimator's side: the coordinator's checks, the workers' runs through
//!   [`CampaignTests`], the in-process campaigns);
//! - [`ExactAnswers`]: `P(A)` by enumeration and the analytic number of
//!   tests (grid cases);
//! - [`CaseViews`]: a scenario's parameters, a library's picture, an
//!   OpenSCENARIO file (the dashboard, event export).
//!
//! [`ScenarioCase`] is all five, for what holds a whole case (an opened
//! campaign, a worker's prepared one). A case implements the five (the
//! last two and the enumeration have defaults that say the case has none),
//! so a new sequential case implements what it needs: identity, vehicles,
//! libraries and sampling; it is a `ScenarioCase` by the blanket impl.

use super::build::{BuildRequest, BuiltLibrary, LibrarySummary};
use super::campaign_tests::CampaignTests;
use super::error::CaseError;
use super::picture::PictureMap;
use super::stages::AdaptiveRun;
use crate::adaptive::AdaptiveSettings;
use crate::descriptor::CaseDescriptor;
use crate::estimator::StoppingRule;
use crate::exact::ExactReport;
use crate::library::Threshold;
use crate::progress::Progress;
use crate::sampling::{OutsideSpread, Split};
use std::collections::HashMap;
use std::sync::Arc;

/// A whole case: every part of the interface.
pub trait ScenarioCase: LibraryBuilder + CampaignSampler + ExactAnswers + CaseViews {}

impl<T: LibraryBuilder + CampaignSampler + ExactAnswers + CaseViews + ?Sized> ScenarioCase for T {}

/// What a case is, and the vehicles it runs.
pub trait CaseIdentity: Send + Sync {
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
}

/// Building and reading a case's libraries.
pub trait LibraryBuilder: CaseIdentity {
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
    /// [`LibraryBuilder::build_library`], counting the search's work in
    /// `progress` as it goes.
    fn build_library_observed(
        &self,
        surrogate: &serde_json::Value,
        request: &BuildRequest,
        progress: &Progress,
    ) -> Result<BuiltLibrary, CaseError>;
    /// A library build's surrogate runs as a campaign's tests, so workers
    /// run them (programs included) under the leases, checks and restarts
    /// of any campaign: test `i` runs `surrogate` on the `i`-th cell with
    /// exposure, in cell order, weight 1. Grid cases only.
    fn enumeration(
        &self,
        surrogate: &serde_json::Value,
    ) -> Result<Arc<dyn CampaignTests>, CaseError> {
        let _ = surrogate;
        Err(not_enumerated())
    }
    /// The number of tests of [`LibraryBuilder::enumeration`]: the cells
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
        Err(not_enumerated())
    }
    /// What library `file` holds (read without checking that it was built
    /// on this case's exposure).
    fn library_summary(&self, file: &[u8]) -> Result<LibrarySummary, CaseError>;
    /// A library `file` built elsewhere (by a worker) for `surrogate`,
    /// checked as well as this process can without building it again: the
    /// file reads as this case's library, and a grid case runs a built-in
    /// surrogate again on up to `sample` of its cells, spread evenly, each
    /// of which must carry the criticality `P(S|x)·P(x)` it records. What
    /// [`LibraryBuilder::build_library_observed`] would return for it.
    fn built_elsewhere(
        &self,
        file: &[u8],
        surrogate: &serde_json::Value,
        sample: usize,
    ) -> Result<BuiltLibrary, CaseError>;
}

/// Why a case's libraries cannot be built cell by cell.
fn not_enumerated() -> CaseError {
    CaseError::Unsupported("this case's libraries are not built by enumerating scenarios".into())
}

/// A campaign's tests: their draws and weights, and adaptive campaigns'
/// stages.
pub trait CampaignSampler: CaseIdentity {
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
}

/// Exact answers by enumeration of the grid.
pub trait ExactAnswers: CaseIdentity {
    /// The exact `P(A)` of a vehicle by enumeration of the grid.
    fn exact_event_probability(&self, vehicle: &serde_json::Value) -> Result<f64, CaseError>;
    /// `P(x)` of every grid cell, in cell order: with a vehicle's outcome
    /// on every cell (an external program's, run once per cell) it gives
    /// the exact `P(A)`. Grid cases only.
    fn cell_exposures(&self) -> Result<Vec<f64>, CaseError>;
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

/// What a case shows of its scenarios and libraries.
pub trait CaseViews: CaseIdentity {
    /// The names of a scenario's parameters, in the order
    /// [`super::PlannedTest::scenario`] lists them (a grid case's axes);
    /// empty for sequential cases, whose scenarios are drawn while they
    /// run.
    fn dimension_names(&self) -> Vec<String> {
        Vec::new()
    }
    /// Grid cell `cell`'s parameters, in [`Self::dimension_names`]' order;
    /// `None` past the grid or for sequential cases.
    fn cell_values(&self, cell: usize) -> Option<Vec<f64>> {
        let _ = cell;
        None
    }
    /// The picture of a library file: the exposure beside the library's
    /// sampling distribution (ε = 0), projected onto two axes.
    fn library_picture(&self, file: &[u8]) -> Result<Vec<PictureMap>, CaseError>;
    /// The criticality `V(x)` of every cell of library `file`, by cell
    /// (grid cases; empty for others).
    fn library_criticalities(&self, file: &[u8]) -> Result<HashMap<usize, f64>, CaseError> {
        let _ = file;
        Ok(Default::default())
    }
    /// Grid cell `cell` as an OpenSCENARIO 1.0 file another simulator can
    /// replay ([`crate::openscenario`]); `None` for cases without one.
    fn openscenario(&self, cell: usize) -> Option<String> {
        let _ = cell;
        None
    }
}
