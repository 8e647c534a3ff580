//! An in-process campaign: tests drawn from a test distribution, run on a
//! vehicle, folded into the prefix estimator in index order until the
//! stopping rule holds. Batches of tests run in parallel, but the fold is
//! sequential in test index ([`crate::prefix`]), so the stopping index and the
//! estimate do not depend on the batch size or the number of threads, and
//! equal, to the bit, what the coordinator computes from the same seed.

pub mod answer;
pub(crate) mod result;

pub use answer::{answer, Answer, AnswerContext, AnswerInterval, AnswerReason};
pub use result::CampaignResult;

use crate::anytime::{AnytimeFold, TermBounds};
use crate::estimator::{Decision, Interval, StoppingRule};
use crate::outside::OutsideMass;
use crate::prefix::{Exploration, PrefixFold, SparseOutcome};
use crate::registry::CampaignTests;
use crate::sampling::TestDistribution;
use crate::sequence::next_settlement;
use rayon::prelude::*;

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
    /// The campaign's switch, if made, and how to make it
    /// ([`crate::sampling::allocated_explores`]): an anytime or guarded
    /// campaign switches after the first batch at whose end the library
    /// stratum is known ([`AnytimeFold::switch_due`],
    /// [`PrefixFold::switch_due`]), from the next test on.
    pub switch: Option<Switcher<'a>>,
}

/// Reads and sets a campaign's switch.
#[derive(Clone, Copy)]
pub struct Switcher<'a> {
    /// The switch, if made.
    pub get: &'a (dyn Fn() -> Option<u64> + Sync),
    /// Makes it at a test index.
    pub set: &'a (dyn Fn(u64) + Sync),
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
    let switch_get = || distribution.explore_from();
    let switch_set = |from| {
        distribution.set_explore_from(Some(from));
    };
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
            switch: Some(Switcher {
                get: &switch_get,
                set: &switch_set,
            }),
        }),
        distribution.term_bounds(),
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
        None,
        rule,
    )
}

/// Tests per span of [`run_campaign_tests`]: enough to fill a batch many
/// times, few enough to spread a round over the threads.
const SPAN: u64 = 1024;

/// [`run_outcome_campaign`] with the outcomes of a span of tests at once:
/// `span(from, to)` lists the tests of `from..to` with an event or invalid,
/// in any order. An anytime rule ([`Interval::Anytime`]) needs `bounds`,
/// its terms' largest values.
pub fn run_span_campaign(
    span: &(dyn Fn(u64, u64) -> Vec<(u64, SparseOutcome)> + Sync),
    explorer: Option<Explorer<'_>>,
    bounds: Option<TermBounds>,
    rule: &StoppingRule,
) -> CampaignResult {
    run_span_campaign_watched(span, explorer, bounds, rule, None)
}

/// What a watched campaign is shown: at each settlement
/// ([`crate::sequence::next_settlement`]), its state as a result (tests,
/// interval, guarded upper end).
pub type Watch<'a> = &'a mut dyn FnMut(&CampaignResult);

/// [`run_span_campaign`], showing `watch` the interval at every settlement
/// point up to the stop (the points at which an anytime interval is
/// defined, and where `tslg validate` checks both intervals).
pub fn run_span_campaign_watched(
    span: &(dyn Fn(u64, u64) -> Vec<(u64, SparseOutcome)> + Sync),
    explorer: Option<Explorer<'_>>,
    bounds: Option<TermBounds>,
    rule: &StoppingRule,
    mut watch: Option<Watch<'_>>,
) -> CampaignResult {
    let z = rule.z();
    let mass = explorer.map(|e| e.mass);
    let strata = explorer.and_then(|e| e.strata);
    let mut fold = match rule.interval {
        Interval::Wald => Fold::Wald(PrefixFold::for_rule(rule, strata)),
        Interval::Anytime => Fold::Anytime(Box::new(AnytimeFold::new(
            rule,
            strata,
            bounds.expect("an anytime campaign's input was checked to have bounded terms"),
        ))),
    };
    let mut batch = FIRST_BATCH;
    // The next settlement a watch is shown, on the chain from 0.
    let mut next_watch = next_settlement(0);
    loop {
        let from = fold.indices();
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
        // Watched, the batch is folded piece by piece, cut at settlements.
        let mut cuts = vec![to];
        if watch.is_some() {
            cuts.clear();
            while next_watch < to {
                cuts.push(next_watch);
                next_watch = next_settlement(next_watch);
            }
            cuts.push(to);
        }
        for end in cuts {
            let start = fold.indices();
            let piece_events: Vec<_> = events
                .iter()
                .copied()
                .filter(|&(i, _)| start <= i && i < end)
                .collect();
            let piece_explored: Vec<u64> = explored
                .iter()
                .copied()
                .filter(|&i| start <= i && i < end)
                .collect();
            let exploration = explorer.map(|e| Exploration {
                explored: &piece_explored,
                mass: e.mass,
                surrogate_misses: e.surrogate_misses,
            });
            let stop = match &mut fold {
                Fold::Wald(fold) => fold.advance(rule, z, end, &piece_events, exploration),
                Fold::Anytime(fold) => fold.advance(rule, end, &piece_events, exploration),
            }
            .expect("weights of a valid distribution are finite and ≥ 0");
            let result = match &fold {
                Fold::Wald(fold) => {
                    CampaignResult::from_fold(stop.unwrap_or(Decision::Continue), fold, rule, mass)
                }
                Fold::Anytime(fold) => CampaignResult::from_anytime(
                    stop.unwrap_or(Decision::Continue),
                    fold,
                    rule,
                    mass,
                ),
            };
            if let Some(watch) = watch.as_mut() {
                watch(&result);
            }
            if stop.is_some() {
                return result;
            }
        }
        // Switch once the library stratum is known: from the next test on,
        // nearly every test explores. The tests drawn so far keep their
        // strata; the next batch is drawn after the switch.
        if let Some(switch) = explorer.and_then(|e| e.switch) {
            let due = match &fold {
                Fold::Wald(fold) => fold.switch_due(rule, z),
                Fold::Anytime(anytime) => anytime.switch_due(rule),
            };
            if (switch.get)().is_none() && due {
                (switch.set)(to);
            }
        }
        batch = (batch * 2).min(MAX_BATCH);
    }
}

/// An in-process campaign's fold, by the interval its rule reads.
enum Fold {
    Wald(PrefixFold),
    Anytime(Box<AnytimeFold>),
}

impl Fold {
    fn indices(&self) -> u64 {
        match self {
            Fold::Wald(fold) => fold.indices,
            Fold::Anytime(fold) => fold.fold.indices,
        }
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
    run_campaign_tests_watched(tests, rule, invalid, None)
}

/// [`run_campaign_tests`], showing `watch` the interval at every settlement
/// ([`run_span_campaign_watched`]).
pub fn run_campaign_tests_watched(
    tests: &dyn CampaignTests,
    rule: &StoppingRule,
    invalid: &(dyn Fn(u64) -> bool + Sync),
    watch: Option<Watch<'_>>,
) -> CampaignResult {
    let explores = |i| tests.explores(i);
    let misses = |i| tests.surrogate_misses(i);
    let switch_get = || tests.explore_from();
    let switch_set = |from| {
        tests.set_explore_from(Some(from));
    };
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
    run_span_campaign_watched(
        &span,
        tests.outside_mass().map(|mass| Explorer {
            explores: &explores,
            mass,
            surrogate_misses: &misses,
            strata: tests.strata(),
            switch: Some(Switcher {
                get: &switch_get,
                set: &switch_set,
            }),
        }),
        tests.term_bounds(),
        rule,
        watch,
    )
}

/// [`run_campaign_with`] for a typed case and deterministic vehicle, and
/// the surrogate of the library `distribution` samples from, when known.
pub fn run_campaign<C: crate::case::Case>(
    case: &C,
    vehicle: &C::Vehicle,
    surrogate: Option<&C::Vehicle>,
    distribution: &TestDistribution,
    rule: &StoppingRule,
    seed: u64,
) -> CampaignResult {
    debug_assert!(
        !case.is_noisy(vehicle),
        "run_campaign takes deterministic vehicles: a noisy one's tests run through CampaignTests"
    );
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
