//! An in-process campaign: tests drawn from a test distribution, run on a
//! vehicle, folded into the estimator in index order until the stopping rule
//! holds. Batches of tests run in parallel, but the fold is sequential in
//! test index, so the stopping index and the estimate do not depend on the
//! batch size or the number of threads (the prefix rule of SPEC §7).

use crate::case::Case;
use crate::estimator::{Decision, ImportanceEstimator, StoppingRule};
use crate::sampling::TestDistribution;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The end state of a campaign.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CampaignResult {
    pub status: Decision,
    pub tests: u64,
    pub events: u64,
    pub estimate: f64,
    pub half_width: f64,
    pub relative_half_width: f64,
    pub ci_low: f64,
    pub ci_high: f64,
}

impl CampaignResult {
    fn from_estimator(status: Decision, e: &ImportanceEstimator, z: f64) -> Self {
        let (ci_low, ci_high) = e.interval(z);
        Self {
            status,
            tests: e.tests(),
            events: e.events(),
            estimate: e.estimate(),
            half_width: e.half_width(z),
            relative_half_width: e.relative_half_width(z),
            ci_low,
            ci_high,
        }
    }

    /// Whether the interval contains `value`.
    pub fn covers(&self, value: f64) -> bool {
        self.ci_low <= value && value <= self.ci_high
    }
}

/// First batch size; batches double up to [`MAX_BATCH`].
const FIRST_BATCH: u64 = 64;
const MAX_BATCH: u64 = 16_384;

/// Runs one campaign of `vehicle` on `case` with tests from `distribution`.
/// The rule must be valid ([`StoppingRule::validate`]).
pub fn run_campaign<C: Case>(
    case: &C,
    vehicle: &C::Vehicle,
    distribution: &TestDistribution,
    rule: &StoppingRule,
    seed: u64,
) -> CampaignResult {
    let z = rule.z();
    let mut estimator = ImportanceEstimator::default();
    let mut next = 0u64;
    let mut batch = FIRST_BATCH;
    loop {
        let end = (next + batch).min(rule.max_tests);
        let outcomes: Vec<(f64, bool)> = (next..end)
            .into_par_iter()
            .map(|i| {
                let draw = distribution.draw(seed, i);
                (draw.weight, case.is_event(vehicle, draw.cell))
            })
            .collect();
        for (weight, event) in outcomes {
            estimator.push(weight, event);
            let decision = rule.decide(&estimator, z);
            if decision != Decision::Continue {
                return CampaignResult::from_estimator(decision, &estimator, z);
            }
        }
        next = end;
        batch = (batch * 2).min(MAX_BATCH);
    }
}
