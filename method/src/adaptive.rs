//! Adaptive campaigns on grid cases (issue 21, docs/adaptive-design.md):
//! find where this vehicle fails, then measure it.
//!
//! A campaign runs in stages, each planned from the resolved results of the
//! stages before it (and the seed) alone, so it is the same whoever runs the
//! tests and in how many pieces:
//!
//! 1. **Library**: the first `library_tests` tests are drawn from the
//!    library's ε-greedy distribution, as a library campaign's are.
//! 2. **Search**: every untested neighbour outside the library of a *seed*
//!    (a scenario where the vehicle failed, or came within `near_miss` of
//!    failing by its [`Case::criticality`]) whose exposure exceeds
//!    `exposure_floor` times the failure mass found so far is tested once,
//!    in cell order; repeated until no seed has such a neighbour. What it
//!    rests on is that the vehicle's failures outside the library are
//!    reachable through failures and near misses from what the tests meet.
//! 3. **Estimation**: the failing scenarios found and the library's cells
//!    not yet tested, `K` ([`Planner::support`]), become a library with
//!    `V(x) = P(x)`, sampled with the stratified split
//!    ([`crate::sampling::Split::Stratified`]) and a share
//!    `1/explore_every` spread by exposure over the rest of the grid. Every
//!    weight is bounded (`P(K)/(1 − ε)` inside, `P(X \ K)/ε` outside), and
//!    a stage of `stage_tests` tests (a multiple of `explore_every`) holds
//!    exactly its share of exploring tests, so the mean of its terms is
//!    unbiased given the past. When an estimation stage meets a new failure
//!    or near miss, the campaign searches again from it.
//!
//! Only estimation tests enter the estimate; library and search tests are
//! the cost of finding `K`. Each estimation term is unbiased given the
//! stages before it, so the estimate is a martingale average, and the
//! stopping rule of [`crate::estimator`] applies to it as to any campaign.

use crate::campaign::CampaignResult;
use crate::case::Case;
use crate::estimator::{Decision, StoppingRule};
use crate::library::{Library, LibraryCell};
use crate::prefix::{PrefixFold, SparseOutcome};
use crate::sampling::{
    LibraryDistribution, NddDistribution, OutsideSpread, SamplingError, Split, TestDistribution,
};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// How an adaptive campaign searches and samples.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AdaptiveSettings {
    /// Tests of the first stage, drawn from the library's distribution.
    pub library_tests: u64,
    /// A tested scenario of criticality at most this seeds the search.
    pub near_miss: f64,
    /// A neighbour is searched only when its exposure exceeds this times
    /// the failure mass found so far.
    pub exposure_floor: f64,
    /// One estimation test in this many explores outside `K`.
    pub explore_every: u64,
    /// Tests of an estimation stage: a multiple of `explore_every`.
    pub stage_tests: u64,
}

impl Default for AdaptiveSettings {
    /// Chosen from measurements on cut-in and highway-exit
    /// (docs/adaptive-design.md): near_miss 0.05 and exposure_floor 10⁻⁴
    /// meet the cost targets on every cut-in pairing and reach every
    /// highway-exit failure of the gap-seeker, which 0.02 does not.
    fn default() -> Self {
        Self {
            library_tests: 100,
            near_miss: 0.05,
            exposure_floor: 1e-4,
            explore_every: 10,
            stage_tests: 100,
        }
    }
}

/// What one test told about its scenario.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// The scenario's grid cell.
    pub cell: usize,
    /// Whether the vehicle had the event.
    pub event: bool,
    /// How close it came ([`Case::criticality`]).
    pub criticality: f64,
}

/// One stage's plan.
#[derive(Debug, Clone)]
pub enum Stage {
    /// Draws from the library's distribution.
    Library(Arc<TestDistribution>),
    /// The cells to test, one per test, in order.
    Search(Vec<usize>),
    /// Draws from the support and the exposure outside it.
    Estimate(Arc<TestDistribution>),
}

/// What the tests so far showed, per cell, kept by [`Planner::observe`]:
/// the search's candidates are gathered as seeds are met, so planning a
/// stage does not rescan the grid.
#[derive(Debug, Clone)]
pub struct Knowledge {
    /// The criticality of each tested cell (0 for a failure).
    criticality: Vec<Option<f64>>,
    /// The failing cells, in the order they were found.
    failures: Vec<usize>,
    /// `Σ P(x)` over `failures`, summed in that order.
    failure_mass: f64,
    /// Cells outside the library with exposure that neighboured a seed
    /// when it was met and were untested then (each once).
    candidates: Vec<usize>,
    is_candidate: Vec<bool>,
}

impl Knowledge {
    /// The failing cells found, in the order they were found.
    pub fn failures(&self) -> &[usize] {
        &self.failures
    }
}

/// Why an adaptive campaign cannot run.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum AdaptiveError {
    /// Settings out of range.
    #[error("adaptive settings: {0}")]
    Settings(String),
    /// The guard bounds a fixed library's outside; an adaptive campaign's changes.
    #[error(
        "guard_outside bounds the outside of a fixed library; an adaptive campaign's \
         library grows as it learns"
    )]
    Guard,
    /// The library's distribution cannot be built.
    #[error(transparent)]
    Sampling(#[from] SamplingError),
}

/// Plans the stages of one adaptive campaign of a grid case.
pub struct Planner<'a, C: Case> {
    case: &'a C,
    library: &'a Library,
    settings: AdaptiveSettings,
    in_library: Vec<bool>,
    /// The first stage's distribution: the library's, ε-greedy.
    library_stage: Arc<TestDistribution>,
    /// The last estimation stage's support and distribution, reused while
    /// the support is unchanged.
    estimation: std::sync::Mutex<Option<(Vec<usize>, Arc<TestDistribution>)>>,
}

impl<'a, C: Case> Planner<'a, C> {
    /// The planner of campaigns on `library` (explored with share `epsilon`
    /// in the library stage).
    pub fn new(
        case: &'a C,
        library: &'a Library,
        epsilon: f64,
        settings: AdaptiveSettings,
    ) -> Result<Self, AdaptiveError> {
        let s = settings;
        if s.library_tests == 0 || s.explore_every < 2 || s.stage_tests == 0 {
            return Err(AdaptiveError::Settings(
                "library_tests and stage_tests must be positive and explore_every at least 2"
                    .into(),
            ));
        }
        if s.stage_tests % s.explore_every != 0 {
            return Err(AdaptiveError::Settings(format!(
                "stage_tests = {} must be a multiple of explore_every = {}",
                s.stage_tests, s.explore_every
            )));
        }
        if !(0.0..=1.0).contains(&s.near_miss) || !(0.0..1.0).contains(&s.exposure_floor) {
            return Err(AdaptiveError::Settings(
                "near_miss must be in [0, 1] and exposure_floor in [0, 1)".into(),
            ));
        }
        let library_stage = Arc::new(TestDistribution::library(LibraryDistribution::new(
            library,
            case.exposure(),
            epsilon,
            OutsideSpread::Uniform,
            Split::Stratified,
        )?));
        let mut in_library = vec![false; case.grid().len()];
        for c in &library.cells {
            in_library[c.cell] = true;
        }
        Ok(Self {
            case,
            library,
            settings,
            in_library,
            library_stage,
            estimation: Default::default(),
        })
    }

    /// Nothing tested yet.
    pub fn knowledge(&self) -> Knowledge {
        let cells = self.case.grid().len();
        Knowledge {
            criticality: vec![None; cells],
            failures: Vec::new(),
            failure_mass: 0.0,
            candidates: Vec::new(),
            is_candidate: vec![false; cells],
        }
    }

    /// Records a test in `knowledge`; a cell's outcome is the same every
    /// time it is run, so only its first test counts. A seed (a failure, or
    /// a near miss within `near_miss`) adds its untested neighbours outside
    /// the library, with exposure, to the search's candidates.
    pub fn observe(&self, knowledge: &mut Knowledge, o: &Observation) {
        if knowledge.criticality[o.cell].is_some() {
            return;
        }
        let criticality = if o.event { 0.0 } else { o.criticality };
        knowledge.criticality[o.cell] = Some(criticality);
        let exposure = self.case.exposure();
        if o.event {
            knowledge.failures.push(o.cell);
            knowledge.failure_mass += exposure.p(o.cell);
        }
        if criticality <= self.settings.near_miss {
            for n in self.case.grid().neighbours(o.cell) {
                if knowledge.criticality[n].is_none()
                    && !self.in_library[n]
                    && exposure.p(n) > 0.0
                    && !knowledge.is_candidate[n]
                {
                    knowledge.is_candidate[n] = true;
                    knowledge.candidates.push(n);
                }
            }
        }
    }

    /// The first stage: the library's own distribution.
    pub fn first(&self) -> Stage {
        Stage::Library(Arc::clone(&self.library_stage))
    }

    /// How many tests `stage` has.
    pub fn len(&self, stage: &Stage) -> u64 {
        match stage {
            Stage::Library(_) => self.settings.library_tests,
            Stage::Search(cells) => cells.len() as u64,
            Stage::Estimate(_) => self.settings.stage_tests,
        }
    }

    /// The stage after the ones `knowledge` summarises: a search while a
    /// seed has an untested neighbour worth testing, else an estimation
    /// stage on the failures found.
    pub fn next(&self, knowledge: &Knowledge) -> Stage {
        let frontier = self.frontier(knowledge);
        if !frontier.is_empty() {
            return Stage::Search(frontier);
        }
        let support = self.support(knowledge);
        let mut cache = self
            .estimation
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        if let Some((cached, distribution)) = cache.as_ref() {
            if *cached == support {
                return Stage::Estimate(Arc::clone(distribution));
            }
        }
        let distribution = Arc::new(self.estimation(&support));
        *cache = Some((support, Arc::clone(&distribution)));
        Stage::Estimate(distribution)
    }

    /// Untested neighbours outside the library of the seeds, whose exposure
    /// exceeds the floor, in cell order.
    fn frontier(&self, knowledge: &Knowledge) -> Vec<usize> {
        let exposure = self.case.exposure();
        let floor = self.settings.exposure_floor * knowledge.failure_mass;
        let mut frontier: Vec<usize> = knowledge
            .candidates
            .iter()
            .copied()
            .filter(|&n| knowledge.criticality[n].is_none() && exposure.p(n) > floor)
            .collect();
        frontier.sort_unstable();
        frontier
    }

    /// The cells an estimation stage samples besides its exploring share:
    /// the failures found and the library's cells not yet tested (a tested
    /// cell that passed needs no test: the vehicles are deterministic).
    pub fn support(&self, knowledge: &Knowledge) -> Vec<usize> {
        let untested_library = self
            .library
            .cells
            .iter()
            .map(|c| c.cell)
            .filter(|&c| knowledge.criticality[c].is_none());
        let mut support: Vec<usize> = knowledge
            .failures
            .iter()
            .copied()
            .chain(untested_library)
            .collect();
        support.sort_unstable();
        support.dedup();
        support
    }

    /// The support as a library (`V = P`), explored by exposure with share
    /// `1/explore_every`; the exposure itself when the support is empty.
    fn estimation(&self, support: &[usize]) -> TestDistribution {
        let exposure = self.case.exposure();
        let mut cells: Vec<LibraryCell> = support
            .iter()
            .filter(|&&c| exposure.p(c) > 0.0)
            .map(|&cell| LibraryCell {
                cell,
                criticality: exposure.p(cell),
            })
            .collect();
        if cells.is_empty() {
            return TestDistribution::Ndd(NddDistribution::new(exposure));
        }
        cells.sort_by_key(|c| c.cell);
        let w = cells.iter().map(|c| c.criticality).sum();
        let found = Library {
            cells,
            w,
            ..self.library.clone()
        };
        let epsilon = 1.0 / self.settings.explore_every as f64;
        TestDistribution::library(
            LibraryDistribution::new(
                &found,
                exposure,
                epsilon,
                OutsideSpread::Ndd,
                Split::Stratified,
            )
            .expect("a non-empty library of cells with exposure"),
        )
    }
}

/// What an adaptive campaign did.
#[derive(Debug, Clone, PartialEq)]
pub struct AdaptiveResult {
    /// The estimate over the estimation tests; `indices` counts every test.
    pub result: CampaignResult,
    /// Tests of the library stage.
    pub library_tests: u64,
    /// Tests of the search stages.
    pub search_tests: u64,
    /// Stages run (library, searches, estimations).
    pub stages: u64,
    /// The cells the last estimation stage sampled besides its exploring
    /// share ([`Planner::support`]).
    pub support: Vec<usize>,
}

/// Runs an adaptive campaign of built-in `vehicle` on `library` to `rule`.
/// Tests run in parallel within a stage and are folded in index order, so
/// the result does not depend on the number of threads.
pub fn run_adaptive<C: Case>(
    case: &C,
    vehicle: &C::Vehicle,
    library: &Library,
    epsilon: f64,
    settings: AdaptiveSettings,
    rule: &StoppingRule,
    seed: u64,
) -> Result<AdaptiveResult, AdaptiveError> {
    if rule.guard_outside {
        return Err(AdaptiveError::Guard);
    }
    let planner = Planner::new(case, library, epsilon, settings)?;
    let observe = |cell: usize| {
        let (event, criticality) = case.event_and_criticality(vehicle, cell);
        Observation {
            cell,
            event,
            criticality,
        }
    };
    let mut knowledge = planner.knowledge();
    let mut fold = PrefixFold::default();
    let z = rule.z();
    // The rule of the estimation tests; the budget counts every test.
    let estimation_rule = StoppingRule {
        max_tests: u64::MAX,
        ..*rule
    };
    let mut index = 0u64;
    let mut spent = Spent::default();
    let mut stage = planner.first();
    loop {
        let len = planner.len(&stage).min(rule.max_tests - index);
        let from = index;
        let observations: Vec<(Observation, f64)> = (from..from + len)
            .into_par_iter()
            .map(|i| match &stage {
                Stage::Library(d) | Stage::Estimate(d) => {
                    let draw = d.draw(seed, i);
                    (observe(draw.cell), draw.weight)
                }
                Stage::Search(cells) => (observe(cells[(i - from) as usize]), 0.0),
            })
            .collect();
        spent.stages += 1;
        index += len;
        match &stage {
            Stage::Library(_) => spent.library_tests += len,
            Stage::Search(_) => spent.search_tests += len,
            Stage::Estimate(_) => {
                let to = fold.indices + len;
                let events: Vec<(u64, SparseOutcome)> = observations
                    .iter()
                    .enumerate()
                    .filter(|(_, (o, _))| o.event)
                    .map(|(k, &(_, w))| (fold.indices + k as u64, SparseOutcome::Event(w)))
                    .collect();
                if let Some(status) = fold
                    .advance(&estimation_rule, z, to, &events, None)
                    .expect("bounded weights in index order")
                {
                    let used = index - (to - fold.indices);
                    let support = planner.support(&knowledge);
                    return Ok(spent.result(status, &fold, rule, used, support));
                }
            }
        }
        for (o, _) in &observations {
            planner.observe(&mut knowledge, o);
        }
        if index >= rule.max_tests {
            let support = planner.support(&knowledge);
            return Ok(spent.result(Decision::Exhausted, &fold, rule, index, support));
        }
        stage = planner.next(&knowledge);
    }
}

/// The tests an adaptive campaign spent outside its estimate.
#[derive(Default)]
struct Spent {
    library_tests: u64,
    search_tests: u64,
    stages: u64,
}

impl Spent {
    /// The campaign's result after `indices` tests in all, the estimate
    /// being `fold`'s.
    fn result(
        self,
        status: Decision,
        fold: &PrefixFold,
        rule: &StoppingRule,
        indices: u64,
        support: Vec<usize>,
    ) -> AdaptiveResult {
        let mut result = CampaignResult::from_fold(status, fold, rule, None);
        result.indices = indices;
        AdaptiveResult {
            result,
            library_tests: self.library_tests,
            search_tests: self.search_tests,
            stages: self.stages,
            support,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cutin::{CutIn, CutInPreset};
    use crate::library::{build_library, LibraryRequest, SearchMethod, Threshold};
    use crate::vehicle::VehicleModel;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The frontier by scanning every tested cell's neighbourhood afresh.
    fn frontier_by_scan<C: Case>(planner: &Planner<'_, C>, knowledge: &Knowledge) -> Vec<usize> {
        let exposure = planner.case.exposure();
        let found: f64 = knowledge.failures.iter().map(|&c| exposure.p(c)).sum();
        let floor = planner.settings.exposure_floor * found;
        let grid = planner.case.grid();
        let mut wanted = vec![false; grid.len()];
        for (cell, c) in knowledge.criticality.iter().enumerate() {
            if c.is_some_and(|c| c <= planner.settings.near_miss) {
                for n in grid.neighbours(cell) {
                    if knowledge.criticality[n].is_none()
                        && exposure.p(n) > floor
                        && !planner.in_library[n]
                    {
                        wanted[n] = true;
                    }
                }
            }
        }
        (0..grid.len()).filter(|&c| wanted[c]).collect()
    }

    #[test]
    fn the_kept_frontier_is_the_scanned_one_after_every_observation() {
        let case = CutIn::builtin(CutInPreset::PaperCode);
        let idm = VehicleModel::builtin("idm").unwrap();
        let request = LibraryRequest {
            threshold: Threshold::default(),
            search: SearchMethod::Exhaustive,
        };
        let spec = serde_json::to_value(idm).unwrap();
        let library = build_library(&case, &idm, spec, "paper-code", &request);
        let planner = Planner::new(&case, &library, 0.1, AdaptiveSettings::default()).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for _ in 0..5 {
            let mut knowledge = planner.knowledge();
            for _ in 0..800 {
                let cell = rng.random_range(0..case.grid().len());
                let o = Observation {
                    cell,
                    event: rng.random::<f64>() < 0.2,
                    criticality: rng.random::<f64>() * 0.3,
                };
                planner.observe(&mut knowledge, &o);
                assert_eq!(
                    planner.frontier(&knowledge),
                    frontier_by_scan(&planner, &knowledge)
                );
            }
            assert!(!knowledge.failures().is_empty());
        }
    }
}
