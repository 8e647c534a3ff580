//! A campaign's anytime-valid interval: the prefix fold ([`crate::prefix`])
//! with confidence sequences ([`crate::sequence`]) beside it, and the
//! stopping rule read on the sequence's interval.
//!
//! **Terms.** An NDD campaign's terms are its outcomes, in `[0, 1]`. A
//! library campaign's estimate `μ̂ = μ̂_in + μ̂_out` has two strata, each the
//! mean of its own terms: a library test's `(1 − ε) w A = (P/q_in) A`, an
//! exploring test's `ε w A = (P/q_out) A`, bounded by the stratum's largest
//! weight ([`TermBounds`]). Each stratum gets a sequence at level `α/2`, and
//! `[L_in + L_out, U_in + U_out]` holds at every `n` with probability at
//! least `1 − α` (a union bound). The stratum of each test is fixed before
//! it is drawn, so each sequence sees independent draws of its own
//! distribution, whatever the split.
//!
//! **Stopping.** The rule is the same as Wald's — `n ≥ n_min`, `min_events`
//! events, both strata tested, `μ̂ > 0` — with the relative half-width read
//! on the sequence: `(U − L)/2 ≤ β μ̂`. It is checked at every event and at
//! the settlements ([`crate::sequence::next_settlement`], counted in test
//! indices), where the sequences settle their zeros; those points depend on
//! the index and the outcomes alone, so the stop is the same however the
//! outcomes are handed in. With the guard, the outside's own sequence
//! bounds the failure mass outside the library: `U_out − μ̂_out ≤ β μ̂`.

use crate::estimator::{Decision, StoppingRule};
use crate::outside::OutsideMass;
use crate::prefix::{check_span, Exploration, FoldError, PrefixFold, SparseOutcome};
use crate::sequence::{next_settlement, BettingSequence, SequenceBounds};
use serde::{Deserialize, Serialize};

/// The largest term each of a campaign's sequences can see.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum TermBounds {
    /// One stream of terms `w A ≤ bound` (an NDD campaign: 1; a library
    /// campaign under the random split: its largest weight).
    Single(f64),
    /// A stratified library campaign: library terms `(1 − ε) w A ≤ inside`,
    /// exploring terms `ε w A ≤ outside`.
    Stratified {
        /// `max_{x∈Φ} P(x)/q_in(x)`.
        inside: f64,
        /// `max_{x∉Φ} P(x)/q_out(x)`.
        outside: f64,
    },
}

/// The prefix fold and its confidence sequences.
#[derive(Debug, Clone)]
pub struct AnytimeFold {
    /// The sums, the outside tally and the indices, as a Wald campaign
    /// keeps them (its own rule never stops it here).
    pub fold: PrefixFold,
    /// The single stream's sequence, or the library stratum's.
    first: BettingSequence,
    /// The exploring stratum's, with its ε.
    outside: Option<(f64, BettingSequence)>,
    /// The next index count at which the sequences settle.
    next: u64,
}

impl AnytimeFold {
    /// An empty fold for `rule` whose terms are bounded by `bounds`; `strata`
    /// is the ε the estimate stratifies on ([`PrefixFold::strata`]), which
    /// must be given exactly when `bounds` is stratified.
    pub fn new(rule: &StoppingRule, strata: Option<f64>, bounds: TermBounds) -> Self {
        let alpha = 1.0 - rule.confidence;
        let (first, outside) = match (bounds, strata) {
            (TermBounds::Stratified { inside, outside }, Some(epsilon)) => (
                BettingSequence::new(inside, alpha / 2.0, rule.beta),
                Some((
                    epsilon,
                    BettingSequence::new(outside, alpha / 2.0, rule.beta),
                )),
            ),
            (TermBounds::Single(bound), None) => {
                (BettingSequence::new(bound, alpha, rule.beta), None)
            }
            (bounds, strata) => panic!("bounds {bounds:?} with strata {strata:?}"),
        };
        Self {
            fold: PrefixFold::with_strata(strata),
            first,
            outside,
            next: next_settlement(0),
        }
    }

    /// `[L, U]` as of the last settlement, the upper end at most 1.
    pub fn bounds(&self) -> SequenceBounds {
        let first = self.first.bounds();
        match &self.outside {
            None => first,
            Some((_, outside)) => {
                let outside = outside.bounds();
                SequenceBounds {
                    low: first.low + outside.low,
                    high: (first.high + outside.high).min(1.0),
                }
            }
        }
    }

    /// The upper end of the exploring stratum's sequence: a bound on the
    /// failure mass outside the library that holds at every `n`.
    pub fn outside_upper(&self) -> Option<f64> {
        self.outside.as_ref().map(|(_, s)| s.bounds().high)
    }

    /// Whether a stratified campaign should switch now to exploring nearly
    /// every test ([`crate::sampling::allocated_explores`]): the rule's
    /// floors are met (`n ≥ n_min`, `min_events` events in the library
    /// stratum, both strata tested) and the library stratum's interval is
    /// within half of β, `(U_in − L_in)/2 ≤ (β/2) μ̂`. From then on what the
    /// campaign waits for is the exploring stratum's bound, and tests
    /// spent in the library would only narrow what is narrow already.
    /// Always `false` for a single stream.
    pub fn switch_due(&self, rule: &StoppingRule) -> bool {
        if self.outside.is_none() {
            return false;
        }
        let fold = &self.fold;
        let inside = self.first.bounds();
        let inside_events = fold.estimator.events() - fold.outside.events;
        fold.estimator.tests() >= rule.n_min
            && inside_events >= rule.min_events
            && fold.strata_ready()
            && fold.estimate() > 0.0
            && (inside.high - inside.low) / 2.0 <= rule.beta / 2.0 * fold.estimate()
    }

    /// Folds the tests `self.fold.indices..to` as [`PrefixFold::advance`]
    /// does, stopping where the rule, read on the sequences, first holds.
    pub fn advance(
        &mut self,
        rule: &StoppingRule,
        to: u64,
        outcomes: &[(u64, SparseOutcome)],
        exploration: Option<Exploration<'_>>,
    ) -> Result<Option<Decision>, FoldError> {
        self.advance_observed(rule, to, outcomes, exploration, &mut |_, _| {})
    }

    /// [`AnytimeFold::advance`], showing `observe` the prefix and the
    /// interval at each point where the sequences settled (a history can
    /// follow a long report's course). The final state is not shown.
    pub fn advance_observed(
        &mut self,
        rule: &StoppingRule,
        to: u64,
        outcomes: &[(u64, SparseOutcome)],
        exploration: Option<Exploration<'_>>,
        observe: &mut dyn FnMut(&PrefixFold, SequenceBounds),
    ) -> Result<Option<Decision>, FoldError> {
        let explored = exploration.map_or(&[][..], |e| e.explored);
        check_span(self.fold.indices, to, outcomes, explored)?;
        if self.fold.indices >= rule.max_tests {
            return Ok(Some(Decision::Exhausted));
        }
        // The prefix fold keeps the sums; it never converges on its own.
        let silent = StoppingRule {
            min_events: u64::MAX,
            guard_outside: false,
            ..*rule
        };
        let z = rule.z();
        let (mut next_outcome, mut next_explored) = (0, 0);
        while self.fold.indices < to.min(rule.max_tests) {
            let from = self.fold.indices;
            let mut end = to.min(rule.max_tests).min(self.next);
            if let Some(&(index, _)) = outcomes.get(next_outcome) {
                end = end.min(index + 1);
            }
            let piece = match outcomes.get(next_outcome) {
                Some(&(index, _)) if index < end => {
                    next_outcome += 1;
                    &outcomes[next_outcome - 1..next_outcome]
                }
                _ => &[],
            };
            let first_explored = next_explored;
            while explored.get(next_explored).is_some_and(|&e| e < end) {
                next_explored += 1;
            }
            let piece_explored = &explored[first_explored..next_explored];
            let decision = self.fold.advance(
                &silent,
                z,
                end,
                piece,
                exploration.map(|e| Exploration {
                    explored: piece_explored,
                    ..e
                }),
            )?;
            let mut settled = self.feed(end - from, piece, piece_explored);
            if end == self.next {
                self.first.settle();
                if let Some((_, outside)) = &mut self.outside {
                    outside.settle();
                }
                self.next = next_settlement(end);
                settled = true;
            }
            if settled && self.stops(rule, exploration) {
                return Ok(Some(Decision::Converged));
            }
            if decision.is_some() {
                return Ok(decision);
            }
            if settled {
                observe(&self.fold, self.bounds());
            }
        }
        Ok((self.fold.indices >= rule.max_tests).then_some(Decision::Exhausted))
    }

    /// Hands the sequences a piece of `len` tests: zeros, then its outcome
    /// (the piece's last test) if any. Whether an event settled a sequence.
    fn feed(&mut self, len: u64, outcome: &[(u64, SparseOutcome)], explored: &[u64]) -> bool {
        let last_explored = |index| explored.last() == Some(&index);
        let (outcome_inside, outcome_outside) = match outcome.first() {
            None => (0, 0),
            Some(&(index, _)) if last_explored(index) => (0, 1),
            Some(_) => (1, 0),
        };
        let outside_len = explored.len() as u64;
        match &mut self.outside {
            None => self.first.zeros(len - outcome_inside - outcome_outside),
            Some((_, outside)) => {
                self.first.zeros(len - outside_len - outcome_inside);
                outside.zeros(outside_len - outcome_outside);
            }
        }
        let Some(&(index, SparseOutcome::Event(weight))) = outcome.first() else {
            return false;
        };
        match &mut self.outside {
            None => self.first.term(weight),
            Some((epsilon, outside)) if last_explored(index) => outside.term(*epsilon * weight),
            Some((epsilon, _)) => self.first.term((1.0 - *epsilon) * weight),
        }
        weight > 0.0
    }

    /// The rule on the sequence: `n ≥ n_min`, `min_events` events, both
    /// strata tested, `μ̂ > 0`, `(U − L)/2 ≤ β μ̂`, and with the guard
    /// `U_out − μ̂_out ≤ β μ̂` (a random split: the prefix fold's guard).
    fn stops(&self, rule: &StoppingRule, exploration: Option<Exploration<'_>>) -> bool {
        let fold = &self.fold;
        let estimate = fold.estimate();
        let bounds = self.bounds();
        let converged = fold.estimator.tests() >= rule.n_min
            && fold.estimator.events() >= rule.min_events
            && fold.strata_ready()
            && estimate > 0.0
            && (bounds.high - bounds.low) / 2.0 <= rule.beta * estimate;
        if !converged || !rule.guard_outside {
            return converged;
        }
        match self.outside_upper() {
            Some(upper) => upper - fold.outside_estimate() <= rule.beta * estimate,
            None => fold.guard_holds(rule, exploration.map(|e| e.mass)),
        }
    }
}

/// The bound on the failure mass outside the library a campaign reports:
/// an anytime campaign's exploring-stratum upper end where it has one
/// (valid at every n), else the Clopper–Pearson bound of `mass` on `fold`'s
/// exploring tests ([`crate::outside`]); `None` without a library outside.
pub fn outside_bound(
    anytime: Option<&AnytimeFold>,
    fold: &PrefixFold,
    mass: Option<&OutsideMass>,
    confidence: f64,
) -> Option<f64> {
    match anytime.and_then(AnytimeFold::outside_upper) {
        Some(upper) => Some(upper),
        None => mass.map(|m| m.upper(fold.outside.tests, fold.outside.events, confidence)),
    }
}

#[cfg(test)]
mod tests;
