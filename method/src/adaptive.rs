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
//! A noisy vehicle's cells fail with a probability: its support grows by
//! the failures every run shows, with their neighbours, and only failures
//! seed the search ([`Planner::observe`]). Whether such a support holds
//! every cell that can fail is never checkable from a few runs, so its
//! campaigns run under the outside guard, with the guard's share of
//! exploring tests chosen to need the fewest tests
//! ([`AllocationInputs::guard_share`]), and answer with the guarded
//! interval (docs/statistics.md, "Noisy vehicles").
//!
//! Only estimation tests enter the estimate; library and search tests are
//! the cost of finding `K`. Each estimation term is unbiased given the
//! stages before it, so the estimate is a martingale average, and the
//! stopping rule of [`crate::estimator`] applies to it as to any campaign.

use crate::campaign::result::CampaignResult;
use crate::case::Case;
use crate::estimator::{Decision, StoppingRule};
use crate::library::Library;
use crate::prefix::{PrefixFold, SparseOutcome};
use crate::sampling::SupportDistribution;
use crate::sampling::{
    LibraryDistribution, NddDistribution, OutsideSpread, SamplingError, Split, TestDistribution,
};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

mod allocation;
mod lattice;
mod outside;
mod record;
pub use allocation::{guard_shares, AllocationInputs};
use lattice::merged;
pub use lattice::{Lattice, MAX_LATTICE_POINTS};
pub use outside::Explored;
pub use record::StageRecord;

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
    /// The vehicle's runs of one scenario may differ (a noisy model or
    /// program): every run of a cell counts, a failure in any run puts the
    /// cell and its neighbours in the support and seeds the search, whose
    /// candidates are tested once, and a library cell that passed stays in
    /// the support ("passed once" is not "never fails"); near misses count
    /// for nothing ([`Planner::observe`]). Such a campaign runs under the
    /// guard unless asked not to ([`crate::noise::guards_by_default`]).
    pub noisy: bool,
    /// Search a fine grid on its coarser lattice ([`Lattice`]): a seed
    /// puts its whole block in the support and the search walks lattice
    /// points, so its cost is the failure region's volume in blocks. It
    /// rests on each failing region holding failing or near-miss lattice
    /// points: true of a MOBIL driver on highway-exit's paper grid, not of
    /// the gap-seeker, whose failures lie in sheets a cell or two thick
    /// between them (docs/adaptive-design.md, "Fine grids").
    #[serde(default)]
    pub lattice: bool,
    /// A search stage of fewer cells than this is widened by the rings
    /// around its cells, nearest first, up to this many: one round of a
    /// large fleet tests what several one-ring searches would, in one
    /// test's time instead of several. It changes which cells are
    /// tested, never how an estimation stage is sampled or weighted, so
    /// the estimate stays unbiased given the past; 0 searches one ring a
    /// stage ([`Self::fleet_search_width`]).
    #[serde(default)]
    pub search_width: u64,
}

impl AdaptiveSettings {
    /// The search width a stage length implies. A service campaign's
    /// stages longer than 100 tests are sized for a fleet of
    /// `stage_tests / 5` threads (`20⌈5T/20⌉`, docs/api.md), so its search
    /// stages are widened to one round of that fleet; stages of at most
    /// 100 tests (up to 20 threads, the default) search one ring a stage.
    pub fn fleet_search_width(stage_tests: u64) -> u64 {
        if stage_tests > 100 {
            stage_tests / 5
        } else {
            0
        }
    }
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
            noisy: false,
            lattice: false,
            search_width: 0,
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

impl Stage {
    /// `"library"`, `"search"` or `"estimate"`.
    pub fn kind(&self) -> &'static str {
        match self {
            Stage::Library(_) => "library",
            Stage::Search(_) => "search",
            Stage::Estimate(_) => "estimate",
        }
    }
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
    /// [`Planner::support`], kept as tests are observed: the failures
    /// found and the library's untested cells, increasing.
    support: Vec<usize>,
    /// `Σ P(x)` over `failures`, summed in that order.
    failure_mass: f64,
    /// Cells outside the library with exposure that neighboured a seed
    /// when it was met and were untested then (each once); on a lattice
    /// ([`Lattice`]), the lattice points next to a seed's block.
    candidates: Vec<usize>,
    is_candidate: Vec<bool>,
    /// On a lattice, the lattice points whose block a seed put in the
    /// support.
    hot: Vec<bool>,
    /// A noisy vehicle's cells: whether a run of each failed; empty for a
    /// deterministic one.
    failed: Vec<bool>,
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
    /// The guard bounds the failure mass off a grid's library or support;
    /// car-following's adaptive campaign learns a policy over states.
    #[error(
        "guard_outside bounds the failure mass off a grid case's library or support; \
         car-following's adaptive campaign probes states and has no outside to bound"
    )]
    Guard,
    /// The library's distribution cannot be built.
    #[error(transparent)]
    Sampling(#[from] SamplingError),
}

/// The last estimation stage's distribution, with the support and the
/// guard's share it explored, if any ([`Planner::next`]).
type CachedEstimation = (Vec<usize>, Option<f64>, Arc<TestDistribution>);

/// The case a planner plans for: borrowed for a campaign run in one
/// call, shared for one a coordinator keeps between reports.
enum Held<'a, C> {
    Borrowed(&'a C),
    Shared(Arc<C>),
}

impl<C> std::ops::Deref for Held<'_, C> {
    type Target = C;
    fn deref(&self) -> &C {
        match self {
            Held::Borrowed(c) => c,
            Held::Shared(c) => c,
        }
    }
}

/// Plans the stages of one adaptive campaign of a grid case.
pub struct Planner<'a, C: Case> {
    case: Held<'a, C>,
    /// The library's cells.
    library_cells: Vec<usize>,
    /// The exposure's alias table, and its cells with exposure: what every
    /// estimation stage draws its exploring tests from
    /// ([`SupportDistribution`]), built once.
    everywhere: Arc<NddDistribution>,
    exposed: usize,
    settings: AdaptiveSettings,
    in_library: Vec<bool>,
    /// The first stage's distribution: the library's, ε-greedy.
    library_stage: Arc<TestDistribution>,
    /// The last estimation stage's support and distribution, reused while
    /// the support is unchanged.
    estimation: std::sync::Mutex<Option<CachedEstimation>>,
    /// What the search walks: the grid, or a coarser lattice of a fine one.
    lattice: Lattice,
    /// The exposure of each lattice block (on a coarser lattice), computed
    /// once: the search's floor reads it at every plan.
    block_masses: std::collections::HashMap<usize, f64>,
}

impl<C: Case> Planner<'static, C> {
    /// [`Planner::new`] holding its case, to be kept between calls.
    pub fn shared(
        case: Arc<C>,
        library: &Library,
        epsilon: f64,
        settings: AdaptiveSettings,
    ) -> Result<Self, AdaptiveError> {
        let Planner {
            library_cells,
            everywhere,
            exposed,
            settings,
            in_library,
            library_stage,
            estimation,
            lattice,
            block_masses,
            ..
        } = Planner::new(case.as_ref(), library, epsilon, settings)?;
        Ok(Planner {
            case: Held::Shared(case),
            library_cells,
            everywhere,
            exposed,
            settings,
            in_library,
            library_stage,
            estimation,
            lattice,
            block_masses,
        })
    }
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
        // A stage holds exactly its share of exploring tests, at
        // 1/explore_every and at the guard's shares (multiples of 1/20), so
        // that its mean is unbiased.
        if !s.stage_tests.is_multiple_of(s.explore_every) || !s.stage_tests.is_multiple_of(20) {
            return Err(AdaptiveError::Settings(format!(
                "stage_tests = {} must be a multiple of explore_every = {} and of 20",
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
        let lattice = if settings.lattice {
            Lattice::of(case.grid())
        } else {
            Lattice::with_stride(case.grid(), 1)
        };
        let mut in_library = vec![false; case.grid().len()];
        for c in &library.cells {
            in_library[c.cell] = true;
        }
        Ok(Self {
            case: Held::Borrowed(case),
            library_cells: {
                let mut cells: Vec<usize> = library.cells.iter().map(|c| c.cell).collect();
                cells.sort_unstable();
                cells
            },
            everywhere: Arc::new(NddDistribution::new(case.exposure())),
            exposed: case.exposure().support_size(),
            settings,
            in_library,
            library_stage,
            estimation: Default::default(),
            block_masses: lattice.block_masses(case.grid(), case.exposure()),
            lattice,
        })
    }

    /// The case planned for.
    pub fn case(&self) -> &C {
        &self.case
    }

    /// Nothing tested yet.
    pub fn knowledge(&self) -> Knowledge {
        let cells = self.case.grid().len();
        Knowledge {
            criticality: vec![None; cells],
            failures: Vec::new(),
            support: self.library_cells.clone(),
            failure_mass: 0.0,
            candidates: Vec::new(),
            is_candidate: vec![false; cells],
            hot: if self.lattice.stride() > 1 {
                vec![false; cells]
            } else {
                Vec::new()
            },
            failed: if self.settings.noisy {
                vec![false; cells]
            } else {
                Vec::new()
            },
        }
    }

    /// Records a test in `knowledge`. A deterministic vehicle's cell gives
    /// the same outcome every time it is run, so only its first test
    /// counts: a failure joins the support, a library cell that passed
    /// leaves it, and a seed (a failure, or a near miss within `near_miss`)
    /// adds its untested neighbours outside the library, with exposure, to
    /// the search's candidates.
    ///
    /// A noisy vehicle's cell fails with a probability, so one run proves
    /// nothing and a near miss is no evidence: its support grows by what
    /// every run shows ([`Self::observe_noisy`]).
    pub fn observe(&self, knowledge: &mut Knowledge, o: &Observation) {
        if self.settings.noisy {
            return self.observe_noisy(knowledge, o);
        }
        if knowledge.criticality[o.cell].is_some() {
            return;
        }
        let criticality = if o.event { 0.0 } else { o.criticality };
        knowledge.criticality[o.cell] = Some(criticality);
        if o.event {
            knowledge.failures.push(o.cell);
            knowledge.failure_mass += self.case.exposure().p(o.cell);
        }
        let at = knowledge.support.binary_search(&o.cell);
        match (o.event, at) {
            (true, Err(k)) => knowledge.support.insert(k, o.cell),
            (false, Ok(k)) => {
                knowledge.support.remove(k);
            }
            _ => {}
        }
        if criticality <= self.settings.near_miss {
            self.seed(knowledge, o.cell);
        }
    }

    /// [`Self::observe`] for a noisy vehicle (docs/statistics.md, "Noisy
    /// vehicles"). Every run counts: the cell keeps its lowest criticality,
    /// and whether a run of it failed. A cell joins the
    /// support the first time a run of it fails, with its neighbours that
    /// have exposure, tested or not (a scenario next to one that fails now
    /// and then fails now and then itself: the evidence of one run, spread
    /// to where it is likely to hold); a library cell stays whatever its
    /// runs gave. Only failures seed the search, each once: a noisy
    /// vehicle's near misses are everywhere its noise reaches, and a
    /// support grown from them holds much exposure that never fails, which
    /// the guard's allocation pays for (the noisy IDM at σ 1.5: support
    /// exposure 0.22 against 0.08, 36,038 tests against 14,862).
    fn observe_noisy(&self, knowledge: &mut Knowledge, o: &Observation) {
        let run = if o.event { 0.0 } else { o.criticality };
        let criticality = knowledge.criticality[o.cell].map_or(run, |b: f64| b.min(run));
        knowledge.criticality[o.cell] = Some(criticality);
        if !o.event || knowledge.failed[o.cell] {
            return;
        }
        knowledge.failed[o.cell] = true;
        let exposure = self.case.exposure();
        knowledge.failures.push(o.cell);
        knowledge.failure_mass += exposure.p(o.cell);
        if self.lattice.stride() == 1 {
            let mut joining: Vec<usize> = std::iter::once(o.cell)
                .chain(self.case.grid().neighbours(o.cell))
                .filter(|&c| exposure.p(c) > 0.0)
                .collect();
            joining.sort_unstable();
            knowledge.support = merged(&knowledge.support, &joining);
        }
        self.seed(knowledge, o.cell);
    }

    /// A seed at `cell`: on the grid its untested neighbours outside the
    /// library, with exposure, join the search's candidates; on a lattice
    /// its block heats ([`Self::heat`]).
    fn seed(&self, knowledge: &mut Knowledge, cell: usize) {
        if self.lattice.stride() > 1 {
            return self.heat(knowledge, cell);
        }
        let exposure = self.case.exposure();
        for n in self.case.grid().neighbours(cell) {
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

    /// A seed on a lattice: its block joins the support (its cells with
    /// exposure, but for those a deterministic vehicle passed), and its
    /// lattice point and the points next to it, untested, are the search's
    /// candidates.
    fn heat(&self, knowledge: &mut Knowledge, cell: usize) {
        let grid = self.case.grid();
        let point = self.lattice.point(grid, cell);
        let next = self.lattice.neighbours(grid, point);
        let exposure = self.case.exposure();
        if !knowledge.hot[point] {
            knowledge.hot[point] = true;
            let joining: Vec<usize> = self
                .lattice
                .block(grid, point)
                .into_iter()
                .filter(|&c| {
                    exposure.p(c) > 0.0
                        && (self.settings.noisy
                            || knowledge.criticality[c].is_none_or(|k| k == 0.0))
                })
                .collect();
            knowledge.support = merged(&knowledge.support, &joining);
        }
        for n in std::iter::once(point).chain(next) {
            if knowledge.criticality[n].is_none() && !knowledge.is_candidate[n] {
                knowledge.is_candidate[n] = true;
                knowledge.candidates.push(n);
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
        self.next_stage(knowledge, None)
    }

    /// [`Self::next`]; a guarded campaign whose estimate is known but whose
    /// outside bound is not yet within β explores the guard's share
    /// (`guarding`, [`AllocationInputs::guard_share`]) of each estimation
    /// stage's tests (docs/statistics.md, "The guard").
    fn next_stage(&self, knowledge: &Knowledge, guarding: Option<f64>) -> Stage {
        let frontier = self.frontier(knowledge);
        if !frontier.is_empty() {
            return Stage::Search(frontier);
        }
        let support = self.support(knowledge);
        let mut cache = self
            .estimation
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        if let Some((cached, late, distribution)) = cache.as_ref() {
            if *cached == support && *late == guarding {
                return Stage::Estimate(Arc::clone(distribution));
            }
        }
        let epsilon = guarding.unwrap_or(1.0 / self.settings.explore_every as f64);
        let distribution = Arc::new(self.estimation(&support, epsilon));
        *cache = Some((support, guarding, Arc::clone(&distribution)));
        Stage::Estimate(distribution)
    }

    /// Untested neighbours outside the library of the seeds, whose exposure
    /// exceeds the floor, in cell order; on a lattice, untested lattice
    /// points next to a seed's block, whose block's exposure exceeds it.
    fn frontier(&self, knowledge: &Knowledge) -> Vec<usize> {
        let exposure = self.case.exposure();
        let floor = self.settings.exposure_floor * knowledge.failure_mass;
        let block_mass = |n: usize| match self.lattice.stride() {
            1 => exposure.p(n),
            _ => self.block_masses.get(&n).copied().unwrap_or(0.0),
        };
        let mut frontier: Vec<usize> = knowledge
            .candidates
            .iter()
            .copied()
            .filter(|&n| knowledge.criticality[n].is_none() && block_mass(n) > floor)
            .collect();
        let width = self.settings.search_width as usize;
        if !frontier.is_empty() && frontier.len() < width {
            // Rings around the frontier, nearest first and each in cell
            // order, until the stage holds `width` cells: what the next
            // searches would test if the frontier failed, tested now by
            // threads that would otherwise wait (`search_width`).
            let mut taken: std::collections::HashSet<usize> = frontier.iter().copied().collect();
            let mut ring = frontier.clone();
            while frontier.len() < width && !ring.is_empty() {
                let mut next: Vec<usize> = Vec::new();
                for &c in &ring {
                    for n in self.lattice.neighbours(self.case.grid(), c) {
                        if knowledge.criticality[n].is_none()
                            && (self.lattice.stride() > 1 || !self.in_library[n])
                            && block_mass(n) > floor
                            && taken.insert(n)
                        {
                            next.push(n);
                        }
                    }
                }
                next.sort_unstable();
                next.truncate(width - frontier.len());
                frontier.extend_from_slice(&next);
                ring = next;
            }
        }
        frontier.sort_unstable();
        frontier
    }

    /// The cells an estimation stage samples besides its exploring share:
    /// the failures found and the library's cells not yet tested (a tested
    /// cell that passed needs no test when the vehicle is deterministic; a
    /// noisy vehicle's library cells all stay).
    pub fn support(&self, knowledge: &Knowledge) -> Vec<usize> {
        knowledge.support.clone()
    }

    /// The support as a library (`V = P`), explored by exposure with share
    /// `epsilon`; the exposure itself when the support is empty.
    fn estimation(&self, support: &[usize], epsilon: f64) -> TestDistribution {
        let exposure = self.case.exposure();
        // The support is increasing ([`Planner::support`]).
        let cells: Vec<usize> = support
            .iter()
            .copied()
            .filter(|&c| exposure.p(c) > 0.0)
            .collect();
        if cells.is_empty() {
            return TestDistribution::Ndd(NddDistribution::clone(&self.everywhere));
        }
        TestDistribution::Support(Box::new(SupportDistribution::new(
            exposure,
            Arc::clone(&self.everywhere),
            self.exposed,
            cells,
            epsilon,
        )))
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
    /// Its exploring tests, which bound the failure mass the support leaves
    /// out (`result.outside_upper`, [`Explored`]).
    pub explored: Explored,
}

/// What one test of a stage gave, in the stage's index order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TestResult {
    /// The vehicle ran the scenario.
    Done {
        /// Whether it had the event.
        event: bool,
        /// How close it came ([`Case::criticality`]); only whether it is
        /// within `near_miss` matters to the plan.
        criticality: f64,
    },
    /// The test has no valid outcome: it teaches nothing and, in an
    /// estimation stage, does not count in `n`.
    Invalid,
}

/// One planned stage: tests `start..start + len`.
#[derive(Debug, Clone)]
pub struct PlannedStage {
    /// Its first test index.
    pub start: u64,
    /// Its tests (fewer than planned when the budget ends inside it).
    pub len: u64,
    /// What it draws.
    pub stage: Stage,
}

impl PlannedStage {
    /// One past its last test index.
    pub fn end(&self) -> u64 {
        self.start + self.len
    }

    /// The cell and weight of test `index` (inside the stage) under `seed`;
    /// a search test's weight is 0: it does not enter the estimate.
    pub fn test(&self, seed: u64, index: u64) -> (usize, f64) {
        match &self.stage {
            Stage::Library(d) | Stage::Estimate(d) => {
                let draw = d.draw(seed, index);
                (draw.cell, draw.weight)
            }
            Stage::Search(cells) => (cells[(index - self.start) as usize], 0.0),
        }
    }

    /// `"library"`, `"search"` or `"estimate"`.
    pub fn kind(&self) -> &'static str {
        self.stage.kind()
    }
}

/// Where an adaptive campaign stands: the stages planned so far (the last
/// is the one running), what their tests showed, and the estimate. It is a
/// function of the seed and the results of the resolved stages alone, so a
/// coordinator rebuilds it from what it stored, and
/// [`run_adaptive`] and a service campaign walk through the same states.
#[derive(Debug, Clone)]
pub struct AdaptiveState {
    seed: u64,
    knowledge: Knowledge,
    fold: PrefixFold,
    spent: Spent,
    explored: Explored,
    /// A guarded campaign whose estimate met the rule while its outside
    /// bound did not meet the guard: the share of their tests its
    /// estimation stages explore from then on ([`AllocationInputs`]).
    guarding: Option<f64>,
    stages: Vec<PlannedStage>,
    finished: Option<AdaptiveResult>,
}

impl AdaptiveState {
    /// The stage running (the last planned).
    pub fn current(&self) -> &PlannedStage {
        self.stages.last().expect("a campaign starts with a stage")
    }

    /// Every stage planned, in order.
    pub fn stages(&self) -> &[PlannedStage] {
        &self.stages
    }

    /// The stage test `index` belongs to, if planned.
    pub fn stage_of(&self, index: u64) -> Option<&PlannedStage> {
        let k = self.stages.partition_point(|s| s.end() <= index);
        self.stages.get(k).filter(|s| s.start <= index)
    }

    /// The seed of the test streams.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The estimation tests' fold.
    pub fn fold(&self) -> &PrefixFold {
        &self.fold
    }

    /// The result, once the campaign stopped.
    pub fn finished(&self) -> Option<&AdaptiveResult> {
        self.finished.as_ref()
    }

    /// What the tests showed.
    pub fn knowledge(&self) -> &Knowledge {
        &self.knowledge
    }

    /// The estimation stages' exploring tests so far.
    pub fn explored(&self) -> Explored {
        self.explored
    }

    /// Tests of the library stage, of the searches, and stages resolved.
    pub fn spent(&self) -> (u64, u64, u64) {
        let s = &self.spent;
        (s.library_tests, s.search_tests, s.stages)
    }
}

/// What the guard's allocation reads off the estimation tests since the
/// last restart, for stages drawn as `distribution` is.
fn allocation_inputs(
    state: &AdaptiveState,
    distribution: &TestDistribution,
    rule: &StoppingRule,
) -> AllocationInputs {
    let n = state.fold.estimator.tests().max(1) as f64;
    AllocationInputs {
        estimate: state.fold.estimate(),
        outside_estimate: state.explored.tally.s1 / n,
        outside_mass: outside::exposure_off_support(distribution),
        beta: rule.beta,
        z: rule.z(),
        confidence: rule.confidence,
    }
}

impl<C: Case> Planner<'_, C> {
    /// A campaign under `seed` before any test: its library stage planned.
    pub fn start(&self, rule: &StoppingRule, seed: u64) -> AdaptiveState {
        let stage = self.first();
        let len = self.len(&stage).min(rule.max_tests);
        AdaptiveState {
            seed,
            knowledge: self.knowledge(),
            fold: PrefixFold::default(),
            spent: Spent::default(),
            explored: Explored::default(),
            guarding: None,
            stages: vec![PlannedStage {
                start: 0,
                len,
                stage,
            }],
            finished: None,
        }
    }

    /// Resolves the running stage with its tests' `results` (in index
    /// order, one per test): an estimation stage's events enter the
    /// estimate, whose rule may stop the campaign inside the stage (at the
    /// index where the rule first holds, as for any campaign); otherwise
    /// the next stage is planned, unless the budget is spent. Returns what
    /// the stage did.
    ///
    /// # Panics
    /// When the campaign has finished or `results` is not one per test.
    pub fn resolve(
        &self,
        state: &mut AdaptiveState,
        rule: &StoppingRule,
        results: &[TestResult],
    ) -> StageRecord {
        assert!(state.finished.is_none(), "the campaign has finished");
        let planned = state.current().clone();
        assert_eq!(results.len() as u64, planned.len, "one result per test");
        let seed = state.seed;
        state.spent.stages += 1;
        let failures_before = state.knowledge.failures.len();
        let observations: Vec<Option<Observation>> = results
            .iter()
            .enumerate()
            .map(|(k, r)| match *r {
                TestResult::Done { event, criticality } => Some(Observation {
                    cell: planned.test(seed, planned.start + k as u64).0,
                    event,
                    criticality,
                }),
                TestResult::Invalid => None,
            })
            .collect();
        let mut course = record::Course::new(planned.start, state.fold.indices);
        let mut restarts = false;
        match &planned.stage {
            Stage::Library(_) => state.spent.library_tests += planned.len,
            Stage::Search(_) => state.spent.search_tests += planned.len,
            Stage::Estimate(distribution) => {
                let to = state.fold.indices + planned.len;
                let outcomes = estimation_outcomes(&planned, seed, state.fold.indices, results);
                // A guarded campaign stops only at a stage's end, where both
                // its rule and its guard are read: its fold runs the whole
                // stage.
                let fold_rule = StoppingRule {
                    n_min: if rule.guard_outside {
                        u64::MAX
                    } else {
                        rule.n_min
                    },
                    ..*rule
                };
                let stopped = fold_estimation_stage_observed(
                    &mut state.fold,
                    &fold_rule,
                    (planned.end(), to),
                    &outcomes,
                    &mut |f| course.keep(f),
                );
                course.keep(&state.fold);
                let used = stopped.map_or(planned.end(), |(_, used)| used);
                for (k, r) in results[..(used - planned.start) as usize]
                    .iter()
                    .enumerate()
                {
                    if let TestResult::Done { event, .. } = *r {
                        let index = planned.start + k as u64;
                        state.explored.test(distribution, seed, index, event);
                    }
                }
                let stopped = match stopped {
                    Some(stop) => Some(stop),
                    None if rule.guard_outside && state.fold.converged(rule, rule.z()) => {
                        if state.explored.guard_holds(&state.fold, rule) {
                            Some((Decision::Converged, planned.end()))
                        } else {
                            if state.guarding.is_none() {
                                // The guard's stages explore another share:
                                // the estimate and its bound start again
                                // with them, so that every stage they read
                                // explores alike (the bound's argument,
                                // `outside.rs`). A restart decided at a
                                // stage's end keeps the estimate unbiased,
                                // and the share, read off the tests before
                                // it, is fixed by the past.
                                let inputs = allocation_inputs(state, distribution, rule);
                                state.guarding = Some(inputs.guard_share());
                                state.fold = PrefixFold::default();
                                state.explored = Explored::default();
                                restarts = true;
                            }
                            None
                        }
                    }
                    None => None,
                };
                if let Some((status, used)) = stopped {
                    let support = self.support(&state.knowledge);
                    let mut record = counted(planned.kind(), planned.start, used, results);
                    record.support = support.len() as u64;
                    record.course = course.points;
                    state.finished = Some(state.spent.result(
                        status,
                        (&state.fold, state.explored),
                        rule,
                        used,
                        support,
                    ));
                    return record;
                }
            }
        }
        for o in observations.iter().flatten() {
            self.observe(&mut state.knowledge, o);
        }
        let mut record = counted(planned.kind(), planned.start, planned.end(), results);
        record.new_failures = (state.knowledge.failures.len() - failures_before) as u64;
        record.support = state.knowledge.support.len() as u64;
        record.restarts_estimate = restarts;
        record.course = course.points;
        if planned.end() >= rule.max_tests {
            let support = self.support(&state.knowledge);
            state.finished = Some(state.spent.result(
                Decision::Exhausted,
                (&state.fold, state.explored),
                rule,
                planned.end(),
                support,
            ));
            return record;
        }
        let stage = self.next_stage(&state.knowledge, state.guarding);
        let len = self.len(&stage).min(rule.max_tests - planned.end());
        state.stages.push(PlannedStage {
            start: planned.end(),
            len,
            stage,
        });
        record
    }
}

impl<C: Case> Planner<'_, C> {
    /// Whether the running stage is an estimation stage whose rule holds
    /// within its first `results.len()` tests. The fold is sequential, so
    /// [`Self::resolve`] then stops the campaign at the same index whatever
    /// the stage's later tests give (it folds no further, and plans
    /// nothing): a coordinator may resolve the stage at once with any
    /// results after them, and its workers need not run them.
    pub fn stops_within(
        &self,
        state: &AdaptiveState,
        rule: &StoppingRule,
        results: &[TestResult],
    ) -> bool {
        let planned = state.current();
        // A guarded campaign reads its guard at a stage's end only.
        if state.finished.is_some()
            || rule.guard_outside
            || !matches!(planned.stage, Stage::Estimate(_))
            || results.len() as u64 > planned.len
        {
            return false;
        }
        let mut fold = state.fold;
        let to = fold.indices + results.len() as u64;
        let outcomes = estimation_outcomes(planned, state.seed, fold.indices, results);
        fold_estimation_stage(&mut fold, rule, planned.end(), to, &outcomes).is_some()
    }
}

/// The record of a stage's tests `start..end` of kind `kind`, counted from
/// their `results` (the stage's, from `start`; those after `end` unused).
fn counted(kind: &'static str, start: u64, end: u64, results: &[TestResult]) -> StageRecord {
    let used = &results[..(end - start) as usize];
    let count = |f: fn(&TestResult) -> bool| used.iter().filter(|r| f(r)).count() as u64;
    StageRecord {
        kind,
        start,
        end,
        events: count(|r| matches!(r, TestResult::Done { event: true, .. })),
        new_failures: 0,
        invalid: count(|r| matches!(r, TestResult::Invalid)),
        support: 0,
        restarts_estimate: false,
        course: Vec::new(),
    }
}

/// The sparse outcomes of an estimation stage's first `results.len()`
/// tests, at estimation indices from `from`: events with their weights,
/// and invalid tests.
fn estimation_outcomes(
    planned: &PlannedStage,
    seed: u64,
    from: u64,
    results: &[TestResult],
) -> Vec<(u64, SparseOutcome)> {
    results
        .iter()
        .enumerate()
        .filter_map(|(k, r)| {
            let i = from + k as u64;
            match r {
                TestResult::Done { event: true, .. } => Some((
                    i,
                    SparseOutcome::Event(planned.test(seed, planned.start + k as u64).1),
                )),
                TestResult::Done { .. } => None,
                TestResult::Invalid => Some((i, SparseOutcome::Invalid)),
            }
        })
        .collect()
}

/// Folds an estimation stage's `outcomes` (estimation indices up to `to`)
/// into `fold` under `rule`, whose budget counts every test and so is not
/// the estimation tests' (they stop only by the rule). When the rule holds
/// inside the stage, the decision and the campaign's indices used: the
/// stage's end (`stage_end`) less the tests after the stop.
pub(crate) fn fold_estimation_stage(
    fold: &mut PrefixFold,
    rule: &StoppingRule,
    stage_end: u64,
    to: u64,
    outcomes: &[(u64, SparseOutcome)],
) -> Option<(Decision, u64)> {
    fold_estimation_stage_observed(fold, rule, (stage_end, to), outcomes, &mut |_| {})
}

/// [`fold_estimation_stage`], showing `observe` the fold on both sides of
/// each outcome ([`PrefixFold::advance_observed`]).
fn fold_estimation_stage_observed(
    fold: &mut PrefixFold,
    rule: &StoppingRule,
    (stage_end, to): (u64, u64),
    outcomes: &[(u64, SparseOutcome)],
    observe: &mut dyn FnMut(&PrefixFold),
) -> Option<(Decision, u64)> {
    let estimation_rule = StoppingRule {
        max_tests: u64::MAX,
        ..*rule
    };
    let decided = fold
        .advance_observed(&estimation_rule, rule.z(), to, outcomes, None, observe)
        .expect("bounded weights in index order");
    decided.map(|status| (status, stage_end - (to - fold.indices)))
}

/// Runs an adaptive campaign of built-in `vehicle` on `library` to `rule`.
/// Tests run in parallel within a stage and are resolved in index order,
/// so the result does not depend on the number of threads.
pub fn run_adaptive<C: Case>(
    case: &C,
    vehicle: &C::Vehicle,
    library: &Library,
    epsilon: f64,
    settings: AdaptiveSettings,
    rule: &StoppingRule,
    seed: u64,
) -> Result<AdaptiveResult, AdaptiveError> {
    let settings = AdaptiveSettings {
        noisy: settings.noisy || case.is_noisy(vehicle),
        ..settings
    };
    let planner = Planner::new(case, library, epsilon, settings)?;
    let mut state = planner.start(rule, seed);
    loop {
        if let Some(result) = state.finished() {
            return Ok(result.clone());
        }
        let stage = state.current();
        let results: Vec<TestResult> = (stage.start..stage.end())
            .into_par_iter()
            .map(|i| {
                let (event, criticality) = case.test_run(vehicle, stage.test(seed, i).0, seed, i);
                TestResult::Done { event, criticality }
            })
            .collect();
        planner.resolve(&mut state, rule, &results);
    }
}

/// The tests an adaptive campaign spent outside its estimate.
#[derive(Debug, Clone, Default)]
struct Spent {
    library_tests: u64,
    search_tests: u64,
    stages: u64,
}

impl Spent {
    /// The campaign's result after `indices` tests in all, the estimate
    /// being `fold`'s.
    fn result(
        &self,
        status: Decision,
        (fold, explored): (&PrefixFold, Explored),
        rule: &StoppingRule,
        indices: u64,
        support: Vec<usize>,
    ) -> AdaptiveResult {
        let mut result = CampaignResult::with_outside_upper(
            status,
            &explored.on(fold),
            rule.z(),
            Some(explored.upper(rule.confidence)),
        );
        result.indices = indices;
        AdaptiveResult {
            result,
            library_tests: self.library_tests,
            search_tests: self.search_tests,
            stages: self.stages,
            support,
            explored,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cases::cutin::{CutIn, CutInPreset};
    use crate::library::{build_library, LibraryRequest, SearchMethod, Threshold};
    use crate::vehicle::VehicleModel;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The IDM's exhaustive library on `case`.
    fn idm_library(case: &CutIn) -> Library {
        let idm = VehicleModel::builtin("idm").unwrap();
        let request = LibraryRequest {
            threshold: Threshold::default(),
            search: SearchMethod::Exhaustive,
        };
        let spec = serde_json::to_value(idm).unwrap();
        build_library(case, &idm, spec, "paper-code", &request)
    }

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
    fn the_kept_frontier_and_support_are_the_scanned_ones_after_every_observation() {
        let case = CutIn::builtin(CutInPreset::PaperCode);
        let library = idm_library(&case);
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
                // The merged support is the sorted union.
                let mut union: Vec<usize> = knowledge
                    .failures()
                    .iter()
                    .copied()
                    .chain(
                        library
                            .cells
                            .iter()
                            .map(|c| c.cell)
                            .filter(|&c| knowledge.criticality[c].is_none()),
                    )
                    .collect();
                union.sort_unstable();
                union.dedup();
                assert_eq!(planner.support(&knowledge), union);
            }
            assert!(!knowledge.failures().is_empty());
        }
    }

    /// The widened frontier by distances: the one-ring frontier at 0, then
    /// cells reached through untested, searchable cells at 1, 2, …, taken
    /// by distance then cell until `width`.
    fn widened_by_distance<C: Case>(
        planner: &Planner<'_, C>,
        knowledge: &Knowledge,
        width: usize,
    ) -> Vec<usize> {
        let narrow = frontier_by_scan(planner, knowledge);
        if narrow.is_empty() || narrow.len() >= width {
            return narrow;
        }
        let exposure = planner.case.exposure();
        let found: f64 = knowledge.failures.iter().map(|&c| exposure.p(c)).sum();
        let floor = planner.settings.exposure_floor * found;
        let grid = planner.case.grid();
        let mut distance: Vec<Option<usize>> = vec![None; grid.len()];
        let mut queue = std::collections::VecDeque::new();
        for &c in &narrow {
            distance[c] = Some(0);
            queue.push_back(c);
        }
        while let Some(c) = queue.pop_front() {
            for n in grid.neighbours(c) {
                if distance[n].is_none()
                    && knowledge.criticality[n].is_none()
                    && !planner.in_library[n]
                    && exposure.p(n) > floor
                {
                    distance[n] = Some(distance[c].unwrap() + 1);
                    queue.push_back(n);
                }
            }
        }
        let mut reached: Vec<(usize, usize)> = (0..grid.len())
            .filter_map(|c| distance[c].map(|d| (d, c)))
            .collect();
        reached.sort_unstable();
        let mut cells: Vec<usize> = reached.into_iter().take(width).map(|(_, c)| c).collect();
        cells.sort_unstable();
        cells
    }

    #[test]
    fn a_widened_search_takes_the_nearest_rings_around_the_frontier_up_to_its_width() {
        let case = CutIn::builtin(CutInPreset::PaperCode);
        let library = idm_library(&case);
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut widened_somewhere = 0;
        for width in [0, 1, 7, 40, 128] {
            let settings = AdaptiveSettings {
                search_width: width,
                ..AdaptiveSettings::default()
            };
            let planner = Planner::new(&case, &library, 0.1, settings).unwrap();
            let mut knowledge = planner.knowledge();
            for _ in 0..300 {
                let cell = rng.random_range(0..case.grid().len());
                let o = Observation {
                    cell,
                    event: rng.random::<f64>() < 0.3,
                    criticality: rng.random::<f64>() * 0.3,
                };
                planner.observe(&mut knowledge, &o);
                let narrow = frontier_by_scan(&planner, &knowledge);
                let widened = planner.frontier(&knowledge);
                assert_eq!(
                    widened,
                    widened_by_distance(&planner, &knowledge, width as usize)
                );
                assert!(narrow.iter().all(|c| widened.binary_search(c).is_ok()));
                if widened.len() > narrow.len() {
                    widened_somewhere += 1;
                    assert!(widened.len() <= width as usize);
                }
            }
        }
        assert!(widened_somewhere > 50, "widened {widened_somewhere} times");
    }
}
