//! What one resolved stage of an adaptive campaign did, as a coordinator
//! stores and a dashboard shows it: where its tests sit among all the
//! campaign's tests, what they found, the support after it, and (an
//! estimation stage) the estimate's course over its tests.

use crate::prefix::PrefixFold;

/// One resolved stage ([`super::Planner::resolve`]).
#[derive(Debug, Clone, PartialEq)]
pub struct StageRecord {
    /// `"library"`, `"search"` or `"estimate"`.
    pub kind: &'static str,
    /// Its first test index among all the campaign's tests.
    pub start: u64,
    /// One past its last test used: the stage's end, or the index where the
    /// rule stopped the campaign inside it.
    pub end: u64,
    /// Tests of `start..end` where the vehicle had the event.
    pub events: u64,
    /// Scenarios found failing for the first time by these tests.
    pub new_failures: u64,
    /// Tests of `start..end` without a valid outcome.
    pub invalid: u64,
    /// `|K|` after the stage: the cells the next estimation stage samples
    /// besides its exploring share ([`super::Planner::support`]).
    pub support: u64,
    /// A guarded campaign's estimate starts again after this stage, with
    /// the guard's stages (`course` and every estimate before are dropped).
    pub restarts_estimate: bool,
    /// An estimation stage's estimate on both sides of each of its events
    /// and invalid tests and at its end, each fold's `indices` being the
    /// campaign's test index (not the estimation tests' count, which is
    /// `estimator.tests()`); empty for other stages.
    pub course: Vec<PrefixFold>,
}

/// Follows an estimation stage's fold, whose estimation indices start at
/// `fold_start` where the campaign's test index is `stage_start`, keeping
/// each state it is shown with its `indices` moved to the campaign's.
pub(super) struct Course {
    stage_start: u64,
    fold_start: u64,
    pub(super) points: Vec<PrefixFold>,
}

impl Course {
    pub(super) fn new(stage_start: u64, fold_start: u64) -> Self {
        Self {
            stage_start,
            fold_start,
            points: Vec::new(),
        }
    }

    /// Keeps `fold` (after at least one estimation test of the stage).
    pub(super) fn keep(&mut self, fold: &PrefixFold) {
        if fold.indices <= self.fold_start {
            return;
        }
        let indices = self.stage_start + (fold.indices - self.fold_start);
        if self.points.last().is_some_and(|p| p.indices == indices) {
            self.points.pop();
        }
        self.points.push(PrefixFold { indices, ..*fold });
    }
}
