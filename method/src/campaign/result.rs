//! The state of a campaign's estimate: the summary of its prefix fold that
//! every view, file and answer reports.

use crate::anytime::{outside_bound, AnytimeFold};
use crate::estimator::{Decision, Interval, StoppingRule};
use crate::outside::OutsideMass;
use crate::prefix::PrefixFold;
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
    /// Which interval `ci_low..ci_high` is: the normal one, or the
    /// confidence sequence's ([`crate::anytime`]).
    #[serde(default)]
    pub interval: Interval,
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
            interval: Interval::Wald,
        }
    }

    /// The summary of an anytime fold: its interval is the sequence's
    /// `[L, U]`, the half-width `(U − L)/2`. A stratified campaign's upper
    /// end already holds the exploring stratum's own bound `U_out`, which
    /// is also its outside bound; a campaign without strata keeps the
    /// Clopper–Pearson bound of `mass`.
    pub fn from_anytime(
        status: Decision,
        fold: &AnytimeFold,
        rule: &StoppingRule,
        mass: Option<&OutsideMass>,
    ) -> Self {
        let outside_upper = outside_bound(Some(fold), &fold.fold, mass, rule.confidence);
        let bounds = fold.bounds();
        Self::with_outside_upper(status, &fold.fold, rule.z(), outside_upper).on_sequence(
            &fold.fold,
            (bounds.low, bounds.high),
            fold.outside_upper().is_some(),
        )
    }

    /// This summary read on a confidence sequence's interval `[low, high]`
    /// of `fold` (an anytime campaign, in process or as a coordinator
    /// stored it): the half-width is `(high − low)/2`. When the sequence
    /// holds the exploring stratum's own bound (`outside_in_sequence`, a
    /// stratified campaign), `high` is the guarded upper end already;
    /// otherwise the outside bound replaces the outside part of the
    /// estimate, as for a Wald interval.
    pub fn on_sequence(
        mut self,
        fold: &PrefixFold,
        (low, high): (f64, f64),
        outside_in_sequence: bool,
    ) -> Self {
        self.ci_low = low;
        self.ci_high = high;
        self.half_width = (high - low) / 2.0;
        self.relative_half_width = if self.estimate > 0.0 {
            self.half_width / self.estimate
        } else {
            f64::INFINITY
        };
        let outside_part = fold.outside_estimate();
        self.guarded_ci_high = self.outside_upper.map(|u| match outside_in_sequence {
            true => high,
            false => high.max(high - outside_part + u),
        });
        self.interval = Interval::Anytime;
        self
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
