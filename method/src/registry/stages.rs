//! An adaptive campaign's stages as a coordinator keeps them between
//! reports, and what an adaptive campaign run in this process did.

use crate::adaptive::{AdaptiveResult, AdaptiveSettings, Explored, StageRecord, TestResult};

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
    /// ([`crate::adaptive::Planner::resolve`]), and says what it did.
    fn resolve(&self, results: &[TestResult]) -> StageRecord;
    /// Whether the running stage's rule stops the campaign within its
    /// first `results.len()` tests, whatever the rest give
    /// ([`crate::adaptive::Planner::stops_within`]): the stage may then be
    /// resolved at once, with any results for the others.
    fn stops_within(&self, results: &[TestResult]) -> bool;
    /// Where the campaign stands.
    fn progress(&self) -> AdaptiveProgress;
    /// The kind of the stage test `index` belongs to (`"library"`,
    /// `"search"`, `"estimate"`), once planned: only estimation tests enter
    /// the estimate.
    fn stage_kind(&self, index: u64) -> Option<&'static str>;
}

/// What an adaptive campaign run in this process did, whatever the case
/// ([`super::CampaignSampler::adaptive_campaign`]).
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
    /// The estimation stages' exploring tests, which bound the failure
    /// mass the support leaves out ([`Explored::upper`]).
    pub explored: Explored,
    /// The result, once the campaign stopped.
    pub finished: Option<AdaptiveResult>,
}
