//! The prefix estimator (SPEC §7): outcomes are folded strictly in test-index
//! order, from sparse input (the events with their weights and the invalid
//! tests; every other index of a resolved range had no event), and the
//! stopping rule is checked at every index, so the stop index is exact.
//!
//! Checking every index of a run of `k` tests without the event costs O(1),
//! not O(k): such tests leave `S₁, S₂` unchanged, and with
//! `g(n) = (n S₂ − S₁²)/(n − 1) = S₂ + (S₂ − S₁²)/(n − 1)` the squared relative
//! half-width is `rₙ² = z² g(n)/S₁²`. Because `S₁² ≥ S₂` for non-negative
//! terms, `g` is non-decreasing in `n`: inside a zero run `rₙ` only grows, and
//! the rule can first hold at the run's first index with `n ≥ n_min`. The
//! event count and `μ̂ₙ > 0` do not change inside the run either.
//!
//! Invalid tests use an index (and count toward `max_tests`, the budget of
//! test indices) but are neither events nor non-events: `n` skips them.

use crate::estimator::{Decision, ImportanceEstimator, StoppingRule};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Input that breaks the fold's contract; the state is left unchanged.
#[derive(Debug, Error, PartialEq)]
pub enum FoldError {
    #[error("outcome at test {index} lies outside the span {from}..{to} being folded")]
    OutOfSpan { index: u64, from: u64, to: u64 },
    #[error("outcomes are not in strictly increasing test order at test {0}")]
    Unordered(u64),
    #[error("event weight {weight} at test {index} is not a finite number ≥ 0")]
    BadWeight { index: u64, weight: f64 },
}

/// One resolved test in sparse form.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SparseOutcome {
    /// The event, with the test's importance weight.
    Event(f64),
    Invalid,
}

/// The state of a campaign's estimate over the resolved prefix `0..indices`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct PrefixFold {
    pub estimator: ImportanceEstimator,
    /// Test indices folded so far (valid and invalid).
    pub indices: u64,
    /// Invalid tests among them.
    pub invalid: u64,
}

impl PrefixFold {
    /// Folds the tests `self.indices..to`, of which `outcomes` (sorted by
    /// index) are the events and invalid tests; all others had no event.
    /// Returns the decision if the rule stopped the campaign, in which case
    /// `self.indices` is the exact stop index and later tests are not folded.
    pub fn advance(
        &mut self,
        rule: &StoppingRule,
        z: f64,
        to: u64,
        outcomes: &[(u64, SparseOutcome)],
    ) -> Result<Option<Decision>, FoldError> {
        self.advance_observed(rule, z, to, outcomes, &mut |_| {})
    }

    /// [`PrefixFold::advance`], showing `observe` the fold on both sides of
    /// each outcome (before it, after the tests without the event that lead
    /// to it, and after it), so a history can follow a long report's course
    /// rather than jump over it. The final state is not shown.
    pub fn advance_observed(
        &mut self,
        rule: &StoppingRule,
        z: f64,
        to: u64,
        outcomes: &[(u64, SparseOutcome)],
        observe: &mut dyn FnMut(&PrefixFold),
    ) -> Result<Option<Decision>, FoldError> {
        let from = self.indices;
        let mut previous = None;
        for &(index, outcome) in outcomes {
            if index < from || index >= to {
                return Err(FoldError::OutOfSpan { index, from, to });
            }
            if previous.is_some_and(|p| index <= p) {
                return Err(FoldError::Unordered(index));
            }
            if let SparseOutcome::Event(weight) = outcome {
                if !(weight.is_finite() && weight >= 0.0) {
                    return Err(FoldError::BadWeight { index, weight });
                }
            }
            previous = Some(index);
        }
        if self.indices >= rule.max_tests {
            return Ok(Some(Decision::Exhausted));
        }
        for &(index, outcome) in outcomes {
            if let Some(stop) = self.fold_zeros(rule, z, index - self.indices) {
                return Ok(Some(stop));
            }
            observe(self);
            if let Some(stop) = self.fold_one(rule, z, outcome) {
                return Ok(Some(stop));
            }
            observe(self);
        }
        Ok(self.fold_zeros(rule, z, to.saturating_sub(self.indices)))
    }

    /// Folds `k` tests without the event.
    fn fold_zeros(&mut self, rule: &StoppingRule, z: f64, k: u64) -> Option<Decision> {
        if k == 0 {
            return None;
        }
        let run = k.min(rule.max_tests - self.indices);
        let n0 = self.estimator.tests();
        let first = (n0 + 1).max(rule.n_min);
        if first <= n0 + run {
            let mut probe = self.estimator;
            probe.push_zeros(first - n0);
            if rule.converged(&probe, z) {
                self.estimator = probe;
                self.indices += first - n0;
                return Some(Decision::Converged);
            }
        }
        self.estimator.push_zeros(run);
        self.indices += run;
        (self.indices >= rule.max_tests).then_some(Decision::Exhausted)
    }

    fn fold_one(
        &mut self,
        rule: &StoppingRule,
        z: f64,
        outcome: SparseOutcome,
    ) -> Option<Decision> {
        self.indices += 1;
        match outcome {
            SparseOutcome::Event(weight) => {
                self.estimator.push(weight, true);
                if rule.converged(&self.estimator, z) {
                    return Some(Decision::Converged);
                }
            }
            SparseOutcome::Invalid => self.invalid += 1,
        }
        (self.indices >= rule.max_tests).then_some(Decision::Exhausted)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The reference: one test at a time, the rule checked after each.
    fn step_by_step(rule: &StoppingRule, z: f64, tests: &[Option<Option<f64>>]) -> PrefixFold {
        let mut fold = PrefixFold::default();
        for t in tests {
            fold.indices += 1;
            match t {
                Some(Some(w)) => fold.estimator.push(*w, true),
                Some(None) => fold.estimator.push(0.0, false),
                None => fold.invalid += 1,
            }
            if rule.converged(&fold.estimator, z) || fold.indices >= rule.max_tests {
                break;
            }
        }
        fold
    }

    fn sparse(tests: &[Option<Option<f64>>], from: usize, to: usize) -> Vec<(u64, SparseOutcome)> {
        (from..to)
            .filter_map(|i| match tests[i] {
                Some(Some(w)) => Some((i as u64, SparseOutcome::Event(w))),
                Some(None) => None,
                None => Some((i as u64, SparseOutcome::Invalid)),
            })
            .collect()
    }

    #[test]
    fn sparse_folds_in_any_chunking_equal_the_step_by_step_rule_to_the_bit() {
        for seed in 0..200u64 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let len = 3000;
            let p_event = rng.random_range(0.002..0.05);
            let tests: Vec<Option<Option<f64>>> = (0..len)
                .map(|_| {
                    let u: f64 = rng.random();
                    if u < 0.01 {
                        None
                    } else if u < 0.01 + p_event {
                        Some(Some(rng.random_range(0.01..3.0)))
                    } else {
                        Some(None)
                    }
                })
                .collect();
            let rule = StoppingRule {
                beta: rng.random_range(0.2..0.9),
                confidence: 0.9,
                n_min: rng.random_range(1..200),
                min_events: rng.random_range(0..5),
                max_tests: rng.random_range(200..len as u64),
            };
            let z = rule.z();
            let reference = step_by_step(&rule, z, &tests);
            let mut fold = PrefixFold::default();
            let mut at = 0usize;
            while at < len {
                let to = (at + rng.random_range(1..400)).min(len);
                let stop = fold
                    .advance(&rule, z, to as u64, &sparse(&tests, at, to))
                    .unwrap();
                if stop.is_some() {
                    break;
                }
                at = to;
            }
            assert_eq!(fold, reference, "seed {seed}");
        }
    }

    #[test]
    fn observed_states_are_the_folds_of_the_prefixes_around_each_outcome() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let tests: Vec<Option<Option<f64>>> = (0..2000)
            .map(|_| match rng.random::<f64>() {
                u if u < 0.005 => None,
                u if u < 0.03 => Some(Some(rng.random_range(0.01..3.0))),
                _ => Some(None),
            })
            .collect();
        let rule = StoppingRule {
            beta: 0.01,
            confidence: 0.9,
            n_min: 10,
            min_events: 5,
            max_tests: 5000,
        };
        let z = rule.z();
        let outcomes = sparse(&tests, 0, 2000);
        let mut seen = Vec::new();
        let mut fold = PrefixFold::default();
        let stop = fold
            .advance_observed(&rule, z, 2000, &outcomes, &mut |state| seen.push(*state))
            .unwrap();
        assert_eq!(stop, None);
        // Two states per outcome: just before it and just after it.
        assert_eq!(seen.len(), 2 * outcomes.len());
        for (k, &(index, _)) in outcomes.iter().enumerate() {
            assert_eq!(seen[2 * k].indices, index);
            assert_eq!(seen[2 * k + 1].indices, index + 1);
        }
        for state in &seen {
            let mut prefix = PrefixFold::default();
            let to = state.indices as usize;
            prefix
                .advance(&rule, z, to as u64, &sparse(&tests, 0, to))
                .unwrap();
            assert_eq!(*state, prefix);
        }
    }

    #[test]
    fn a_zero_run_stops_at_n_min_when_the_rule_already_holds() {
        // Ten events of weight 1 then zeros: r_n is 0 while n = 10, then grows;
        // with n_min = 12 the rule holds first at n = 12 (r₁₂ ≈ 0.16 ≤ 0.5).
        let rule = StoppingRule {
            beta: 0.5,
            confidence: 0.9,
            n_min: 12,
            min_events: 1,
            max_tests: 100,
        };
        let z = rule.z();
        let events: Vec<_> = (0..10).map(|i| (i, SparseOutcome::Event(1.0))).collect();
        let mut fold = PrefixFold::default();
        let stop = fold.advance(&rule, z, 50, &events).unwrap();
        assert_eq!(stop, Some(Decision::Converged));
        assert_eq!(fold.indices, 12);
        assert_eq!(fold.estimator.tests(), 12);
    }

    #[test]
    fn invalid_tests_use_the_budget_but_not_n_and_bad_input_is_refused() {
        let rule = StoppingRule {
            beta: 0.1,
            confidence: 0.9,
            n_min: 1,
            min_events: 1,
            max_tests: 5,
        };
        let z = rule.z();
        let mut fold = PrefixFold::default();
        let invalid: Vec<_> = (0..3).map(|i| (i, SparseOutcome::Invalid)).collect();
        assert_eq!(fold.advance(&rule, z, 3, &invalid).unwrap(), None);
        assert_eq!(
            (fold.indices, fold.invalid, fold.estimator.tests()),
            (3, 3, 0)
        );
        let before = fold;
        let err = fold.advance(&rule, z, 4, &[(7, SparseOutcome::Invalid)]);
        assert_eq!(
            err,
            Err(FoldError::OutOfSpan {
                index: 7,
                from: 3,
                to: 4
            })
        );
        let err = fold.advance(&rule, z, 5, &[(3, SparseOutcome::Event(f64::NAN))]);
        assert!(matches!(err, Err(FoldError::BadWeight { index: 3, .. })));
        assert_eq!(fold, before);
        assert_eq!(
            fold.advance(&rule, z, 100, &[]).unwrap(),
            Some(Decision::Exhausted)
        );
        assert_eq!((fold.indices, fold.estimator.tests()), (5, 2));
    }
}
