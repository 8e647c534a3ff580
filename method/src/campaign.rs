//! An in-process campaign: tests drawn from a test distribution, run on a
//! vehicle, folded into the prefix estimator in index order until the
//! stopping rule holds. Batches of tests run in parallel, but the fold is
//! sequential in test index ([`crate::prefix`]), so the stopping index and the
//! estimate do not depend on the batch size or the number of threads, and
//! equal, to the bit, what the coordinator computes from the same seed.

use crate::estimator::{Decision, StoppingRule};
use crate::prefix::{PrefixFold, SparseOutcome};
use crate::sampling::TestDistribution;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The state of a campaign's estimate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CampaignResult {
    pub status: Decision,
    /// Valid tests in the resolved prefix (`n`).
    pub tests: u64,
    pub events: u64,
    /// Invalid tests in the resolved prefix.
    pub invalid: u64,
    /// Test indices in the resolved prefix (`tests + invalid`); the stop
    /// index once the campaign has stopped.
    pub indices: u64,
    pub estimate: f64,
    pub half_width: f64,
    pub relative_half_width: f64,
    pub ci_low: f64,
    pub ci_high: f64,
    /// Kish's effective number of events `S₁²/S₂`
    /// ([`crate::estimator::ImportanceEstimator::effective_events`]).
    pub effective_events: f64,
    /// The largest weighted term's share of the estimate.
    pub largest_weight_share: Option<f64>,
}

impl CampaignResult {
    /// The summary of `fold` under a rule with quantile `z`.
    pub fn from_fold(status: Decision, fold: &PrefixFold, z: f64) -> Self {
        let e = &fold.estimator;
        let (ci_low, ci_high) = e.interval(z);
        Self {
            status,
            tests: e.tests(),
            events: e.events(),
            invalid: fold.invalid,
            indices: fold.indices,
            estimate: e.estimate(),
            half_width: e.half_width(z),
            relative_half_width: e.relative_half_width(z),
            ci_low,
            ci_high,
            effective_events: e.effective_events(),
            largest_weight_share: e.largest_share(),
        }
    }

    /// Whether the interval contains `value`.
    pub fn covers(&self, value: f64) -> bool {
        self.ci_low <= value && value <= self.ci_high
    }
}

/// First batch size; batches double up to [`MAX_BATCH`].
const FIRST_BATCH: u64 = 64;
const MAX_BATCH: u64 = 65_536;

/// Runs one campaign on a case given as its event test `is_event(cell)`
/// with tests from `distribution`. The rule must be valid
/// ([`StoppingRule::validate`]).
pub fn run_campaign_with(
    is_event: &(dyn Fn(usize) -> bool + Sync),
    distribution: &TestDistribution,
    rule: &StoppingRule,
    seed: u64,
) -> CampaignResult {
    run_indexed_campaign(
        &|i| {
            let draw = distribution.draw(seed, i);
            is_event(draw.cell).then_some(draw.weight)
        },
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
    run_outcome_campaign(&|i| event_weight(i).map(SparseOutcome::Event), rule)
}

/// Runs one campaign whose test `i` has the outcome `outcome(i)`: an event
/// with its weight, invalid (it takes an index but enters neither sum), or
/// `None` for no event. A service campaign whose workers report the same
/// outcomes stops at the same index with the same estimate.
pub fn run_outcome_campaign(
    outcome: &(dyn Fn(u64) -> Option<SparseOutcome> + Sync),
    rule: &StoppingRule,
) -> CampaignResult {
    let z = rule.z();
    let mut fold = PrefixFold::default();
    let mut batch = FIRST_BATCH;
    loop {
        let from = fold.indices;
        let to = (from + batch).min(rule.max_tests);
        let mut events: Vec<(u64, SparseOutcome)> = (from..to)
            .into_par_iter()
            .filter_map(|i| outcome(i).map(|o| (i, o)))
            .collect();
        events.sort_by_key(|&(i, _)| i);
        let stop = fold
            .advance(rule, z, to, &events)
            .expect("weights of a valid distribution are finite and ≥ 0");
        if let Some(status) = stop {
            return CampaignResult::from_fold(status, &fold, z);
        }
        batch = (batch * 2).min(MAX_BATCH);
    }
}

/// [`run_campaign_with`] for a typed case and vehicle.
pub fn run_campaign<C: crate::case::Case>(
    case: &C,
    vehicle: &C::Vehicle,
    distribution: &TestDistribution,
    rule: &StoppingRule,
    seed: u64,
) -> CampaignResult {
    run_campaign_with(
        &|cell| case.is_event(vehicle, cell),
        distribution,
        rule,
        seed,
    )
}

/// What campaigns with seeds `0..campaigns` of one configuration did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeededCoverage {
    pub campaigns: u64,
    /// Campaigns whose interval contains the reference value.
    pub covered: u64,
    pub mean_tests: f64,
    pub mean_estimate: f64,
}

impl SeededCoverage {
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
