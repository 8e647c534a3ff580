//! One row of the reproduction: a vehicle tested with one case's library,
//! with every campaign run for it and the paper's numbers beside.

use tslg_api::CampaignView;
use tslg_method::cases::PaperFigures as Paper;
use tslg_method::exact::ExactReport;

/// Where an NDD test count comes from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum NddSource {
    /// A campaign ran to β.
    Run,
    /// `z² (1 − μ)/(β² μ)` with the exact `P(A)`.
    AnalyticExact,
    /// The same with the library campaigns' median estimate.
    AnalyticEstimate,
}

/// One vehicle tested with one case's library: the row of the table.
pub struct Row {
    pub case: &'static str,
    pub preset: &'static str,
    pub exposure: String,
    pub surrogate: &'static str,
    pub library_size: u64,
    pub total_scenarios: u64,
    pub vehicle: &'static str,
    pub epsilon: f64,
    pub beta: f64,
    pub library_runs: Vec<CampaignView>,
    /// The guarded campaign (grid cases).
    pub guarded_run: Option<CampaignView>,
    /// Adaptive campaigns, one per seed of the library campaigns (grid
    /// cases; none for car-following).
    pub adaptive_runs: Vec<CampaignView>,
    /// Adaptive campaigns that search the grid's coarser lattice, one per
    /// seed, on a grid finer than [`tslg_method::adaptive::MAX_LATTICE_POINTS`]
    /// cells; none elsewhere.
    pub lattice_runs: Vec<CampaignView>,
    pub ndd_run: Option<CampaignView>,
    pub ndd_tests: f64,
    pub ndd_source: NddSource,
    pub exact: Option<ExactReport>,
    pub paper: Paper,
}

/// The median of sorted values, the lower middle one of an even count (a
/// value that occurred); `None` when empty.
pub fn lower_median<T>(sorted: &[T]) -> Option<&T> {
    sorted.get(sorted.len().saturating_sub(1) / 2)
}
