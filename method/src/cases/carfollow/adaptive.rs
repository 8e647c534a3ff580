//! Adaptive campaigns on car-following (issue 21, docs/adaptive-design.md):
//! the policy's Q-values learned toward the vehicle under test.
//!
//! A car-following library is the surrogate's `Q(s, u) = P(u|s) P(S|T(s, u))`
//! over grid states, computed by dynamic programming from the surrogate's
//! one-decision transitions `T` ([`super::library`]). The best library for
//! a vehicle is the same computation on the vehicle's own transitions: on
//! the risky preset the ACC+AEB with a 0.3 s actuator lag, which the IDM's
//! library covers at 0.72, covers at 0.87–0.93 with its own
//! (`method/benches/carfollow_adaptive.rs`). Learning those transitions
//! from the tests' trajectories alone does not get there (0.75): the tests
//! rarely pass the states where the two models part. So the campaign
//! *probes* the vehicle, as the grid cases' search tests cells:
//!
//! 1. **Library**: the first `library_tests` tests are drawn from the
//!    surrogate's library, as a library campaign's are.
//! 2. **Probes**: every grid state that a test ending in an accident passed
//!    through (its nearest grid state at each decision) is *probed*: the
//!    vehicle is run from it, braking hard for the zone ([`Zone`]) and
//!    one decision under each of the 31 actions, and its transitions
//!    replace the surrogate's there. A probed state that is dangerous for
//!    the vehicle and where the vehicle's zone or transitions differ from
//!    the surrogate's passes the probe on to its 26 neighbours in (v, R,
//!    Ṙ); a stage probes one layer, until no state is left. The flood thus
//!    covers the region where the vehicle is dangerous and unlike the
//!    surrogate, connected to the accidents the tests met; where the two
//!    agree it stops at once (the surrogate itself costs a few hundred
//!    probes).
//! 3. **Estimation**: the learned transitions give a library by dynamic
//!    programming, sampled as a library campaign samples (ε-greedy in every
//!    decision), `stage_tests` tests a stage. Each test is weighted by its
//!    own stage's policy, so each term is unbiased given the stages before
//!    it and the estimate is a martingale average; the stopping rule holds
//!    on the estimation tests. An estimation test ending in an accident
//!    through states not yet probed sends the campaign back to step 2.
//!
//! Every stage is planned from the seed and the results of the stages
//! before it alone, so the campaign is the same on any number of threads.
//! Only estimation tests enter the estimate; library tests and probes are
//! the cost of learning the vehicle. A probe costs at most `decisions + 31`
//! one-second decisions of the vehicle (a 30-decision test's 30), counted
//! in [`FollowAdaptiveResult::probe_decisions`].

use super::library::{dynamic_programming, Next, PolicyLibrary, Transitions, Zone};
use super::states::StateGrid;
use super::world::{advance_with, FollowWorld, Odometer};
use super::{CarFollowing, FollowDecision, FollowSampler, FollowTest};
use crate::adaptive::{fold_estimation_stage, AdaptiveError};
use crate::campaign::CampaignResult;
use crate::cases::carfollow::case::DP_TOLERANCE;
use crate::estimator::{Decision, StoppingRule};
use crate::prefix::{PrefixFold, SparseOutcome};
use crate::sampling::OutsideSpread;
use crate::vehicle::{FollowDriver, VehicleModel};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// How a car-following adaptive campaign learns and samples.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FollowAdaptiveSettings {
    /// Tests of the first stage, drawn from the surrogate's library.
    pub library_tests: u64,
    /// Tests of an estimation stage.
    pub stage_tests: u64,
}

impl Default for FollowAdaptiveSettings {
    /// 100 and 100: stages of 50 and 300 measured the same
    /// (docs/adaptive-design.md).
    fn default() -> Self {
        Self {
            library_tests: 100,
            stage_tests: 100,
        }
    }
}

/// What probing the vehicle from one grid state found.
#[derive(Debug, Clone, PartialEq)]
pub struct Probe {
    /// The state's zone for the vehicle.
    pub zone: Zone,
    /// Where each action leads, for a dangerous state (else empty).
    pub next: Vec<Next>,
    /// The vehicle's decisions the probe ran.
    pub decisions: u64,
}

/// Runs the vehicle from grid state `s`: hard braking for up to
/// `decisions` decisions (its zone), then, if an accident can follow, one
/// decision under each action; `driver` gives a fresh vehicle per run.
pub fn probe_with<D: FollowDriver>(
    world: &FollowWorld,
    grid: &StateGrid,
    s: usize,
    mut driver: impl FnMut() -> D,
) -> Result<Probe, D::Error> {
    let start = grid.state(s);
    let mut decisions = 0u64;
    let zone = if start.range <= world.accident_range {
        Zone::Collision
    } else {
        let mut vut = driver();
        let mut odometer = Odometer::default();
        let mut x = start;
        let mut zone = Zone::Safe;
        for _ in 0..world.decisions {
            decisions += 1;
            match advance_with(world, x, world.u_min, &mut vut, &mut odometer)? {
                None => {
                    zone = Zone::Dangerous;
                    break;
                }
                Some(next) => x = next,
            }
        }
        zone
    };
    let mut next = Vec::new();
    if zone == Zone::Dangerous {
        for k in 0..world.actions {
            decisions += 1;
            let mut vut = driver();
            let to = advance_with(
                world,
                start,
                world.action(k),
                &mut vut,
                &mut Odometer::default(),
            )?;
            next.push(match to {
                None => Next::Accident,
                Some(x) => grid.nearest(&x).map_or(Next::Free, Next::State),
            });
        }
    }
    Ok(Probe {
        zone,
        next,
        decisions,
    })
}

/// A built-in vehicle's [`probe_with`].
pub fn probe(world: &FollowWorld, grid: &StateGrid, vehicle: &VehicleModel, s: usize) -> Probe {
    let Ok(p) = probe_with(world, grid, s, || vehicle.controller());
    p
}

/// What one test of a stage gave, in the stage's index order.
#[derive(Debug, Clone, PartialEq)]
pub enum FollowTestResult {
    /// A test of a library or estimation stage.
    Test {
        /// Whether it ended in an accident.
        accident: bool,
        /// Its importance weight under its stage's policy.
        weight: f64,
        /// The nearest grid state of each decision, for an accident (the
        /// probes' seeds); empty otherwise.
        states: Vec<usize>,
    },
    /// A probe of a probe stage.
    Probe(Probe),
    /// No valid outcome: it teaches nothing and does not count in `n`.
    Invalid,
}

impl FollowTestResult {
    /// A test's result from its decisions.
    pub fn from_trace(grid: &StateGrid, test: &FollowTest, trace: &[FollowDecision]) -> Self {
        let states = if test.accident {
            trace.iter().filter_map(|d| grid.nearest(&d.from)).collect()
        } else {
            Vec::new()
        };
        FollowTestResult::Test {
            accident: test.accident,
            weight: test.weight(),
            states,
        }
    }
}

/// One stage's plan.
#[derive(Debug, Clone)]
pub enum FollowStage {
    /// Tests from the surrogate's library.
    Library(Arc<FollowSampler>),
    /// The grid states to probe, one per index, increasing.
    Probe(Arc<Vec<usize>>),
    /// Tests from the learned library.
    Estimate(Arc<FollowSampler>),
}

/// One planned stage: indices `start..start + len`.
#[derive(Debug, Clone)]
pub struct FollowPlannedStage {
    /// Its first index.
    pub start: u64,
    /// Its indices (fewer than planned when the budget ends inside it).
    pub len: u64,
    /// What it runs.
    pub stage: FollowStage,
}

impl FollowPlannedStage {
    /// One past its last index.
    pub fn end(&self) -> u64 {
        self.start + self.len
    }

    /// `"library"`, `"probe"` or `"estimate"`.
    pub fn kind(&self) -> &'static str {
        match self.stage {
            FollowStage::Library(_) => "library",
            FollowStage::Probe(_) => "probe",
            FollowStage::Estimate(_) => "estimate",
        }
    }
}

/// What a car-following adaptive campaign did.
#[derive(Debug, Clone, PartialEq)]
pub struct FollowAdaptiveResult {
    /// The estimate over the estimation tests; `indices` counts every
    /// index (tests and probes).
    pub result: CampaignResult,
    /// Tests of the library stage.
    pub library_tests: u64,
    /// Grid states probed.
    pub probes: u64,
    /// The vehicle's decisions the probes ran.
    pub probe_decisions: u64,
    /// Stages run.
    pub stages: u64,
    /// Probed states dangerous for the vehicle.
    pub dangerous_probed: u64,
}

impl FollowAdaptiveResult {
    /// The vehicle's driving spent, in tests of `decisions` decisions:
    /// library and estimation tests plus the probes' decisions.
    pub fn test_equivalents(&self, decisions: usize) -> f64 {
        (self.result.indices - self.probes) as f64 + self.probe_decisions as f64 / decisions as f64
    }
}

/// Plans the stages of car-following adaptive campaigns of one library.
pub struct FollowPlanner {
    case: Arc<CarFollowing>,
    epsilon: f64,
    outside: OutsideSpread,
    settings: FollowAdaptiveSettings,
    /// The surrogate's transitions, which the probes overwrite.
    surrogate: Arc<Transitions>,
    library_stage: Arc<FollowSampler>,
}

impl FollowPlanner {
    /// The planner of campaigns on `library`, the policy of `surrogate`
    /// (whose transitions it computes once), explored with share `epsilon`
    /// spread by `outside`.
    pub fn new(
        case: Arc<CarFollowing>,
        surrogate: &VehicleModel,
        library: Arc<PolicyLibrary>,
        epsilon: f64,
        outside: OutsideSpread,
        settings: FollowAdaptiveSettings,
    ) -> Result<Self, AdaptiveError> {
        if settings.library_tests == 0 || settings.stage_tests == 0 {
            return Err(AdaptiveError::Settings(
                "library_tests and stage_tests must be positive".into(),
            ));
        }
        let library_stage = Arc::new(FollowSampler::library(
            case.world,
            case.grid,
            &case.exposure,
            library,
            epsilon,
            outside,
        )?);
        let surrogate = Arc::new(Transitions::compute(
            &case.world,
            case.grid,
            &case.exposure,
            surrogate,
        ));
        Ok(Self {
            case,
            epsilon,
            outside,
            settings,
            surrogate,
            library_stage,
        })
    }

    /// The case.
    pub fn case(&self) -> &CarFollowing {
        &self.case
    }

    /// A campaign under `seed` before any test: its library stage planned.
    pub fn start(&self, rule: &StoppingRule, seed: u64) -> FollowAdaptiveState {
        let states = self.case.grid.len();
        FollowAdaptiveState {
            seed,
            model: Transitions::clone(&self.surrogate),
            probed: vec![false; states],
            pending: Vec::new(),
            changed: false,
            sampler: Arc::clone(&self.library_stage),
            fold: PrefixFold::default(),
            library_tests: 0,
            probes: 0,
            probe_decisions: 0,
            dangerous_probed: 0,
            resolved: 0,
            stages: vec![FollowPlannedStage {
                start: 0,
                len: self.settings.library_tests.min(rule.max_tests),
                stage: FollowStage::Library(Arc::clone(&self.library_stage)),
            }],
            finished: None,
        }
    }

    /// Resolves the running stage with its `results` (in index order, one
    /// per index) and plans the next, unless the campaign stopped.
    ///
    /// # Panics
    /// When the campaign has finished, `results` is not one per index, or
    /// a result is not of the stage's kind.
    pub fn resolve(
        &self,
        state: &mut FollowAdaptiveState,
        rule: &StoppingRule,
        results: &[FollowTestResult],
    ) {
        assert!(state.finished.is_none(), "the campaign has finished");
        let planned = state.current().clone();
        assert_eq!(results.len() as u64, planned.len, "one result per index");
        state.resolved += 1;
        match &planned.stage {
            FollowStage::Library(_) => {
                state.library_tests += planned.len;
                state.seed_from(results);
            }
            FollowStage::Probe(cells) => {
                for (&s, r) in cells.iter().zip(results) {
                    match r {
                        FollowTestResult::Probe(p) => state.apply(&self.surrogate, s, p),
                        FollowTestResult::Invalid => {}
                        FollowTestResult::Test { .. } => panic!("a probe stage's result"),
                    }
                }
                state.probes += planned.len;
            }
            FollowStage::Estimate(_) => {
                let from = state.fold.indices;
                let to = from + planned.len;
                let outcomes: Vec<(u64, SparseOutcome)> = results
                    .iter()
                    .enumerate()
                    .filter_map(|(k, r)| {
                        let i = from + k as u64;
                        match r {
                            FollowTestResult::Test {
                                accident: true,
                                weight,
                                ..
                            } => Some((i, SparseOutcome::Event(*weight))),
                            FollowTestResult::Test { .. } => None,
                            FollowTestResult::Invalid => Some((i, SparseOutcome::Invalid)),
                            FollowTestResult::Probe(_) => panic!("an estimation stage's result"),
                        }
                    })
                    .collect();
                if let Some((status, used)) =
                    fold_estimation_stage(&mut state.fold, rule, planned.end(), to, &outcomes)
                {
                    state.finish(status, rule, used);
                    return;
                }
                state.seed_from(results);
            }
        }
        if planned.end() >= rule.max_tests {
            state.finish(Decision::Exhausted, rule, planned.end());
            return;
        }
        let stage = self.next(state);
        let len = match &stage {
            FollowStage::Probe(cells) => cells.len() as u64,
            _ => self.settings.stage_tests,
        }
        .min(rule.max_tests - planned.end());
        state.stages.push(FollowPlannedStage {
            start: planned.end(),
            len,
            stage,
        });
    }

    /// The next stage: the pending probes, else an estimation stage from
    /// the transitions learned so far.
    fn next(&self, state: &mut FollowAdaptiveState) -> FollowStage {
        let mut pending = std::mem::take(&mut state.pending);
        pending.sort_unstable();
        pending.dedup();
        pending.retain(|&s| !state.probed[s]);
        if !pending.is_empty() {
            return FollowStage::Probe(Arc::new(pending));
        }
        if state.changed {
            state.changed = false;
            let learned = Arc::new(dynamic_programming(&state.model, DP_TOLERANCE));
            // A vehicle with no accident anywhere the probes reached keeps
            // the policy it had.
            if let Ok(sampler) = FollowSampler::library(
                self.case.world,
                self.case.grid,
                &self.case.exposure,
                learned,
                self.epsilon,
                self.outside,
            ) {
                state.sampler = Arc::new(sampler);
            }
        }
        FollowStage::Estimate(Arc::clone(&state.sampler))
    }
}

/// Where a car-following adaptive campaign stands: a function of the seed
/// and the results of the resolved stages alone.
#[derive(Debug, Clone)]
pub struct FollowAdaptiveState {
    seed: u64,
    /// The surrogate's transitions with the probed states' replaced.
    model: Transitions,
    probed: Vec<bool>,
    /// States to probe next.
    pending: Vec<usize>,
    /// Whether probes changed the model since the last policy.
    changed: bool,
    /// The policy of the estimation stages.
    sampler: Arc<FollowSampler>,
    fold: PrefixFold,
    library_tests: u64,
    probes: u64,
    probe_decisions: u64,
    dangerous_probed: u64,
    resolved: u64,
    stages: Vec<FollowPlannedStage>,
    finished: Option<FollowAdaptiveResult>,
}

impl FollowAdaptiveState {
    /// The stage running (the last planned).
    pub fn current(&self) -> &FollowPlannedStage {
        self.stages.last().expect("a campaign starts with a stage")
    }

    /// The stage index `index` belongs to, if planned.
    pub fn stage_of(&self, index: u64) -> Option<&FollowPlannedStage> {
        let k = self.stages.partition_point(|s| s.end() <= index);
        self.stages.get(k).filter(|s| s.start <= index)
    }

    /// The seed of the test streams.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The result, once the campaign stopped.
    pub fn finished(&self) -> Option<&FollowAdaptiveResult> {
        self.finished.as_ref()
    }

    /// The estimation tests' fold.
    pub fn fold(&self) -> &PrefixFold {
        &self.fold
    }

    /// The states an accident passed through, not yet probed, join the
    /// probes to come.
    fn seed_from(&mut self, results: &[FollowTestResult]) {
        for r in results {
            if let FollowTestResult::Test {
                accident: true,
                states,
                ..
            } = r
            {
                self.pending
                    .extend(states.iter().copied().filter(|&s| !self.probed[s]));
            }
        }
    }

    /// Puts probe `p` of state `s` into the model; a dangerous state where
    /// the vehicle differs from `surrogate` passes the probe on to its
    /// neighbours.
    fn apply(&mut self, surrogate: &Transitions, s: usize, p: &Probe) {
        self.probed[s] = true;
        self.probe_decisions += p.decisions;
        let actions = self.model.actions;
        let row = s * actions..(s + 1) * actions;
        let differs = surrogate.zones[s] != p.zone
            || (p.zone == Zone::Dangerous && surrogate.next[row.clone()] != p.next[..]);
        self.model.zones[s] = p.zone;
        if p.zone == Zone::Dangerous {
            self.model.next[row].copy_from_slice(&p.next);
            self.dangerous_probed += 1;
        } else {
            self.model.next[row].fill(Next::Free);
        }
        self.changed |= differs;
        if differs && p.zone == Zone::Dangerous {
            let grid = self.model.grid;
            self.pending
                .extend(neighbours(&grid, s).filter(|&n| !self.probed[n]));
        }
    }

    fn finish(&mut self, status: Decision, rule: &StoppingRule, indices: u64) {
        let mut result = CampaignResult::from_fold(status, &self.fold, rule, None);
        result.indices = indices;
        self.finished = Some(FollowAdaptiveResult {
            result,
            library_tests: self.library_tests,
            probes: self.probes,
            probe_decisions: self.probe_decisions,
            stages: self.resolved,
            dangerous_probed: self.dangerous_probed,
        });
    }
}

/// The up to 26 grid neighbours of state `s` in (v, R, Ṙ).
fn neighbours(grid: &StateGrid, s: usize) -> impl Iterator<Item = usize> + '_ {
    let (nv, nr, nrr) = (grid.speed.1, grid.range.1, grid.range_rate.1);
    let (iv, ir, irr) = (s / (nrr * nr), (s / nrr) % nr, s % nrr);
    let around = |i: usize, n: usize| i.saturating_sub(1)..=(i + 1).min(n - 1);
    around(iv, nv).flat_map(move |v| {
        around(ir, nr).flat_map(move |r| {
            around(irr, nrr)
                .map(move |rr| grid.index(v, r, rr))
                .filter(move |&n| n != s)
        })
    })
}

/// Runs a car-following adaptive campaign of built-in `vut` on `library`
/// (the policy of `surrogate`) to `rule`; the stages' tests and probes run
/// in parallel and are resolved in index order, so the result does not
/// depend on the number of threads.
pub fn run_follow_adaptive(
    planner: &FollowPlanner,
    vut: &VehicleModel,
    rule: &StoppingRule,
    seed: u64,
) -> Result<FollowAdaptiveResult, AdaptiveError> {
    if rule.guard_outside {
        return Err(AdaptiveError::Guard);
    }
    let case = planner.case();
    let mut state = planner.start(rule, seed);
    loop {
        if let Some(result) = state.finished() {
            return Ok(result.clone());
        }
        let stage = state.current().clone();
        let results: Vec<FollowTestResult> = match &stage.stage {
            FollowStage::Library(sampler) | FollowStage::Estimate(sampler) => (stage.start
                ..stage.end())
                .into_par_iter()
                .map(|i| {
                    let mut trace = Vec::with_capacity(case.world.decisions);
                    let Ok(t) =
                        sampler.run_traced(&mut vut.controller(), seed, i, |d| trace.push(d));
                    FollowTestResult::from_trace(&case.grid, &t, &trace)
                })
                .collect(),
            FollowStage::Probe(cells) => cells[..stage.len as usize]
                .par_iter()
                .map(|&s| FollowTestResult::Probe(probe(&case.world, &case.grid, vut, s)))
                .collect(),
        };
        planner.resolve(&mut state, rule, &results);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cases::carfollow::library::zone;
    use crate::cases::carfollow::world::advance;
    use crate::cases::carfollow::FollowPreset;

    #[test]
    fn a_probe_is_the_vehicles_zone_and_transitions() {
        let case = CarFollowing::new(FollowPreset::Risky);
        let idm = CarFollowing::vehicle(&serde_json::json!({"model": "idm"})).unwrap();
        let t = Transitions::compute(&case.world, case.grid, &case.exposure, &idm);
        let actions = case.world.actions;
        let mut dangerous = 0;
        for s in (0..case.grid.len()).step_by(97) {
            let p = probe(&case.world, &case.grid, &idm, s);
            assert_eq!(p.zone, zone(&case.world, case.grid.state(s), &idm), "{s}");
            assert_eq!(p.zone, t.zones[s]);
            if p.zone == Zone::Dangerous {
                dangerous += 1;
                assert_eq!(p.next[..], t.next[s * actions..(s + 1) * actions]);
                assert!(p.decisions > actions as u64);
            } else {
                assert!(p.next.is_empty());
            }
            assert!(p.decisions <= (case.world.decisions + actions) as u64);
        }
        assert!(dangerous > 10, "{dangerous}");
        // A transition is one decision of a fresh vehicle.
        let s = (0..case.grid.len())
            .find(|&s| t.zones[s] == Zone::Dangerous)
            .unwrap();
        let x = advance(
            &case.world,
            case.grid.state(s),
            case.world.action(0),
            &mut idm.controller(),
        );
        let expected = x.map_or(Next::Accident, |x| {
            case.grid.nearest(&x).map_or(Next::Free, Next::State)
        });
        assert_eq!(probe(&case.world, &case.grid, &idm, s).next[0], expected);
    }

    #[test]
    fn neighbours_are_the_moore_neighbourhood_inside_the_grid() {
        let grid = StateGrid::paper();
        let corner = grid.index(0, 0, 0);
        let mut n: Vec<usize> = neighbours(&grid, corner).collect();
        n.sort_unstable();
        assert_eq!(n.len(), 7);
        let inner = grid.index(5, 50, 9);
        let n: Vec<usize> = neighbours(&grid, inner).collect();
        assert_eq!(n.len(), 26);
        for m in n {
            let (a, b) = (grid.state(inner), grid.state(m));
            assert!((a.bv_speed - b.bv_speed).abs() <= 1.0);
            assert!((a.range - b.range).abs() <= 1.0);
            assert!((a.range_rate - b.range_rate).abs() <= 1.0);
        }
    }
}
