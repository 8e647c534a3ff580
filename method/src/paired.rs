//! Paired regression campaigns: two vehicles (today's build and
//! yesterday's) tested on the same test stream, so the difference of their
//! rates is estimated from the same draws.
//!
//! Test `i` gives each vehicle its importance-weighted outcome,
//! `aᵢ = w_{a,i} 1{A_a,i}` and `bᵢ = w_{b,i} 1{A_b,i}` (for a grid case the
//! scenario and weight are drawn before the vehicle runs, so `w_a = w_b = w`
//! and `dᵢ = w (y_a − y_b)`; for car-following each vehicle's trajectory
//! gives its own weight, and the pairing is common random numbers). `ā` and
//! `b̄` are the plain means `S₁/n` of the pair's tests (a library campaign
//! under the stratified split weights its two strata by their shares
//! instead, so its own estimate differs slightly), and
//!
//! ```text
//! Δ̂ = d̄ = ā − b̄,   s²_d = (Σ dᵢ² − n d̄²)/(n − 1),   h = z s_d / √n.
//! ```
//!
//! `Var(d) = Var(a) + Var(b) − 2 Cov(a, b)`: vehicles that fail on mostly the
//! same scenarios have a large covariance, so the paired interval is far
//! tighter than two independent campaigns' (`√(Var a/n + Var b/n)`);
//! [`PairedResult::independent_tests`] says how many tests those would
//! need for the same half-width.
//!
//! The campaign stops at the first `n ≥ n_min` with at least `min_events`
//! discordant tests (one vehicle failed, the other did not: the normal
//! interval of `d̄` rests on them as a single campaign's rests on its
//! events) where
//!
//! - **precision**: `h ≤ β · max(ā, b̄)`: the difference is known to within β
//!   of the larger rate (a regression smaller than that is not worth
//!   telling), or
//! - **significance**: the interval excludes zero, looked at only at
//!   `n_min · 2ᵏ` with confidence `1 − α/2^{k+1}` at the k-th look (α spent
//!   over the looks sums to at most α = 1 − c): stopping at the first
//!   interval that excludes zero, checked at every test, would call a
//!   difference between equal vehicles far more often than α.
//!
//! or at `max_tests` (exhausted). The α-spending bounds the `significant`
//! stops between equal vehicles; a `precision` stop's interval is at the
//! nominal level, so between equal vehicles an interval that excludes zero
//! at a stop of either kind happens with probability up to about 2α.

use crate::estimator::{z_for_confidence, StoppingRule};
use crate::registry::CampaignTests;
use rayon::prelude::*;
use serde::Serialize;

/// The running sums of a paired campaign.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PairedSums {
    /// Tests.
    pub n: u64,
    /// Events of vehicle a, of vehicle b, and tests where only one failed.
    pub events: (u64, u64, u64),
    /// `Σ a`, `Σ a²`.
    pub a: (f64, f64),
    /// `Σ b`, `Σ b²`.
    pub b: (f64, f64),
    /// `Σ d`, `Σ d²` with `d = a − b`.
    pub d: (f64, f64),
}

/// The mean and the variance of the mean from `(Σ x, Σ x²)` over `n`.
fn mean_and_variance((s1, s2): (f64, f64), n: u64) -> (f64, f64) {
    if n == 0 {
        return (0.0, 0.0);
    }
    let n = n as f64;
    let mean = s1 / n;
    let sample = if n > 1.0 {
        ((s2 - n * mean * mean) / (n - 1.0)).max(0.0)
    } else {
        0.0
    };
    (mean, sample / n)
}

impl PairedSums {
    /// Adds one test's weighted outcomes `a`, `b`.
    pub fn push(&mut self, a: f64, b: f64) {
        self.n += 1;
        self.add(a, b);
    }

    /// Adds the outcomes of a test already counted in `n`.
    fn add(&mut self, a: f64, b: f64) {
        let d = a - b;
        self.events.0 += u64::from(a > 0.0);
        self.events.1 += u64::from(b > 0.0);
        self.events.2 += u64::from((a > 0.0) != (b > 0.0));
        self.a = (self.a.0 + a, self.a.1 + a * a);
        self.b = (self.b.0 + b, self.b.1 + b * b);
        self.d = (self.d.0 + d, self.d.1 + d * d);
    }

    /// `(ā, b̄, Δ̂)` and their variances.
    pub fn estimates(&self) -> [(f64, f64); 3] {
        [self.a, self.b, self.d].map(|s| mean_and_variance(s, self.n))
    }

    /// Tests two independent campaigns would each need for the paired
    /// half-width at `n`: `n (Var a + Var b) / Var d` (estimated; `None`
    /// while `Var d` is 0).
    pub fn independent_tests(&self) -> Option<f64> {
        let [(_, va), (_, vb), (_, vd)] = self.estimates();
        (vd > 0.0).then(|| self.n as f64 * (va + vb) / vd)
    }
}

/// Why a paired campaign stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum PairedStop {
    /// The difference is known to within β of the larger rate.
    Precision,
    /// The difference's interval excludes zero at a look.
    Significant,
    /// `max_tests` reached first.
    Exhausted,
}

impl PairedStop {
    /// The stop's name on the wire and in the database.
    pub fn as_str(self) -> &'static str {
        match self {
            PairedStop::Precision => "precision",
            PairedStop::Significant => "significant",
            PairedStop::Exhausted => "exhausted",
        }
    }

    /// The stop named `s`, if it is one.
    pub fn parse(s: &str) -> Option<Self> {
        [
            PairedStop::Precision,
            PairedStop::Significant,
            PairedStop::Exhausted,
        ]
        .into_iter()
        .find(|stop| stop.as_str() == s)
    }
}

/// A paired campaign's result.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PairedResult {
    /// Why it stopped.
    pub stop: PairedStop,
    /// Tests run (the stop index + 1).
    pub tests: u64,
    /// Events of vehicle a, of vehicle b, and discordant tests.
    pub events: (u64, u64, u64),
    /// Vehicle a's estimate and interval.
    pub rate_a: (f64, f64, f64),
    /// Vehicle b's estimate and interval.
    pub rate_b: (f64, f64, f64),
    /// `Δ̂ = ā − b̄` and its interval at the campaign's confidence.
    pub difference: (f64, f64, f64),
    /// The confidence the stop at a significance look used (the
    /// difference's interval at that level excludes zero).
    pub look_confidence: Option<f64>,
    /// Tests two independent campaigns would each need for the same
    /// half-width of the difference.
    pub independent_tests: Option<f64>,
}

/// Whether `n` is a significance look (`n_min · 2ᵏ`), and its `k`.
fn look(n: u64, n_min: u64) -> Option<u32> {
    let first = n_min.max(1);
    (n >= first && n.is_multiple_of(first) && (n / first).is_power_of_two())
        .then(|| (n / first).trailing_zeros())
}

impl PairedSums {
    /// The result at `n` tests, stopped for `stop`.
    fn result(
        &self,
        rule: &StoppingRule,
        stop: PairedStop,
        look_confidence: Option<f64>,
    ) -> PairedResult {
        let z = rule.z();
        let interval = |(mean, var): (f64, f64)| {
            let h = z * var.sqrt();
            (mean, mean - h, mean + h)
        };
        let [a, b, d] = self.estimates();
        PairedResult {
            stop,
            tests: self.n,
            events: self.events,
            rate_a: interval(a),
            rate_b: interval(b),
            difference: interval(d),
            look_confidence,
            independent_tests: self.independent_tests(),
        }
    }

    /// The stop after the current test, if any; `indices` counts the tests
    /// resolved, valid or not (`max_tests` bounds them, as a single
    /// campaign's).
    fn decide(&self, rule: &StoppingRule, z: f64, indices: u64) -> Option<PairedResult> {
        // The difference's interval rests on the discordant tests (where only
        // one vehicle failed): at least `min_events` of them, as a single
        // campaign's interval rests on its events. Vehicles that never
        // differ run to `max_tests` and say so.
        let enough = self.n >= rule.n_min && self.events.2 >= rule.min_events;
        if enough {
            let [(a, _), (b, _), (d, vd)] = self.estimates();
            let h = z * vd.sqrt();
            if h <= rule.beta * a.max(b) {
                return Some(self.result(rule, PairedStop::Precision, None));
            }
            if let Some(k) = look(self.n, rule.n_min) {
                let alpha = (1.0 - rule.confidence) / 2f64.powi(k as i32 + 1);
                let level = 1.0 - alpha;
                if vd > 0.0 && d.abs() > z_for_confidence(level) * vd.sqrt() {
                    return Some(self.result(rule, PairedStop::Significant, Some(level)));
                }
            }
        }
        (indices >= rule.max_tests).then(|| self.result(rule, PairedStop::Exhausted, None))
    }

    /// Folds the tests `*indices..to` in index order, checking the rule
    /// after each index (a test either vehicle could not run changes only
    /// the count against `max_tests`): `outcomes` lists, in index order and
    /// inside the range, the tests where either vehicle had the event or
    /// could not run (every other test is valid with no event for both). A test either
    /// vehicle could not run does not count in `n`. Returns the stop, with
    /// `*indices` one past its test; the same outcomes give the same stop
    /// however they are cut into calls.
    pub fn advance(
        &mut self,
        rule: &StoppingRule,
        z: f64,
        indices: &mut u64,
        to: u64,
        outcomes: &[(u64, PairedOutcome)],
    ) -> Option<PairedResult> {
        debug_assert!(
            outcomes.windows(2).all(|w| w[0].0 < w[1].0)
                && outcomes.iter().all(|o| (*indices..to).contains(&o.0)),
            "outcomes out of order or outside {}..{to}",
            *indices
        );
        let mut listed = outcomes.iter().peekable();
        while *indices < to {
            let i = *indices;
            *indices += 1;
            match listed.next_if(|(j, _)| *j == i).map(|(_, o)| *o) {
                Some(PairedOutcome::Invalid) => {}
                Some(PairedOutcome::Weighted(a, b)) => {
                    self.n += 1;
                    self.add(a, b);
                }
                None => self.n += 1,
            }
            if let Some(result) = self.decide(rule, z, *indices) {
                return Some(result);
            }
        }
        None
    }

    /// The result of a campaign that stopped for `stop` (as stored: the
    /// look's confidence where the stop was a significance look).
    pub fn stopped(
        &self,
        rule: &StoppingRule,
        stop: PairedStop,
        look_confidence: Option<f64>,
    ) -> PairedResult {
        self.result(rule, stop, look_confidence)
    }
}

/// A test of a paired campaign that the fold must see: either vehicle had
/// the event (the weighted outcomes `aᵢ`, `bᵢ`), or either could not run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PairedOutcome {
    /// `(aᵢ, bᵢ)`, at least one of them non-zero.
    Weighted(f64, f64),
    /// One of the vehicles could not run the test: it counts for neither.
    Invalid,
}

/// Tests per parallel span.
const SPAN: u64 = 1024;
const FIRST_BATCH: u64 = 64;
const MAX_BATCH: u64 = 65_536;

/// The weighted outcomes `(i, a, b)` of the tests of `from..to` where either
/// vehicle had the event, in index order.
fn outcomes(
    a: &dyn CampaignTests,
    b: &dyn CampaignTests,
    from: u64,
    to: u64,
) -> Vec<(u64, f64, f64)> {
    let starts: Vec<u64> = (from..to).step_by(SPAN as usize).collect();
    starts
        .into_par_iter()
        .flat_map_iter(|start| {
            let end = (start + SPAN).min(to);
            let run = |tests: &dyn CampaignTests| {
                tests
                    .run_span(start, end)
                    .unwrap_or_else(|| (start..end).map(|i| tests.run(i)).collect())
            };
            let (ra, rb) = (run(a), run(b));
            (start..end)
                .zip(ra.into_iter().zip(rb))
                .filter(|(_, (x, y))| x.event || y.event)
                .map(|(i, (x, y))| {
                    let weighted =
                        |o: crate::registry::TestOutcome| if o.event { o.weight } else { 0.0 };
                    (i, weighted(x), weighted(y))
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// Runs the paired campaign of vehicles `a` and `b`: two campaigns' tests
/// built from the same plan (case, library, ε, seed) with their built-in
/// vehicles, so test `i` draws the same for both. The rule must be valid.
pub fn run_paired(
    a: &dyn CampaignTests,
    b: &dyn CampaignTests,
    rule: &StoppingRule,
) -> PairedResult {
    run_paired_outcomes(&|from, to| outcomes(a, b, from, to), rule)
}

/// [`run_paired`] on `outcomes(from, to)`: the tests of `from..to` where
/// either vehicle had the event, as `(i, aᵢ, bᵢ)` in index order.
pub fn run_paired_outcomes(
    outcomes: &(dyn Fn(u64, u64) -> Vec<(u64, f64, f64)> + Sync),
    rule: &StoppingRule,
) -> PairedResult {
    let z = rule.z();
    let mut sums = PairedSums::default();
    let mut indices = 0;
    let mut batch = FIRST_BATCH;
    loop {
        let to = (indices + batch).min(rule.max_tests);
        let listed: Vec<(u64, PairedOutcome)> = outcomes(indices, to)
            .into_iter()
            .map(|(i, a, b)| (i, PairedOutcome::Weighted(a, b)))
            .collect();
        if let Some(result) = sums.advance(rule, z, &mut indices, to, &listed) {
            return result;
        }
        batch = (batch * 2).min(MAX_BATCH);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sums_give_the_difference_of_the_means_and_the_paired_variance() {
        let mut s = PairedSums::default();
        for (a, b) in [(2.0, 2.0), (0.0, 1.0), (3.0, 0.0), (0.0, 0.0)] {
            s.push(a, b);
        }
        let [(a, _), (b, _), (d, vd)] = s.estimates();
        assert_eq!((a, b, d), (1.25, 0.75, 0.5));
        // d = 0, −1, 3, 0: mean 0.5, sample variance (10 − 4·0.25)/3 = 3.
        assert!((vd - 3.0 / 4.0).abs() < 1e-15);
        assert_eq!(s.events, (2, 2, 2));
    }

    #[test]
    fn advance_gives_the_same_stop_however_the_tests_are_cut() {
        let rule = StoppingRule {
            beta: 0.2,
            confidence: 0.9,
            n_min: 30,
            min_events: 10,
            max_tests: 100_000,
            guard_outside: false,
            interval: Default::default(),
        };
        // Vehicle a fails on every 7th test, b on every 11th; test 5 of
        // each 50 could not run.
        let outcome = |i: u64| match (i % 50 == 5, i.is_multiple_of(7), i.is_multiple_of(11)) {
            (true, _, _) => Some(PairedOutcome::Invalid),
            (_, false, false) => None,
            (_, a, b) => Some(PairedOutcome::Weighted(
                f64::from(u8::from(a)),
                f64::from(u8::from(b)),
            )),
        };
        let listed = |from: u64, to: u64| -> Vec<(u64, PairedOutcome)> {
            (from..to)
                .filter_map(|i| outcome(i).map(|o| (i, o)))
                .collect()
        };
        let whole = {
            let (mut sums, mut indices) = (PairedSums::default(), 0);
            let r = sums.advance(&rule, rule.z(), &mut indices, 100_000, &listed(0, 100_000));
            (r.expect("stops"), indices)
        };
        let mut sums = PairedSums::default();
        let mut indices = 0;
        let mut cut = None;
        for to in (7..100_000).step_by(13) {
            let from = indices;
            if let Some(r) = sums.advance(&rule, rule.z(), &mut indices, to, &listed(from, to)) {
                cut = Some((r, indices));
                break;
            }
        }
        assert_eq!(cut, Some(whole.clone()));
        // Invalid tests count for neither vehicle: n < indices.
        assert!(
            whole.0.tests < whole.1,
            "{} tests of {} indices",
            whole.0.tests,
            whole.1
        );
    }

    #[test]
    fn looks_are_at_n_min_times_powers_of_two() {
        let looks: Vec<(u64, u32)> = (1..=1000)
            .filter_map(|n| look(n, 100).map(|k| (n, k)))
            .collect();
        assert_eq!(looks, [(100, 0), (200, 1), (400, 2), (800, 3)]);
    }
}
