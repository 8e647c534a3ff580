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
use crate::outside::{OutsideMass, OutsideTally};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Input that breaks the fold's contract; the state is left unchanged.
#[derive(Debug, Error, PartialEq)]
pub enum FoldError {
    /// An outcome outside the span being folded.
    #[error("outcome at test {index} lies outside the span {from}..{to} being folded")]
    OutOfSpan {
        /// The outcome's test.
        index: u64,
        /// First index of the span.
        from: u64,
        /// One past the span's last index.
        to: u64,
    },
    /// Outcomes not in strictly increasing test order.
    #[error("outcomes are not in strictly increasing test order at test {0}")]
    Unordered(u64),
    /// An event weight that is NaN, infinite or negative.
    #[error("event weight {weight} at test {index} is not a finite number ≥ 0")]
    BadWeight {
        /// The test.
        index: u64,
        /// Its weight.
        weight: f64,
    },
    /// Exploring tests outside the span or out of order.
    #[error(
        "exploring test {index} is not in strictly increasing order inside the span {from}..{to}"
    )]
    Explored {
        /// The exploring test.
        index: u64,
        /// First index of the span.
        from: u64,
        /// One past the span's last index.
        to: u64,
    },
}

/// One resolved test in sparse form.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SparseOutcome {
    /// The event, with the test's importance weight.
    Event(f64),
    /// The test could not be run; it does not count in `n`.
    Invalid,
}

/// What a library campaign's fold needs about its exploring tests
/// ([`crate::outside`]): which tests of the span drew outside the library,
/// and the fill that bounds the failure mass there.
#[derive(Clone, Copy)]
pub struct Exploration<'a> {
    /// The indices of the span being folded whose tests explored, increasing.
    pub explored: &'a [u64],
    /// The worst-case fill of the outside scenarios.
    pub mass: &'a OutsideMass,
    /// Whether the library's surrogate has no event in the scenario of
    /// test `i` (asked only of exploring tests with the event).
    pub surrogate_misses: &'a (dyn Fn(u64) -> bool + Sync),
}

/// The state of a campaign's estimate over the resolved prefix `0..indices`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct PrefixFold {
    /// The running sums of the valid tests folded.
    pub estimator: ImportanceEstimator,
    /// Test indices folded so far (valid and invalid).
    pub indices: u64,
    /// Invalid tests among them.
    pub invalid: u64,
    /// The valid tests among them that explored, and their events.
    #[serde(default)]
    pub outside: OutsideTally,
}

impl PrefixFold {
    /// Folds the tests `self.indices..to`, of which `outcomes` (sorted by
    /// index) are the events and invalid tests; all others had no event.
    /// `exploration` lists the span's exploring tests (library campaigns of
    /// grid cases; `None` otherwise). Returns the decision if the rule
    /// stopped the campaign, in which case `self.indices` is the exact stop
    /// index and later tests are not folded.
    pub fn advance(
        &mut self,
        rule: &StoppingRule,
        z: f64,
        to: u64,
        outcomes: &[(u64, SparseOutcome)],
        exploration: Option<Exploration<'_>>,
    ) -> Result<Option<Decision>, FoldError> {
        self.advance_observed(rule, z, to, outcomes, exploration, &mut |_| {})
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
        exploration: Option<Exploration<'_>>,
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
        let explored = exploration.map_or(&[][..], |e| e.explored);
        let mut previous = None;
        for &index in explored {
            if index < from || index >= to || previous.is_some_and(|p| index <= p) {
                return Err(FoldError::Explored { index, from, to });
            }
            previous = Some(index);
        }
        if self.indices >= rule.max_tests {
            return Ok(Some(Decision::Exhausted));
        }
        let mut pass = Pass {
            rule,
            z,
            mass: exploration.map(|e| e.mass),
            surrogate_misses: exploration.map(|e| e.surrogate_misses),
            explored,
        };
        for &(index, outcome) in outcomes {
            if let Some(stop) = self.fold_zeros(&mut pass, index - self.indices) {
                return Ok(Some(stop));
            }
            observe(self);
            if let Some(stop) = self.fold_one(&mut pass, index, outcome) {
                return Ok(Some(stop));
            }
            observe(self);
        }
        Ok(self.fold_zeros(&mut pass, to.saturating_sub(self.indices)))
    }

    /// Whether the rule stops here: `rₙ ≤ β` and the rest of
    /// [`StoppingRule::converged`], and, when the rule guards the outside,
    /// the guard of [`OutsideTally::guarded`].
    pub fn stops(&self, rule: &StoppingRule, z: f64, mass: Option<&OutsideMass>) -> bool {
        rule.converged(&self.estimator, z) && self.guard_holds(rule, mass)
    }

    fn guard_holds(&self, rule: &StoppingRule, mass: Option<&OutsideMass>) -> bool {
        let (Some(mass), true) = (mass, rule.guard_outside) else {
            return true;
        };
        let (s1, _) = self.estimator.sums();
        self.outside
            .guarded(mass, rule.confidence, rule.beta, s1, self.estimator.tests())
    }

    /// This fold after `k` more tests without the event, `explored` being
    /// the exploring tests from `self.indices` on.
    fn after_zeros(&self, k: u64, explored: &[u64]) -> PrefixFold {
        let mut next = *self;
        next.estimator.push_zeros(k);
        next.indices += k;
        next.outside.tests += explored.partition_point(|&e| e < next.indices) as u64;
        next
    }

    /// Folds `k` tests without the event.
    ///
    /// Without the guard the rule can first hold at the run's first index
    /// with `n ≥ n_min` (see the module's note). With it, `rₙ ≤ β` holds on
    /// an interval `[first, last]` of the run (found by bisection, `rₙ`
    /// growing), and the guard `U(m) ≤ (β S₁ + S₁,out)/n` can first hold at
    /// `first` or just after an exploring test: between those `U` is fixed
    /// and the right side falls.
    fn fold_zeros(&mut self, pass: &mut Pass<'_>, k: u64) -> Option<Decision> {
        if k == 0 {
            return None;
        }
        let rule = pass.rule;
        let run = k.min(rule.max_tests - self.indices);
        let n0 = self.estimator.tests();
        let start = self.indices;
        let first = (n0 + 1).max(rule.n_min);
        let mut stop = None;
        if first <= n0 + run {
            let at_first = self.after_zeros(first - n0, pass.explored);
            if rule.converged(&at_first.estimator, pass.z) {
                if at_first.guard_holds(rule, pass.mass) {
                    stop = Some(at_first);
                } else {
                    let (mut lo, mut hi) = (first, n0 + run);
                    while lo < hi {
                        let mid = lo + (hi - lo).div_ceil(2);
                        let probe = self.after_zeros(mid - n0, pass.explored);
                        if rule.converged(&probe.estimator, pass.z) {
                            lo = mid;
                        } else {
                            hi = mid - 1;
                        }
                    }
                    let (a, b) = (start + (first - n0), start + (lo - n0));
                    stop = pass
                        .explored
                        .iter()
                        .filter(|&&e| a <= e && e < b)
                        .map(|&e| self.after_zeros(e - start + 1, pass.explored))
                        .find(|probe| probe.guard_holds(rule, pass.mass));
                }
            }
        }
        if let Some(state) = stop {
            *self = state;
            pass.consume_below(self.indices);
            return Some(Decision::Converged);
        }
        *self = self.after_zeros(run, pass.explored);
        pass.consume_below(self.indices);
        (self.indices >= rule.max_tests).then_some(Decision::Exhausted)
    }

    fn fold_one(
        &mut self,
        pass: &mut Pass<'_>,
        index: u64,
        outcome: SparseOutcome,
    ) -> Option<Decision> {
        let explored = pass.explored.first() == Some(&index);
        pass.consume_below(index + 1);
        self.indices += 1;
        match outcome {
            SparseOutcome::Event(weight) => {
                self.estimator.push(weight, true);
                if explored {
                    let misses = || pass.surrogate_misses.is_some_and(|misses| misses(index));
                    self.outside.add(weight, misses);
                }
                if self.stops(pass.rule, pass.z, pass.mass) {
                    return Some(Decision::Converged);
                }
            }
            SparseOutcome::Invalid => self.invalid += 1,
        }
        (self.indices >= pass.rule.max_tests).then_some(Decision::Exhausted)
    }
}

/// The tally a fold of `0..to` keeps of its exploring tests, from the
/// span's `explored` tests and its stored `outcomes` (both sorted): the
/// valid exploring tests, their events and those events' weights summed in
/// index order, as [`PrefixFold::advance`] sums them.
pub fn outside_tally(
    explored: &[u64],
    outcomes: &[(u64, SparseOutcome)],
    surrogate_misses: &dyn Fn(u64) -> bool,
) -> OutsideTally {
    let mut tally = OutsideTally::default();
    let mut k = 0;
    for &index in explored {
        while k < outcomes.len() && outcomes[k].0 < index {
            k += 1;
        }
        match outcomes.get(k) {
            Some(&(i, SparseOutcome::Invalid)) if i == index => {}
            Some(&(i, SparseOutcome::Event(w))) if i == index => {
                tally.add(w, || surrogate_misses(index));
            }
            _ => tally.tests += 1,
        }
    }
    tally
}

/// One `advance`: the rule and what remains of the span's exploring tests.
struct Pass<'a> {
    rule: &'a StoppingRule,
    z: f64,
    mass: Option<&'a OutsideMass>,
    surrogate_misses: Option<&'a (dyn Fn(u64) -> bool + Sync)>,
    explored: &'a [u64],
}

impl Pass<'_> {
    fn consume_below(&mut self, bound: u64) {
        let k = self.explored.partition_point(|&e| e < bound);
        self.explored = &self.explored[k..];
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

    /// One test: invalid with probability 0.01, an event with probability
    /// `p_event` (of weight 0, a scenario without exposure, one time in
    /// five; else of weight in [0.01, 3)), else no event.
    fn random_outcome(rng: &mut ChaCha8Rng, p_event: f64) -> Option<Option<f64>> {
        let u: f64 = rng.random();
        if u < 0.01 {
            None
        } else if u < 0.01 + p_event {
            let impossible = rng.random::<f64>() < 0.2;
            Some(Some(if impossible {
                0.0
            } else {
                rng.random_range(0.01..3.0)
            }))
        } else {
            Some(None)
        }
    }

    /// A valid rule with random β, n_min, min_events and max_tests < `len`.
    fn random_rule(rng: &mut ChaCha8Rng, len: u64, guard_outside: bool) -> StoppingRule {
        StoppingRule {
            beta: rng.random_range(0.2..0.9),
            confidence: 0.9,
            n_min: rng.random_range(1..200),
            min_events: rng.random_range(0..5),
            max_tests: rng.random_range(200..len),
            guard_outside,
        }
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
                .map(|_| random_outcome(&mut rng, p_event))
                .collect();
            let rule = random_rule(&mut rng, len as u64, false);
            let z = rule.z();
            let reference = step_by_step(&rule, z, &tests);
            let mut fold = PrefixFold::default();
            let mut at = 0usize;
            while at < len {
                let to = (at + rng.random_range(1..400)).min(len);
                let stop = fold
                    .advance(&rule, z, to as u64, &sparse(&tests, at, to), None)
                    .unwrap();
                if stop.is_some() {
                    break;
                }
                at = to;
            }
            assert_eq!(fold, reference, "seed {seed}");
        }
    }

    /// The guarded reference: one test at a time, each either exploring or
    /// not, the rule and the guard checked after each.
    fn step_by_step_guarded(
        rule: &StoppingRule,
        z: f64,
        tests: &[(Option<Option<f64>>, bool)],
        mass: &OutsideMass,
    ) -> PrefixFold {
        let mut fold = PrefixFold::default();
        for (index, &(t, explores)) in tests.iter().enumerate() {
            fold.indices += 1;
            match t {
                Some(Some(w)) => {
                    fold.estimator.push(w, true);
                    if explores {
                        fold.outside.tests += 1;
                        if w > 0.0 {
                            fold.outside.events += 1;
                            fold.outside.s1 += w;
                            fold.outside.mismatches += u64::from(index % 3 == 0);
                        }
                    }
                }
                Some(None) => {
                    fold.estimator.push(0.0, false);
                    fold.outside.tests += u64::from(explores);
                }
                None => fold.invalid += 1,
            }
            let (s1, _) = fold.estimator.sums();
            let n = fold.estimator.tests();
            let guarded = !rule.guard_outside
                || fold
                    .outside
                    .guarded(mass, rule.confidence, rule.beta, s1, n);
            if (rule.converged(&fold.estimator, z) && guarded) || fold.indices >= rule.max_tests {
                break;
            }
        }
        fold
    }

    #[test]
    fn guarded_folds_in_any_chunking_equal_the_step_by_step_rule_to_the_bit() {
        let mut guard_mattered = 0;
        for seed in 0..300u64 {
            let mut rng = ChaCha8Rng::seed_from_u64(1000 + seed);
            let len = 4000;
            let p_event = rng.random_range(0.005..0.05);
            let epsilon = rng.random_range(0.05..0.5);
            let tests: Vec<(Option<Option<f64>>, bool)> = (0..len)
                .map(|_| {
                    let explores = rng.random::<f64>() < epsilon;
                    (random_outcome(&mut rng, p_event), explores)
                })
                .collect();
            let mass = if seed % 2 == 0 {
                OutsideMass::Proportional {
                    total: rng.random_range(0.01..2.0),
                }
            } else {
                OutsideMass::uniform((0..50).map(|_| rng.random_range(0.0..0.05)).collect())
            };
            let rule = random_rule(&mut rng, len as u64, true);
            let z = rule.z();
            let reference = step_by_step_guarded(&rule, z, &tests, &mass);
            let plain = step_by_step_guarded(
                &StoppingRule {
                    guard_outside: false,
                    ..rule
                },
                z,
                &tests,
                &mass,
            );
            guard_mattered += usize::from(plain.indices != reference.indices);
            let explored: Vec<u64> = (0..len as u64).filter(|&i| tests[i as usize].1).collect();
            let plain_tests: Vec<Option<Option<f64>>> = tests.iter().map(|t| t.0).collect();
            let mut fold = PrefixFold::default();
            let mut at = 0usize;
            while at < len {
                let to = (at + rng.random_range(1..400)).min(len);
                let span: Vec<u64> = explored
                    .iter()
                    .copied()
                    .filter(|&e| (at as u64..to as u64).contains(&e))
                    .collect();
                let exploration = Exploration {
                    explored: &span,
                    mass: &mass,
                    surrogate_misses: &|i| i % 3 == 0,
                };
                let stop = fold
                    .advance(
                        &rule,
                        z,
                        to as u64,
                        &sparse(&plain_tests, at, to),
                        Some(exploration),
                    )
                    .unwrap();
                if stop.is_some() {
                    break;
                }
                at = to;
            }
            assert_eq!(fold, reference, "seed {seed}");
            // Counting again from the stored outcomes gives the same tally.
            let upto = fold.indices;
            let stored = sparse(&plain_tests, 0, upto as usize);
            let span: Vec<u64> = explored.iter().copied().filter(|&e| e < upto).collect();
            assert_eq!(
                outside_tally(&span, &stored, &|i| i % 3 == 0),
                fold.outside,
                "seed {seed}"
            );
        }
        // The guard delayed the stop in a good share of the configurations.
        assert!(
            guard_mattered > 50,
            "the guard changed {guard_mattered} stops"
        );
    }

    #[test]
    fn exploring_tests_out_of_order_or_span_are_refused() {
        let rule = StoppingRule::new(0.2, 100);
        let mass = OutsideMass::Proportional { total: 1.0 };
        let mut fold = PrefixFold::default();
        for explored in [&[3u64, 3][..], &[5, 2], &[12]] {
            let err = fold.advance(
                &rule,
                rule.z(),
                10,
                &[],
                Some(Exploration {
                    explored,
                    mass: &mass,
                    surrogate_misses: &|_| false,
                }),
            );
            assert!(
                matches!(err, Err(FoldError::Explored { .. })),
                "{explored:?}"
            );
            assert_eq!(fold, PrefixFold::default());
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
            guard_outside: false,
        };
        let z = rule.z();
        let outcomes = sparse(&tests, 0, 2000);
        let mut seen = Vec::new();
        let mut fold = PrefixFold::default();
        let stop = fold
            .advance_observed(&rule, z, 2000, &outcomes, None, &mut |state| {
                seen.push(*state)
            })
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
                .advance(&rule, z, to as u64, &sparse(&tests, 0, to), None)
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
            guard_outside: false,
        };
        let z = rule.z();
        let events: Vec<_> = (0..10).map(|i| (i, SparseOutcome::Event(1.0))).collect();
        let mut fold = PrefixFold::default();
        let stop = fold.advance(&rule, z, 50, &events, None).unwrap();
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
            guard_outside: false,
        };
        let z = rule.z();
        let mut fold = PrefixFold::default();
        let invalid: Vec<_> = (0..3).map(|i| (i, SparseOutcome::Invalid)).collect();
        assert_eq!(fold.advance(&rule, z, 3, &invalid, None).unwrap(), None);
        assert_eq!(
            (fold.indices, fold.invalid, fold.estimator.tests()),
            (3, 3, 0)
        );
        let before = fold;
        let err = fold.advance(&rule, z, 4, &[(7, SparseOutcome::Invalid)], None);
        assert_eq!(
            err,
            Err(FoldError::OutOfSpan {
                index: 7,
                from: 3,
                to: 4
            })
        );
        let err = fold.advance(&rule, z, 5, &[(3, SparseOutcome::Event(f64::NAN))], None);
        assert!(matches!(err, Err(FoldError::BadWeight { index: 3, .. })));
        assert_eq!(fold, before);
        assert_eq!(
            fold.advance(&rule, z, 100, &[], None).unwrap(),
            Some(Decision::Exhausted)
        );
        assert_eq!((fold.indices, fold.estimator.tests()), (5, 2));
    }
}
