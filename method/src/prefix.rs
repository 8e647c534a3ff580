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
//!
//! A stratified library campaign ([`crate::sampling::Split::Stratified`])
//! estimates `μ̂ = (1 − ε) S₁,in/n_in + ε S₁,out/n_out` ([`PrefixFold::estimate`]).
//! Inside a zero run `n μ̂` is no longer constant (`n/n_in` and `n/n_out`
//! saw-tooth as the strata fill), so `rₙ` is not monotone there and the
//! first stopping index is searched for: the run is cut at its exploring
//! tests (between them `n_out` is fixed and `μ̂` falls) and each piece is
//! bisected with a bound that is exact on a single index
//! ([`PrefixFold::may_stop_between`]).

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
    /// The exploring share ε of a stratified library campaign, whose
    /// estimate weights the two strata by their shares
    /// ([`PrefixFold::estimate`]); `None`: the plain mean `S₁/n`.
    #[serde(default)]
    pub strata: Option<f64>,
    /// Whether a stratified campaign's half-width reads the within-strata
    /// variance ([`PrefixFold::half_width`]) rather than the pooled one: a
    /// guarded Wald campaign's, whose allocation leaves the proportional
    /// split once its library stratum is known ([`PrefixFold::switch_due`]).
    #[serde(default)]
    pub within_strata: bool,
}

/// The stratified estimate `(1 − ε) S₁,in/n_in + ε S₁,out/n_out` of `n`
/// valid tests with sums `s1`, of which `n_out` explored with sum `s1_out`.
///
/// Why it is unbiased: the wire weight is `w = P/q` with `q` the mixture
/// `(1 − ε) q_in + ε q_out`, so a library test's own stratum weight is
/// `P/q_in = (1 − ε) w` and an exploring test's `P/q_out = ε w`. Each
/// stratum's tests are independent draws of their own `q`, so given the
/// (deterministic) stratum sizes `(1 − ε) S₁,in/n_in` has mean
/// `μ_in = Σ_{x∈Φ} P(x)A(x)` and `ε S₁,out/n_out` mean `μ_out`. A stratum
/// without a test contributes 0 (and the rule waits for one,
/// [`PrefixFold::strata_ready`]).
pub fn stratified_estimate(epsilon: f64, s1: f64, n: u64, s1_out: f64, n_out: u64) -> f64 {
    let n_in = n.saturating_sub(n_out);
    let inside = if n_in > 0 {
        (1.0 - epsilon) * (s1 - s1_out).max(0.0) / n_in as f64
    } else {
        0.0
    };
    let outside = if n_out > 0 {
        epsilon * s1_out / n_out as f64
    } else {
        0.0
    };
    inside + outside
}

/// The relative rounding of a sum of up to 10⁷ terms in `f64`
/// (`n · 2⁻⁵³ ≈ 1.1 × 10⁻⁹`, Higham's bound), and of the grid enumeration
/// an estimate is compared with: the least relative half-width of a
/// within-strata interval ([`PrefixFold::half_width`]).
pub const ROUNDING: f64 = 1e-9;

/// Slack on the bound of [`PrefixFold::may_stop_between`]: the bound is
/// computed in other operations than the rule, so it must not exclude an
/// index the rule (with its own rounding) accepts.
const BOUND_SLACK: f64 = 1e-9;

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
        let explored = exploration.map_or(&[][..], |e| e.explored);
        check_span(self.indices, to, outcomes, explored)?;
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

    /// An empty fold whose estimate stratifies on `strata`
    /// ([`PrefixFold::strata`]).
    pub fn with_strata(strata: Option<f64>) -> Self {
        Self {
            strata,
            ..Self::default()
        }
    }

    /// An empty fold for a campaign of `rule` whose estimate stratifies on
    /// `strata`: a guarded Wald campaign's reads the within-strata variance
    /// ([`PrefixFold::within_strata`]).
    pub fn for_rule(rule: &StoppingRule, strata: Option<f64>) -> Self {
        Self {
            within_strata: strata.is_some()
                && rule.guard_outside
                && rule.interval == crate::estimator::Interval::Wald,
            ..Self::with_strata(strata)
        }
    }

    /// Adds one valid test with weight `weight` and outcome `event`, drawn
    /// outside the library when `explored`: the one-test step of
    /// [`PrefixFold::advance`] without the rule, for a curve that checks
    /// the interval at every `n` (no surrogate mismatch is counted).
    pub fn push(&mut self, weight: f64, event: bool, explored: bool) {
        self.indices += 1;
        self.estimator.push(weight, event);
        if explored {
            self.outside.add(if event { weight } else { 0.0 }, || false);
        }
    }

    /// `μ̂ₙ`: `S₁/n`, or for a stratified campaign
    /// [`stratified_estimate`] (0 before the first test).
    pub fn estimate(&self) -> f64 {
        match self.strata {
            None => self.estimator.estimate(),
            Some(epsilon) => {
                let (s1, _) = self.estimator.sums();
                let n = self.estimator.tests();
                stratified_estimate(epsilon, s1, n, self.outside.s1, self.outside.tests)
            }
        }
    }

    /// The part of `μ̂ₙ` drawn from the exploring tests: `S₁,out/n`, or
    /// `ε S₁,out/n_out` for a stratified campaign.
    pub fn outside_estimate(&self) -> f64 {
        match self.strata {
            None => self.outside.s1 / self.estimator.tests().max(1) as f64,
            Some(epsilon) if self.outside.tests > 0 => {
                epsilon * self.outside.s1 / self.outside.tests as f64
            }
            Some(_) => 0.0,
        }
    }

    /// The half-width `z sₙ/√n` with the pooled sample variance `sₙ²` of
    /// all terms `wᵢyᵢ` ([`ImportanceEstimator::half_width`]). For a
    /// stratified campaign this is conservative: the strata are allocated
    /// in proportion to their shares, and then the pooled variance is the
    /// within-strata variance (the stratified estimate's) plus the
    /// between-strata part `Σ_h π_h (m_h − m)²` (Cochran 1977, §5.6).
    /// The within-strata estimate alone collapses to 0 whenever the
    /// exploring stratum has no event yet: on the IDM's built-in library,
    /// which leaves 1.3 % of its failure mass outside, it covers 0.31 at
    /// n = 100 where the pooled one covers always (docs/statistics.md).
    ///
    /// A guarded campaign ([`PrefixFold::within_strata`]) reads the
    /// stratified estimate's own variance instead,
    /// `z √((1 − ε)² v_in/n_in + ε² v_out/n_out)` with `v_h` the sample
    /// variance of stratum `h`'s wire terms: once the campaign switches
    /// to exploring nearly every test the allocation is far from
    /// proportional, and the pooled variance understates the library
    /// stratum's part by about `(n_in/((1 − ε) n))²`. What the exploring
    /// stratum has not yet shown is the guard's to bound
    /// ([`PrefixFold::stops`]). Infinite until each stratum has 2 tests.
    ///
    /// The within-strata half-width is 0 where every library test has the
    /// same term and no exploring test failed (a library that holds
    /// exactly the vehicle's failures): the interval is then the estimate
    /// alone, and it is at least [`ROUNDING`] × `μ̂` so that it still holds
    /// the value its terms sum to in exact arithmetic.
    pub fn half_width(&self, z: f64) -> f64 {
        match (self.strata, self.within_strata) {
            (Some(epsilon), true) => {
                let half = z * self.within_strata_variance(epsilon).sqrt();
                half.max(ROUNDING * self.estimate())
            }
            _ => self.estimator.half_width(z),
        }
    }

    /// The strata's sums `((n_in, S₁,in, S₂,in), (n_out, S₁,out, S₂,out))`
    /// of the wire terms `wᵢyᵢ`.
    fn strata_sums(&self) -> ((u64, f64, f64), (u64, f64, f64)) {
        let (s1, s2) = self.estimator.sums();
        let out = &self.outside;
        let n_in = self.estimator.tests().saturating_sub(out.tests);
        (
            (n_in, (s1 - out.s1).max(0.0), (s2 - out.s2).max(0.0)),
            (out.tests, out.s1, out.s2),
        )
    }

    /// `Var(μ̂) ≈ (1 − ε)² v_in/n_in + ε² v_out/n_out` (infinite until each
    /// stratum has 2 tests).
    fn within_strata_variance(&self, epsilon: f64) -> f64 {
        let (inside, outside) = self.strata_sums();
        let part = |share: f64, (n, s1, s2): (u64, f64, f64)| {
            if n < 2 {
                return f64::INFINITY;
            }
            let n = n as f64;
            share * share * ((s2 - s1 * s1 / n) / (n - 1.0)).max(0.0) / n
        };
        part(1.0 - epsilon, inside) + part(epsilon, outside)
    }

    /// Whether a guarded Wald campaign should switch now to exploring
    /// nearly every test ([`crate::sampling::allocated_explores`]): the
    /// rule's floors are met (`n ≥ n_min`, `min_events` events in the
    /// library stratum, both strata tested, `μ̂ > 0`) and the library
    /// stratum's half-width is within half of β,
    /// `z (1 − ε) √(v_in/n_in) ≤ (β/2) μ̂`. From then on the campaign waits
    /// for the guard, which only exploring tests move. Always `false` for
    /// other campaigns.
    pub fn switch_due(&self, rule: &StoppingRule, z: f64) -> bool {
        let (Some(epsilon), true) = (self.strata, self.within_strata) else {
            return false;
        };
        let (inside, _) = self.strata_sums();
        let (n_in, s1, s2) = inside;
        let mean = self.estimate();
        let inside_events = self.estimator.events() - self.outside.events;
        if n_in < 2
            || self.estimator.tests() < rule.n_min
            || inside_events < rule.min_events
            || !self.strata_ready()
            || mean <= 0.0
        {
            return false;
        }
        let n = n_in as f64;
        let variance = ((s2 - s1 * s1 / n) / (n - 1.0)).max(0.0);
        z * (1.0 - epsilon) * (variance / n).sqrt() <= rule.beta / 2.0 * mean
    }

    /// `rₙ = half_width/μ̂ₙ`; infinite while `μ̂ₙ = 0`.
    pub fn relative_half_width(&self, z: f64) -> f64 {
        match self.strata {
            None => self.estimator.relative_half_width(z),
            Some(_) => {
                let mean = self.estimate();
                if mean > 0.0 {
                    self.half_width(z) / mean
                } else {
                    f64::INFINITY
                }
            }
        }
    }

    /// The interval `μ̂ₙ ± z sₙ/√n`, its lower end cut at 0
    /// ([`crate::estimator::probability_interval`]).
    pub fn interval(&self, z: f64) -> (f64, f64) {
        crate::estimator::probability_interval(self.estimate(), self.half_width(z))
    }

    /// Whether both strata of a stratified campaign have a valid test (the
    /// estimate has no part for an empty stratum); always for others.
    pub fn strata_ready(&self) -> bool {
        self.strata.is_none()
            || (self.outside.tests >= 1 && self.estimator.tests() > self.outside.tests)
    }

    /// [`StoppingRule::converged`] on this fold's estimate: `n ≥ n_min`,
    /// `min_events` events, both strata tested, `μ̂ₙ > 0` and `rₙ ≤ β`.
    pub fn converged(&self, rule: &StoppingRule, z: f64) -> bool {
        match self.strata {
            None => rule.converged(&self.estimator, z),
            Some(_) => {
                self.estimator.tests() >= rule.n_min
                    && self.estimator.events() >= rule.min_events
                    && self.strata_ready()
                    && self.estimate() > 0.0
                    && self.relative_half_width(z) <= rule.beta
            }
        }
    }

    /// Whether the rule stops here: [`PrefixFold::converged`] and, when the
    /// rule guards the outside, the guard of [`OutsideTally::guarded`].
    pub fn stops(&self, rule: &StoppingRule, z: f64, mass: Option<&OutsideMass>) -> bool {
        self.converged(rule, z) && self.guard_holds(rule, mass)
    }

    pub(crate) fn guard_holds(&self, rule: &StoppingRule, mass: Option<&OutsideMass>) -> bool {
        let (Some(mass), true) = (mass, rule.guard_outside) else {
            return true;
        };
        match self.strata {
            None => {
                let (s1, _) = self.estimator.sums();
                self.outside
                    .guarded(mass, rule.confidence, rule.beta, s1, self.estimator.tests())
            }
            Some(_) => {
                let upper = mass.upper(self.outside.tests, self.outside.events, rule.confidence);
                upper <= rule.beta * self.estimate() + self.outside_estimate()
            }
        }
    }

    /// The valid tests a guarded campaign needs, all told, before its
    /// guard `U − μ̂_out ≤ β μ̂` can hold, from the bound `upper` on its
    /// `m` exploring tests so far: with the events fixed the bound falls
    /// about as `1/m` (`ln(1/(1 − c))/m` with none), so it needs
    /// `m* = m U/(β μ̂ + μ̂_out)` exploring tests, `share` of each further
    /// test exploring ([`crate::sampling::LATE_SHARE`] once switched).
    /// `None` without the guard, an estimate or an exploring test; the
    /// tests so far when it holds already.
    pub fn tests_to_guard(&self, rule: &StoppingRule, upper: f64, share: f64) -> Option<u64> {
        let target = rule.beta * self.estimate() + self.outside_estimate();
        let m = self.outside.tests;
        let positive = |x: f64| x > 0.0;
        if !rule.guard_outside || !positive(target) || m == 0 || !positive(share) {
            return None;
        }
        let n = self.estimator.tests();
        if upper <= target {
            return Some(n);
        }
        let more = (m as f64 * upper / target - m as f64) / share;
        Some((n as f64 + more).min(1e15).ceil() as u64)
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
        if self.strata.is_some() {
            if first <= n0 + run {
                stop = self.stratified_stop(pass, first - n0, run);
            }
        } else if first <= n0 + run {
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

    /// The first state after `j ∈ [from, run]` more tests without the event
    /// at which a stratified campaign stops. The run is cut where `n_out`
    /// changes: state `j` holds the tests `indices..indices + j`, so an
    /// exploring test `e` enters at `j = e − indices + 1`.
    fn stratified_stop(&self, pass: &Pass<'_>, from: u64, run: u64) -> Option<PrefixFold> {
        if self.estimator.events() < pass.rule.min_events {
            return None;
        }
        let start = self.indices;
        let entered = |e: u64| e - start + 1;
        let mut k = pass.explored.partition_point(|&e| entered(e) <= from);
        let mut a = from;
        loop {
            let b = match pass.explored.get(k) {
                Some(&e) if entered(e) <= run => entered(e) - 1,
                _ => run,
            };
            if let Some(state) = self.search_piece(pass, a, b) {
                return Some(state);
            }
            if b == run {
                return None;
            }
            a = b + 1;
            k += 1;
        }
    }

    /// The first `j ∈ [a, b]` (a piece of a zero run with `n_out` fixed) at
    /// which the rule stops, by bisection pruned with
    /// [`PrefixFold::may_stop_between`].
    fn search_piece(&self, pass: &Pass<'_>, a: u64, b: u64) -> Option<PrefixFold> {
        if a > b {
            return None;
        }
        let low = self.after_zeros(a, pass.explored);
        if !low.may_stop_between(pass, b - a) {
            return None;
        }
        if a == b {
            return low.stops(pass.rule, pass.z, pass.mass).then_some(low);
        }
        let mid = a + (b - a) / 2;
        self.search_piece(pass, a, mid)
            .or_else(|| self.search_piece(pass, mid + 1, b))
    }

    /// Whether a stratified campaign could stop at this state or at one of
    /// the next `extra` tests without the event, none of them exploring.
    /// Over those `n ∈ [n₀, n₀ + extra]`: `μ̂` falls (only `n_in` grows), the
    /// guard's `U` is fixed, and the half-width `z √g(n)/n` with
    /// `g(n) = (n S₂ − S₁²)/(n − 1)` non-decreasing is at least
    /// `z √g(n₀)/(n₀ + extra)`. With `extra = 0` the bound is the rule
    /// itself, up to [`BOUND_SLACK`].
    fn may_stop_between(&self, pass: &Pass<'_>, extra: u64) -> bool {
        let rule = pass.rule;
        let n = self.estimator.tests();
        if !self.strata_ready() || n + extra < rule.n_min {
            return false;
        }
        let mean = self.estimate();
        if mean <= 0.0 {
            return false;
        }
        let least_half_width = match (self.strata, self.within_strata) {
            (Some(epsilon), true) => self.least_within_half_width(epsilon, pass.z, extra),
            _ if n >= 2 => {
                let (s1, s2) = self.estimator.sums();
                let g = ((n as f64 * s2 - s1 * s1) / (n as f64 - 1.0)).max(0.0);
                pass.z * g.sqrt() / (n + extra) as f64
            }
            _ => 0.0,
        };
        if least_half_width > rule.beta * mean * (1.0 + BOUND_SLACK) {
            return false;
        }
        match (pass.mass, rule.guard_outside) {
            (Some(mass), true) => {
                let upper = mass.upper(self.outside.tests, self.outside.events, rule.confidence);
                upper <= (rule.beta * mean + self.outside_estimate()) * (1.0 + BOUND_SLACK)
            }
            _ => true,
        }
    }

    /// A lower bound on the within-strata half-width over the next
    /// `extra` library tests without the event (`n_in` from `n₀` to
    /// `n₁ = n₀ + extra`, the exploring stratum fixed): the library part
    /// `(1 − ε)² (n S₂ − S₁²)/(n²(n − 1))` has a non-decreasing numerator,
    /// so it is at least `(1 − ε)² (n₀ S₂ − S₁²)/(n₁²(n₁ − 1))`; exact at
    /// `extra = 0`.
    fn least_within_half_width(&self, epsilon: f64, z: f64, extra: u64) -> f64 {
        let ((n_in, s1, s2), outside) = self.strata_sums();
        if n_in + extra < 2 || outside.0 < 2 {
            return f64::INFINITY;
        }
        let out_part = {
            let (n, s1, s2) = (outside.0 as f64, outside.1, outside.2);
            epsilon * epsilon * ((s2 - s1 * s1 / n) / (n - 1.0)).max(0.0) / n
        };
        let (n0, n1) = (n_in as f64, (n_in + extra) as f64);
        let in_part =
            (1.0 - epsilon).powi(2) * (n0 * s2 - s1 * s1).max(0.0) / (n1 * n1 * (n1 - 1.0));
        z * (in_part + out_part).sqrt()
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

/// Checks a span `from..to` handed to a fold: its outcomes and exploring
/// tests inside it and in strictly increasing order, event weights finite
/// and `≥ 0`.
pub(crate) fn check_span(
    from: u64,
    to: u64,
    outcomes: &[(u64, SparseOutcome)],
    explored: &[u64],
) -> Result<(), FoldError> {
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
    let mut previous = None;
    for &index in explored {
        if index < from || index >= to || previous.is_some_and(|p| index <= p) {
            return Err(FoldError::Explored { index, from, to });
        }
        previous = Some(index);
    }
    Ok(())
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
            interval: Default::default(),
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
                            fold.outside.s2 += w * w;
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

    /// Folds `tests` (exploring where `explored` says) onto `fold` in spans
    /// of random length, as reports arrive, until the rule stops; the
    /// surrogate misses every third test.
    fn fold_in_random_spans(
        mut fold: PrefixFold,
        rng: &mut ChaCha8Rng,
        rule: &StoppingRule,
        tests: &[Option<Option<f64>>],
        explored: &[u64],
        mass: &OutsideMass,
    ) -> PrefixFold {
        let len = tests.len();
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
                mass,
                surrogate_misses: &|i| i % 3 == 0,
            };
            let stop = fold
                .advance(
                    rule,
                    rule.z(),
                    to as u64,
                    &sparse(tests, at, to),
                    Some(exploration),
                )
                .unwrap();
            if stop.is_some() {
                break;
            }
            at = to;
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
            let fold = fold_in_random_spans(
                PrefixFold::default(),
                &mut rng,
                &rule,
                &plain_tests,
                &explored,
                &mass,
            );
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

    /// The stratified reference, written from the formulas alone: after
    /// each test the estimate `(1 − ε) S₁,in/n_in + ε S₁,out/n_out`, the
    /// pooled half-width (or with `within` the within-strata one,
    /// `z √((1 − ε)² v_in/n_in + ε² v_out/n_out)`) and the guard
    /// `U ≤ β μ̂ + ε S₁,out/n_out` are computed afresh from the lists of
    /// terms.
    fn step_by_step_stratified(
        rule: &StoppingRule,
        z: f64,
        (epsilon, within): (f64, bool),
        tests: &[(Option<Option<f64>>, bool)],
        mass: &OutsideMass,
    ) -> u64 {
        let part = |share: f64, terms: &[f64]| {
            let n = terms.len() as f64;
            let s1: f64 = terms.iter().sum();
            let s2: f64 = terms.iter().map(|x| x * x).sum();
            if n < 2.0 {
                f64::INFINITY
            } else {
                share * share * ((s2 - s1 * s1 / n) / (n - 1.0)).max(0.0) / n
            }
        };
        let (mut inside, mut outside) = (Vec::new(), Vec::new());
        for (index, &(t, explores)) in tests.iter().enumerate() {
            let indices = index as u64 + 1;
            if let Some(term) = t {
                let x = term.unwrap_or(0.0);
                if explores {
                    outside.push(x);
                } else {
                    inside.push(x);
                }
            }
            let (n_in, n_out) = (inside.len() as f64, outside.len() as f64);
            let n = n_in + n_out;
            let events = inside.iter().chain(&outside).filter(|&&x| x > 0.0).count();
            let out_events = outside.iter().filter(|&&x| x > 0.0).count();
            let (s1_in, s1_out) = (inside.iter().sum::<f64>(), outside.iter().sum::<f64>());
            let s2: f64 = inside.iter().chain(&outside).map(|x| x * x).sum();
            let s1 = s1_in + s1_out;
            let ready = n_in >= 1.0 && n_out >= 1.0;
            let mean = if ready {
                (1.0 - epsilon) * s1_in / n_in + epsilon * s1_out / n_out
            } else {
                0.0
            };
            let half = if within {
                z * (part(1.0 - epsilon, &inside) + part(epsilon, &outside)).sqrt()
            } else if n >= 2.0 {
                z * ((s2 - s1 * s1 / n) / (n - 1.0) / n).max(0.0).sqrt()
            } else {
                f64::INFINITY
            };
            let converged = n >= rule.n_min as f64
                && events as u64 >= rule.min_events
                && ready
                && mean > 0.0
                && half / mean <= rule.beta;
            let guarded = !rule.guard_outside
                || mass.upper(outside.len() as u64, out_events as u64, rule.confidence)
                    <= rule.beta * mean + epsilon * s1_out / n_out.max(1.0);
            if (converged && guarded) || indices >= rule.max_tests {
                return indices;
            }
        }
        tests.len() as u64
    }

    #[test]
    fn stratified_folds_in_any_chunking_stop_where_the_formulas_say() {
        let mut guard_mattered = 0;
        let mut stops_in_zero_runs = 0;
        let mut within_stops = 0;
        for seed in 0..400u64 {
            let mut rng = ChaCha8Rng::seed_from_u64(7000 + seed);
            let len = 4000;
            let epsilon = [0.05, 0.1, 0.3, 0.5][seed as usize % 4];
            // Guarded campaigns read the within-strata variance on every
            // other seed, half of them after a switch to exploring nearly
            // every test (the allocation: strata far from proportional).
            let within = seed % 4 == 2 || seed % 4 == 0 && seed % 8 == 0;
            let switch = (within && seed % 3 == 0).then(|| rng.random_range(0..len as u64 / 2));
            // Library tests are events often, exploring ones rarely (a
            // library that covers most of the failures).
            let p_in = rng.random_range(0.05..0.9);
            let p_out = rng.random_range(0.0..[0.05, 0.6][seed as usize % 3 / 2]);
            let tests: Vec<(Option<Option<f64>>, bool)> = (0..len as u64)
                .map(|i| {
                    let explores = crate::sampling::allocated_explores(epsilon, switch, i);
                    let p = if explores { p_out } else { p_in };
                    (random_outcome(&mut rng, p), explores)
                })
                .collect();
            let mass = OutsideMass::Proportional {
                total: rng.random_range(0.01..2.0),
            };
            let guard_outside = seed % 2 == 0;
            let rule = StoppingRule {
                beta: rng.random_range(0.05..0.5),
                min_events: rng.random_range(1..5),
                n_min: rng.random_range(1..100),
                ..random_rule(&mut rng, len as u64, guard_outside)
            };
            let z = rule.z();
            let reference = step_by_step_stratified(&rule, z, (epsilon, within), &tests, &mass);
            if guard_outside {
                let plain = StoppingRule {
                    guard_outside: false,
                    ..rule
                };
                let unguarded =
                    step_by_step_stratified(&plain, z, (epsilon, within), &tests, &mass);
                guard_mattered += usize::from(unguarded != reference);
            }
            let explored: Vec<u64> = (0..len as u64).filter(|&i| tests[i as usize].1).collect();
            let plain_tests: Vec<Option<Option<f64>>> = tests.iter().map(|t| t.0).collect();
            let fold = fold_in_random_spans(
                PrefixFold {
                    within_strata: within,
                    ..PrefixFold::with_strata(Some(epsilon))
                },
                &mut rng,
                &rule,
                &plain_tests,
                &explored,
                &mass,
            );
            assert_eq!(
                fold.indices, reference,
                "seed {seed} (ε {epsilon}, within strata {within})"
            );
            within_stops += usize::from(within && fold.indices < len as u64);
            let last = plain_tests[fold.indices as usize - 1];
            stops_in_zero_runs += usize::from(!matches!(last, Some(Some(_))));
        }
        // The search inside zero runs was exercised, and so was the guard.
        assert!(
            stops_in_zero_runs > 40,
            "{stops_in_zero_runs} zero-run stops"
        );
        assert!(
            guard_mattered > 10,
            "the guard changed {guard_mattered} stops"
        );
        assert!(within_stops > 40, "{within_stops} within-strata stops");
    }

    /// A library that holds exactly the vehicle's failures gives every
    /// library test the same term: the within-strata interval has no
    /// width but the rounding of the sums, and must still hold the exact
    /// mean (which it missed in 200 of 200 campaigns on the authors' table
    /// before the floor).
    #[test]
    fn an_exact_stratum_s_interval_holds_its_exact_value_despite_rounding() {
        let z = 1.645;
        let (mut missed_unfloored, mut tried) = (0, 0);
        for k in 1..200u32 {
            let term = 8.6621e-4 / 0.9 * (1.0 + f64::from(k) * 1e-3);
            let mut fold = PrefixFold {
                within_strata: true,
                ..PrefixFold::with_strata(Some(0.1))
            };
            for i in 0..14_150u64 {
                let explores = crate::sampling::stratified_explores(0.1, i);
                fold.push(if explores { 0.0 } else { term }, !explores, explores);
            }
            let exact = 0.9 * term;
            let (low, high) = fold.interval(z);
            assert!(
                low <= exact && exact <= high,
                "k {k}: [{low:e}, {high:e}] vs {exact:e}"
            );
            tried += 1;
            let mean = fold.estimate();
            missed_unfloored += usize::from(mean != exact);
        }
        // The rounding is real: without the floor many of these would miss.
        assert!(
            missed_unfloored > tried / 4,
            "{missed_unfloored} of {tried}"
        );
    }

    #[test]
    fn the_tests_a_guard_needs_scale_with_its_bound_over_its_target() {
        let rule = StoppingRule {
            guard_outside: true,
            ..random_rule(&mut ChaCha8Rng::seed_from_u64(1), 1 << 40, true)
        };
        let mass = OutsideMass::Proportional { total: 1.0 };
        // 1,000 tests, 100 exploring without an event, μ̂ = 1e-3: the bound
        // 1 − (1 − c)^{1/100} must fall to β μ̂.
        let mut fold = PrefixFold::with_strata(Some(0.1));
        for i in 0..1000u64 {
            fold.push(
                if i % 10 == 1 { 0.0 } else { 1e-3 / 0.9 },
                i % 10 != 1,
                i % 10 == 1,
            );
        }
        let upper = mass.upper(100, 0, rule.confidence);
        let target = rule.beta * fold.estimate();
        let needed = fold.tests_to_guard(&rule, upper, 0.95).unwrap();
        let exploring = 100.0 + (needed - 1000) as f64 * 0.95;
        // At that many exploring tests the exact bound is within a few
        // percent of the target (it falls a little faster than 1/m).
        let there = mass.upper(exploring as u64, 0, rule.confidence);
        assert!((there / target - 1.0).abs() < 0.05, "{there} vs {target}");
        // Without the guard, or once it holds, nothing more to say.
        let plain = StoppingRule {
            guard_outside: false,
            ..rule
        };
        assert_eq!(fold.tests_to_guard(&plain, upper, 0.95), None);
        assert_eq!(fold.tests_to_guard(&rule, 0.5 * target, 0.95), Some(1000));
    }

    #[test]
    fn the_stratified_split_puts_floor_n_epsilon_exploring_tests_in_every_prefix() {
        for epsilon in [1e-6, 0.013, 0.05, 0.1, 1.0 / 3.0, 0.5, 0.999] {
            let mut explored = 0u64;
            for n in 1..=20_000u64 {
                explored += u64::from(crate::sampling::stratified_explores(epsilon, n - 1));
                assert_eq!(
                    explored,
                    (n as f64 * epsilon).floor() as u64,
                    "ε {epsilon}, n {n}"
                );
            }
        }
        assert!(!crate::sampling::stratified_explores(0.0, 5));
    }

    #[test]
    fn a_stratified_estimate_weights_each_stratum_by_its_share() {
        // ε = 0.25: three library tests with terms 4, 0, 2 (stratum weight
        // (1 − ε)w: 3, 0, 1.5) and one exploring test with term 8 (ε w = 2):
        // μ̂ = 4.5/3 + 2/1 = 3.5, where the plain mean is 14/4 = 3.5 too, as
        // the strata hold exactly their shares. With a second library test
        // of term 0 the shares drift: plain 14/5 = 2.8, stratified
        // 4.5/4 + 2 = 3.125.
        let mut fold = PrefixFold::with_strata(Some(0.25));
        for (w, out) in [(4.0, false), (0.0, false), (2.0, false), (8.0, true)] {
            fold.estimator.push(w, w > 0.0);
            if out {
                fold.outside.add(w, || false);
            }
        }
        assert!((fold.estimate() - 3.5).abs() < 1e-15);
        fold.estimator.push(0.0, false);
        assert!((fold.estimate() - 3.125).abs() < 1e-15);
        assert!((fold.estimator.estimate() - 2.8).abs() < 1e-15);
        assert!((fold.outside_estimate() - 2.0).abs() < 1e-15);
        // No exploring test yet: the outside stratum is empty and the rule waits.
        let early = PrefixFold::with_strata(Some(0.25));
        assert!(!early.strata_ready());
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
            interval: Default::default(),
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
            interval: Default::default(),
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
            interval: Default::default(),
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
