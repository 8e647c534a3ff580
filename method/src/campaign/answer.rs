//! Which interval a campaign answers with, and why (issue 66): the one a
//! user should report, the same in every view (the API's `answer`, the
//! command line, the dashboard, `tslg reproduce`, `tslg validate`'s
//! coverage).
//!
//! - A campaign with no outside to bound (the NDD, car-following) answers
//!   with its interval, which assumes nothing about where the vehicle
//!   fails.
//! - A guarded campaign, and any campaign of a **noisy** vehicle, answers
//!   with the guarded interval `[ci_low, guarded_ci_high]`: the upper end
//!   holds the bound on the failure mass the library (or an adaptive
//!   campaign's support) leaves out instead of the few exploring tests'
//!   estimate of it. A noisy vehicle's scenarios fail with a probability,
//!   so whether the library or the support holds every one that can fail
//!   is never checkable from a few runs: its plain interval covered 0.30
//!   to 0.44 of the time on a noisy Gipps program (docs/statistics.md,
//!   "Noisy vehicles").
//! - Otherwise the plain interval, which assumes the library (or the
//!   search) covers where the vehicle fails; the guarded upper end is shown
//!   beside it.

use super::CampaignResult;
use serde::{Deserialize, Serialize};

/// Which interval a campaign answers with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum AnswerInterval {
    /// `[ci_low, ci_high]`.
    Plain,
    /// `[ci_low, guarded_ci_high]`.
    Guarded,
}

/// Why a campaign answers with the interval it does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AnswerReason {
    /// No outside to bound: the interval assumes nothing about where the
    /// vehicle fails (the NDD), or its sampling has no outside
    /// (car-following's policy).
    NoOutside,
    /// A noisy vehicle.
    Noisy,
    /// The campaign ran under the guard.
    Guard,
    /// The plain interval of a library campaign.
    Library,
    /// The plain interval of an adaptive campaign.
    Search,
}

impl AnswerReason {
    /// The reason in words.
    pub fn text(self) -> &'static str {
        match self {
            AnswerReason::NoOutside => {
                "its interval; it has no library outside to bound, and assumes nothing about \
                 where the vehicle fails beyond its sampling"
            }
            AnswerReason::Noisy => {
                "the guarded interval: the vehicle is noisy, so whether the library or the \
                 support holds every scenario that can fail cannot be checked from a few runs; \
                 its upper end holds the bound on what they leave out"
            }
            AnswerReason::Guard => {
                "the guarded interval: the campaign ran under the guard, and its upper end \
                 holds the bound on the failure mass the library or the support leaves out"
            }
            AnswerReason::Library => {
                "the plain interval, which assumes the library covers where this vehicle fails; \
                 the guarded upper end does not"
            }
            AnswerReason::Search => {
                "the plain interval, which assumes the search reached every failure of this \
                 vehicle; the guarded upper end does not"
            }
        }
    }
}

/// The interval a campaign answers with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Answer {
    /// Which interval.
    pub interval: AnswerInterval,
    /// Its lower end (`ci_low`).
    pub low: f64,
    /// Its upper end: `ci_high` or `guarded_ci_high`.
    pub high: f64,
    /// Why.
    pub reason: AnswerReason,
}

impl Answer {
    /// Whether the answer contains `value`.
    pub fn covers(&self, value: f64) -> bool {
        self.low <= value && value <= self.high
    }
}

/// What a campaign is, as far as its answer goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AnswerContext {
    /// It stopped only under the outside guard.
    pub guard_outside: bool,
    /// Its vehicle's runs of one scenario may differ.
    pub noisy: bool,
    /// An adaptive campaign (its outside is off its support).
    pub adaptive: bool,
}

/// The interval `result` answers with under `context` (see the module).
pub fn answer(result: &CampaignResult, context: AnswerContext) -> Answer {
    let plain = |reason| Answer {
        interval: AnswerInterval::Plain,
        low: result.ci_low,
        high: result.ci_high,
        reason,
    };
    let Some(guarded_high) = result.guarded_ci_high else {
        return plain(AnswerReason::NoOutside);
    };
    let guarded = |reason| Answer {
        interval: AnswerInterval::Guarded,
        low: result.ci_low,
        high: guarded_high,
        reason,
    };
    match context {
        AnswerContext { noisy: true, .. } => guarded(AnswerReason::Noisy),
        AnswerContext {
            guard_outside: true,
            ..
        } => guarded(AnswerReason::Guard),
        AnswerContext { adaptive: true, .. } => plain(AnswerReason::Search),
        _ => plain(AnswerReason::Library),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimator::Decision;
    use crate::prefix::PrefixFold;

    fn result(outside_upper: Option<f64>) -> CampaignResult {
        let mut fold = PrefixFold::default();
        for i in 0..40u64 {
            fold.push(if i % 4 == 0 { 2e-3 } else { 0.0 }, i % 4 == 0, i % 10 == 9);
        }
        CampaignResult::with_outside_upper(Decision::Converged, &fold, 1.645, outside_upper)
    }

    #[test]
    fn a_noisy_or_guarded_campaign_answers_with_the_guarded_interval() {
        let r = result(Some(0.3));
        let high = r.guarded_ci_high.unwrap();
        assert!(high > r.ci_high);
        let context = |guard_outside, noisy, adaptive| AnswerContext {
            guard_outside,
            noisy,
            adaptive,
        };
        for (c, interval, end, reason) in [
            (
                context(false, true, true),
                AnswerInterval::Guarded,
                high,
                AnswerReason::Noisy,
            ),
            (
                context(true, true, false),
                AnswerInterval::Guarded,
                high,
                AnswerReason::Noisy,
            ),
            (
                context(true, false, false),
                AnswerInterval::Guarded,
                high,
                AnswerReason::Guard,
            ),
            (
                context(false, false, true),
                AnswerInterval::Plain,
                r.ci_high,
                AnswerReason::Search,
            ),
            (
                context(false, false, false),
                AnswerInterval::Plain,
                r.ci_high,
                AnswerReason::Library,
            ),
        ] {
            let a = answer(&r, c);
            assert_eq!(
                (a.interval, a.high, a.reason),
                (interval, end, reason),
                "{c:?}"
            );
            assert_eq!(a.low, r.ci_low);
            assert_eq!(a.covers(high), interval == AnswerInterval::Guarded);
        }
        // Without an outside bound (the NDD) a noisy vehicle's interval is
        // its plain one: nothing lies outside.
        let ndd = answer(&result(None), context(false, true, false));
        assert_eq!(
            (ndd.interval, ndd.reason),
            (AnswerInterval::Plain, AnswerReason::NoOutside)
        );
    }
}
