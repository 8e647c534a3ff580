//! An in-process campaign: tests drawn from a test distribution, run on a
//! vehicle, folded into the prefix estimator in index order until the
//! stopping rule holds. Batches of tests run in parallel, but the fold is
//! sequential in test index ([`crate::prefix`]), so the stopping index and the
//! estimate do not depend on the batch size or the number of threads, and
//! equal, to the bit, what the coordinator computes from the same seed.

use crate::estimator::{Decision, StoppingRule};
use crate::outside::OutsideMass;
use crate::prefix::{Exploration, PrefixFold, SparseOutcome};
use crate::registry::CampaignTests;
use crate::sampling::TestDistribution;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The state of a campaign's estimate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CampaignResult {
    /// Whether the campaign goes on, converged or ran out of tests.
    pub status: Decision,
    /// Valid tests in the resolved prefix (`n`).
    pub tests: u64,
    /// Tests in the resolved prefix with the event.
    pub events: u64,
    /// Invalid tests in the resolved prefix.
    pub invalid: u64,
    /// Test indices in the resolved prefix (`tests + invalid`); the stop
    /// index once the campaign has stopped.
    pub indices: u64,
    /// `μ̂ₙ = S₁/n`, `S₁ = Σ wᵢyᵢ`; for a stratified campaign
    /// `(1 − ε) S₁,in/n_in + ε S₁,out/n_out`
    /// ([`crate::prefix::PrefixFold::estimate`]).
    pub estimate: f64,
    /// `z σ̂/√n`, the normal interval's half-width.
    pub half_width: f64,
    /// `rₙ = half_width / μ̂ₙ` (infinite while `μ̂ₙ = 0`).
    pub relative_half_width: f64,
    /// `max(0, μ̂ₙ − half_width)`.
    pub ci_low: f64,
    /// `μ̂ₙ + half_width`.
    pub ci_high: f64,
    /// Kish's effective number of events `S₁²/S₂`
    /// ([`crate::estimator::ImportanceEstimator::effective_events`]).
    pub effective_events: f64,
    /// The largest weighted term's share of the estimate.
    pub largest_weight_share: Option<f64>,
    /// Valid tests drawn outside the library (ε-exploration), and their events.
    pub outside_tests: u64,
    /// Events among the exploring tests.
    pub outside_events: u64,
    /// Those events where the library's surrogate has no event.
    pub mismatched_events: u64,
    /// The events outside the library's share of the estimate (`S₁,out/S₁`,
    /// or `ε (S₁,out/n_out)/μ̂` for a stratified campaign):
    /// the vehicle fails where the surrogate found nothing critical.
    pub outside_share: Option<f64>,
    /// `U`: the upper confidence bound on the failure mass outside the
    /// library ([`crate::outside`]); `None` where the campaign has no
    /// library outside to bound (the NDD, car-following).
    pub outside_upper: Option<f64>,
    /// The interval's upper end with the outside part of the estimate
    /// ([`crate::prefix::PrefixFold::outside_estimate`]) replaced by its
    /// bound: `max(ci_high, ci_high − μ̂_out + U)`.
    pub guarded_ci_high: Option<f64>,
}

impl CampaignResult {
    /// The summary of `fold` under `rule`, with the outside bound when the
    /// campaign explores outside a library of fill `mass`.
    pub fn from_fold(
        status: Decision,
        fold: &PrefixFold,
        rule: &StoppingRule,
        mass: Option<&OutsideMass>,
    ) -> Self {
        let upper = mass.map(|m| m.upper(fold.outside.tests, fold.outside.events, rule.confidence));
        Self::with_outside_upper(status, fold, rule.z(), upper)
    }

    /// The summary of `fold` with quantile `z` and the outside bound
    /// `outside_upper` already computed (as a coordinator persists it).
    pub fn with_outside_upper(
        status: Decision,
        fold: &PrefixFold,
        z: f64,
        outside_upper: Option<f64>,
    ) -> Self {
        let e = &fold.estimator;
        let (ci_low, ci_high) = fold.interval(z);
        let (s1, _) = e.sums();
        let outside_part = fold.outside_estimate();
        Self {
            status,
            tests: e.tests(),
            events: e.events(),
            invalid: fold.invalid,
            indices: fold.indices,
            estimate: fold.estimate(),
            half_width: fold.half_width(z),
            relative_half_width: fold.relative_half_width(z),
            ci_low,
            ci_high,
            effective_events: e.effective_events(),
            largest_weight_share: e.largest_share(),
            outside_tests: fold.outside.tests,
            outside_events: fold.outside.events,
            mismatched_events: fold.outside.mismatches,
            outside_share: (outside_upper.is_some() && s1 > 0.0)
                .then(|| (outside_part / fold.estimate()).min(1.0)),
            outside_upper,
            guarded_ci_high: outside_upper.map(|u| ci_high.max(ci_high - outside_part + u)),
        }
    }

    /// Whether the interval contains `value`.
    pub fn covers(&self, value: f64) -> bool {
        self.ci_low <= value && value <= self.ci_high
    }

    /// Whether the guarded interval `[ci_low, guarded_ci_high]` contains
    /// `value` (the plain one where there is no outside bound).
    pub fn guarded_covers(&self, value: f64) -> bool {
        self.ci_low <= value && value <= self.guarded_ci_high.unwrap_or(self.ci_high)
    }
}

/// First batch size; batches double up to [`MAX_BATCH`].
const FIRST_BATCH: u64 = 64;
const MAX_BATCH: u64 = 65_536;

/// How an in-process campaign learns which tests explored: `explores(i)`
/// and the fill of the outside scenarios.
#[derive(Clone, Copy)]
pub struct Explorer<'a> {
    /// Whether test `i` drew its scenario outside the library.
    pub explores: &'a (dyn Fn(u64) -> bool + Sync),
    /// The worst-case fill of the outside scenarios.
    pub mass: &'a OutsideMass,
    /// See [`Exploration::surrogate_misses`].
    pub surrogate_misses: &'a (dyn Fn(u64) -> bool + Sync),
    /// The exploring share a stratified campaign's estimate stratifies on
    /// ([`PrefixFold::strata`]).
    pub strata: Option<f64>,
}

/// Runs one campaign on a case given as its event test `is_event(cell)`
/// with tests from `distribution`; `surrogate_event(cell)` is the library's
/// surrogate's (for the mismatch count; `None` counts none). The rule must
/// be valid ([`StoppingRule::validate`]).
pub fn run_campaign_with(
    is_event: &(dyn Fn(usize) -> bool + Sync),
    surrogate_event: Option<&(dyn Fn(usize) -> bool + Sync)>,
    distribution: &TestDistribution,
    rule: &StoppingRule,
    seed: u64,
) -> CampaignResult {
    let explores = |i| distribution.explores(seed, i);
    let misses = |i| surrogate_event.is_some_and(|f| !f(distribution.draw(seed, i).cell));
    // Spans of tests in parallel, each drawn several streams at a time
    // ([`TestDistribution::draw_each`]).
    let span = |from: u64, to: u64| -> Vec<(u64, SparseOutcome)> {
        let starts: Vec<u64> = (from..to).step_by(SPAN as usize).collect();
        starts
            .into_par_iter()
            .flat_map_iter(|start| {
                let mut events = Vec::new();
                distribution.draw_each(seed, start..(start + SPAN).min(to), |i, draw| {
                    if is_event(draw.cell) {
                        events.push((i, SparseOutcome::Event(draw.weight)));
                    }
                });
                events
            })
            .collect()
    };
    run_span_campaign(
        &span,
        distribution.outside_mass().map(|mass| Explorer {
            explores: &explores,
            mass,
            surrogate_misses: &misses,
            strata: distribution.strata(),
        }),
        rule,
    )
}

/// Runs one campaign whose test `i` is `event_weight(i)`: the importance
/// weight when the test had the event, `None` otherwise. For cases whose
/// tests draw while they run (car-following), where the weight depends on
/// the vehicle's trajectory.
pub fn run_indexed_campaign(
    event_weight: &(dyn Fn(u64) -> Option<f64> + Sync),
    rule: &StoppingRule,
) -> CampaignResult {
    run_outcome_campaign(&|i| event_weight(i).map(SparseOutcome::Event), None, rule)
}

/// Runs one campaign whose test `i` has the outcome `outcome(i)`: an event
/// with its weight, invalid (it takes an index but enters neither sum), or
/// `None` for no event; `explorer` says which tests drew outside the
/// library, if the campaign has one. A service campaign whose workers
/// report the same outcomes stops at the same index with the same estimate.
pub fn run_outcome_campaign(
    outcome: &(dyn Fn(u64) -> Option<SparseOutcome> + Sync),
    explorer: Option<Explorer<'_>>,
    rule: &StoppingRule,
) -> CampaignResult {
    run_span_campaign(
        &|from, to| {
            (from..to)
                .into_par_iter()
                .filter_map(|i| outcome(i).map(|o| (i, o)))
                .collect()
        },
        explorer,
        rule,
    )
}

/// Tests per span of [`run_campaign_tests`]: enough to fill a batch many
/// times, few enough to spread a round over the threads.
const SPAN: u64 = 1024;

/// [`run_outcome_campaign`] with the outcomes of a span of tests at once:
/// `span(from, to)` lists the tests of `from..to` with an event or invalid,
/// in any order.
pub fn run_span_campaign(
    span: &(dyn Fn(u64, u64) -> Vec<(u64, SparseOutcome)> + Sync),
    explorer: Option<Explorer<'_>>,
    rule: &StoppingRule,
) -> CampaignResult {
    let z = rule.z();
    let mass = explorer.map(|e| e.mass);
    let mut fold = PrefixFold::with_strata(explorer.and_then(|e| e.strata));
    let mut batch = FIRST_BATCH;
    loop {
        let from = fold.indices;
        let to = (from + batch).min(rule.max_tests);
        let mut events = span(from, to);
        events.sort_by_key(|&(i, _)| i);
        let explored: Vec<u64> = match explorer {
            Some(e) => (from..to)
                .into_par_iter()
                .filter(|&i| (e.explores)(i))
                .collect(),
            None => Vec::new(),
        };
        let exploration = explorer.map(|e| Exploration {
            explored: &explored,
            mass: e.mass,
            surrogate_misses: e.surrogate_misses,
        });
        let stop = fold
            .advance(rule, z, to, &events, exploration)
            .expect("weights of a valid distribution are finite and ≥ 0");
        if let Some(status) = stop {
            return CampaignResult::from_fold(status, &fold, rule, mass);
        }
        batch = (batch * 2).min(MAX_BATCH);
    }
}

/// Runs the tests of a service campaign (`tests`, as the coordinator and
/// the workers build them) in this process on its built-in vehicle, the
/// tests `invalid` picks having no valid outcome: the in-process twin of a
/// service campaign, with its exploring tests and mismatches counted as
/// the coordinator counts them.
pub fn run_campaign_tests(
    tests: &dyn CampaignTests,
    rule: &StoppingRule,
    invalid: &(dyn Fn(u64) -> bool + Sync),
) -> CampaignResult {
    let explores = |i| tests.explores(i);
    let misses = |i| tests.surrogate_misses(i);
    let one = |i| {
        if invalid(i) {
            return Some(SparseOutcome::Invalid);
        }
        let outcome = tests.run(i);
        outcome
            .event
            .then_some(SparseOutcome::Event(outcome.weight))
    };
    // Spans of tests run in parallel, each in batches where the case has
    // them ([`CampaignTests::run_span`]).
    let span = |from: u64, to: u64| -> Vec<(u64, SparseOutcome)> {
        let starts: Vec<u64> = (from..to).step_by(SPAN as usize).collect();
        starts
            .into_par_iter()
            .flat_map_iter(|start| {
                let end = (start + SPAN).min(to);
                let outcomes: Vec<(u64, SparseOutcome)> = match tests.run_span(start, end) {
                    Some(outcomes) => (start..end)
                        .zip(outcomes)
                        .filter_map(|(i, o)| {
                            if invalid(i) {
                                Some((i, SparseOutcome::Invalid))
                            } else {
                                o.event.then_some((i, SparseOutcome::Event(o.weight)))
                            }
                        })
                        .collect(),
                    None => (start..end)
                        .filter_map(|i| one(i).map(|o| (i, o)))
                        .collect(),
                };
                outcomes
            })
            .collect()
    };
    run_span_campaign(
        &span,
        tests.outside_mass().map(|mass| Explorer {
            explores: &explores,
            mass,
            surrogate_misses: &misses,
            strata: tests.strata(),
        }),
        rule,
    )
}

/// [`run_campaign_with`] for a typed case and vehicle, and the surrogate
/// of the library `distribution` samples from, when known.
pub fn run_campaign<C: crate::case::Case>(
    case: &C,
    vehicle: &C::Vehicle,
    surrogate: Option<&C::Vehicle>,
    distribution: &TestDistribution,
    rule: &StoppingRule,
    seed: u64,
) -> CampaignResult {
    let surrogate_event = surrogate.map(|s| move |cell| case.is_event(s, cell));
    run_campaign_with(
        &|cell| case.is_event(vehicle, cell),
        surrogate_event
            .as_ref()
            .map(|f| f as &(dyn Fn(usize) -> bool + Sync)),
        distribution,
        rule,
        seed,
    )
}

/// What campaigns with seeds `0..campaigns` of one configuration did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeededCoverage {
    /// Campaigns run.
    pub campaigns: u64,
    /// Campaigns whose interval contains the reference value.
    pub covered: u64,
    /// Mean valid tests at the stop.
    pub mean_tests: f64,
    /// Mean estimate at the stop.
    pub mean_estimate: f64,
}

impl SeededCoverage {
    /// The share of campaigns whose interval covered: `covered / campaigns`.
    pub fn coverage(&self) -> f64 {
        self.covered as f64 / self.campaigns as f64
    }
}

/// Runs one campaign per seed `0..campaigns`, test `i` of seed `s` being
/// `event_weight(s, i)`, and counts the intervals that contain `truth`:
/// the empirical coverage of the interval (nominal: the rule's confidence).
pub fn seeded_coverage(
    event_weight: &(dyn Fn(u64, u64) -> Option<f64> + Sync),
    rule: &StoppingRule,
    campaigns: u64,
    truth: f64,
) -> SeededCoverage {
    let runs: Vec<CampaignResult> = (0..campaigns)
        .map(|seed| run_indexed_campaign(&|i| event_weight(seed, i), rule))
        .collect();
    let n = runs.len().max(1) as f64;
    SeededCoverage {
        campaigns,
        covered: runs.iter().filter(|r| r.covers(truth)).count() as u64,
        mean_tests: runs.iter().map(|r| r.tests as f64).sum::<f64>() / n,
        mean_estimate: runs.iter().map(|r| r.estimate).sum::<f64>() / n,
    }
}

/// The mean weight of tests `0..n` (0 for a test without the event) and its
/// standard error `√((m₂ − m²)/n)`: a reference value by brute force where
/// no enumeration exists.
pub fn mean_weight(event_weight: &(dyn Fn(u64) -> Option<f64> + Sync), n: u64) -> (f64, f64) {
    let (s1, s2) = (0..n)
        .into_par_iter()
        .map(|i| event_weight(i).map_or((0.0, 0.0), |w| (w, w * w)))
        .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    let mean = s1 / n as f64;
    let variance = (s2 / n as f64 - mean * mean).max(0.0);
    (mean, (variance / n as f64).sqrt())
}
