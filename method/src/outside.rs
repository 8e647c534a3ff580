//! How much failure mass can hide outside a library (SPEC §2.4, issue 9).
//!
//! The library estimate `μ̂ = μ̂_in + μ̂_out` learns about the scenarios
//! outside the library `Φ` only from the ε-share of tests drawn there. When
//! the vehicle fails where the surrogate found nothing critical, those tests
//! are rare and their weights large, so a campaign can meet `rₙ ≤ β` before
//! any of them has an event: a narrow interval far below the truth. The
//! figures here bound what those tests could still be hiding.
//!
//! **The bound.** A test that explores draws `x` from `q_out(x) = q(x)/ε`
//! on `X \ Φ`, and `μ_out = Σ_{x∉Φ} P(x) A(x) = E_{q_out}[r(x) A(x)]` with
//! `r = P/q_out`. Let `p = q_out({x ∉ Φ : A(x)})`, the chance that an
//! exploring test has the event. Among the sets of `q_out`-mass `p`, the one
//! with the most exposure takes the cells of largest `r` first, so
//!
//! `μ_out ≤ F(p)`, `F(p) = max { P(S) : S ⊆ X \ Φ, q_out(S) ≤ p }`,
//!
//! a concave, increasing "worst-case fill". With `k` events among `m`
//! exploring tests, the one-sided Clopper–Pearson bound `p ≤ p_U(k, m, c)`
//! holds with probability at least `c`, and `F` is increasing, so
//! `U = F(p_U)` bounds `μ_out` at confidence `c` whatever the vehicle does.
//! With no events `p_U = 1 − (1 − c)^{1/m}` (the "rule of three" at
//! c = 0.95). For the NDD spread `r ≡ P(X \ Φ)` and `F(p) = p P(X \ Φ)`:
//! then `μ_out/P(X \ Φ)` is exactly the binomial `p` and the bound is tight.
//! For the uniform spread `F` sums the largest outside exposures first: valid
//! but conservative when the vehicle fails in rare scenarios.
//!
//! The bound holds at a fixed number of tests; a campaign stops at a random
//! one, chosen by the inside tests mostly, so it is approximate there, as
//! the normal interval is (docs/statistics.md measures both).

use serde::{Deserialize, Serialize};
use statrs::distribution::{Beta, ContinuousCDF};

/// The worst-case fill `F(p)` of the scenarios outside a library.
#[derive(Debug, Clone, PartialEq)]
pub enum OutsideMass {
    /// `F(p) = p · total`: every exploring draw has `r = P(X \ Φ)`.
    Proportional {
        /// `P(X \ Φ)`, the exposure outside the library.
        total: f64,
    },
    /// `q_out` uniform over `cells` outside cells: `F(p)` is the exposure of
    /// the `p · cells` most exposed of them. `cumulative[j]` is the exposure
    /// of the `j` most exposed (only the cells with `P > 0` are kept).
    Uniform {
        /// Cells outside the library (with and without exposure).
        cells: usize,
        /// `cumulative[j]`: the exposure of the `j` most exposed outside cells.
        cumulative: Vec<f64>,
    },
}

impl OutsideMass {
    /// The fill of exposures `masses` of the outside cells under the uniform spread.
    pub fn uniform(mut masses: Vec<f64>) -> Self {
        let cells = masses.len();
        masses.retain(|&p| p > 0.0);
        masses.sort_by(|a, b| b.total_cmp(a));
        let mut cumulative = Vec::with_capacity(masses.len() + 1);
        let mut sum = 0.0;
        cumulative.push(0.0);
        for p in masses {
            sum += p;
            cumulative.push(sum);
        }
        OutsideMass::Uniform { cells, cumulative }
    }

    /// `P(X \ Φ)`: the exposure outside the library, `F(1)`.
    pub fn total(&self) -> f64 {
        match self {
            OutsideMass::Proportional { total } => *total,
            OutsideMass::Uniform { cumulative, .. } => *cumulative.last().unwrap_or(&0.0),
        }
    }

    /// `F(p)` for `p ∈ [0, 1]`.
    pub fn fill(&self, p: f64) -> f64 {
        let p = p.clamp(0.0, 1.0);
        match self {
            OutsideMass::Proportional { total } => p * total,
            OutsideMass::Uniform { cells, cumulative } => {
                let m = p * *cells as f64;
                let whole = (m.floor() as usize).min(cumulative.len() - 1);
                if whole + 1 >= cumulative.len() {
                    return cumulative[cumulative.len() - 1];
                }
                let next = cumulative[whole + 1] - cumulative[whole];
                cumulative[whole] + (m - whole as f64) * next
            }
        }
    }

    /// `U = F(p_U(k, m, c))`: the upper confidence bound on the failure mass
    /// outside the library after `events` events in `tests` exploring tests.
    pub fn upper(&self, tests: u64, events: u64, confidence: f64) -> f64 {
        self.fill(clopper_pearson_upper(events, tests, confidence))
    }
}

/// The one-sided Clopper–Pearson upper bound on a binomial proportion after
/// `k` successes in `m` trials at confidence `c`: the `c`-quantile of
/// `Beta(k + 1, m − k)`; `1 − (1 − c)^{1/m}` when `k = 0`, and 1 when
/// `k = m` (including `m = 0`: nothing is known).
pub fn clopper_pearson_upper(k: u64, m: u64, confidence: f64) -> f64 {
    if k >= m {
        return 1.0;
    }
    if k == 0 {
        return 1.0 - (1.0 - confidence).powf(1.0 / m as f64);
    }
    Beta::new(k as f64 + 1.0, (m - k) as f64)
        .expect("shape parameters are positive")
        .inverse_cdf(confidence)
}

/// The exploring tests of a campaign's prefix: those drawn outside the
/// library, their events and those events' weighted sum `S₁,out`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct OutsideTally {
    /// Valid tests drawn outside the library.
    pub tests: u64,
    /// Those with the event.
    pub events: u64,
    /// `S₁,out = Σ wᵢyᵢ` over them.
    pub s1: f64,
    /// `S₂,out = Σ (wᵢyᵢ)²` over them: the exploring stratum's variance
    /// for the within-strata half-width ([`crate::prefix::PrefixFold::within_strata`]).
    #[serde(default)]
    pub s2: f64,
    /// Those events in scenarios where the library's surrogate has no
    /// event: the vehicle fails where the surrogate does not.
    #[serde(default)]
    pub mismatches: u64,
}

impl OutsideTally {
    /// Counts one valid exploring test with the event and weight `weight`.
    /// Only an event of positive weight counts as an event (in `k` of the
    /// Clopper–Pearson bound and as a mismatch): a scenario of exposure 0
    /// carries no failure mass, so `μ_out = Σ P(x) A(x)` is unchanged when
    /// its events are left out, and `F` already skips such cells. Counting
    /// them made `U` tend to a constant on libraries whose outside holds
    /// many impossible failing cells, and the guard never held.
    /// `surrogate_misses` is asked only for such events.
    pub fn add(&mut self, weight: f64, surrogate_misses: impl FnOnce() -> bool) {
        self.tests += 1;
        if weight > 0.0 {
            self.events += 1;
            self.s1 += weight;
            self.s2 += weight * weight;
            self.mismatches += u64::from(surrogate_misses());
        }
    }

    /// The guard's test: `U − S₁,out/n ≤ β S₁/n`, i.e. the failure mass
    /// outside the library may exceed the part of the estimate already
    /// drawn from there by at most β times the estimate. `s1` and `n` are
    /// the whole estimator's.
    pub fn guarded(&self, mass: &OutsideMass, confidence: f64, beta: f64, s1: f64, n: u64) -> bool {
        let upper = mass.upper(self.tests, self.events, confidence);
        upper * n as f64 <= beta * s1 + self.s1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clopper_pearson_matches_known_values() {
        // No events: 1 − 0.1^{1/m}; m = 1 gives 0.9, m = 22 about 0.0993.
        assert!((clopper_pearson_upper(0, 1, 0.9) - 0.9).abs() < 1e-12);
        assert!(
            (clopper_pearson_upper(0, 22, 0.9) - (1.0 - 0.1f64.powf(1.0 / 22.0))).abs() < 1e-15
        );
        // k = 1 of m = 10 at 95 %: 0.3942 (the Beta(2, 9) 0.95-quantile).
        assert!((clopper_pearson_upper(1, 10, 0.95) - 0.394163).abs() < 1e-5);
        // k = 5 of m = 10 at 90 %: 0.73268 (Beta(6, 5), scipy.stats.beta.ppf).
        assert!((clopper_pearson_upper(5, 10, 0.9) - 0.732682).abs() < 1e-5);
        assert_eq!(clopper_pearson_upper(0, 0, 0.9), 1.0);
        assert_eq!(clopper_pearson_upper(3, 3, 0.9), 1.0);
    }

    #[test]
    fn clopper_pearson_covers_at_least_nominally_by_enumeration() {
        // P(p ≤ p_U(K, m)) summed over K ~ Binomial(m, p) exactly.
        for &m in &[5u64, 20, 60] {
            for &p in &[0.01f64, 0.05, 0.2, 0.5] {
                let mut cover = 0.0;
                for k in 0..=m {
                    let prob = statrs::function::factorial::binomial(m, k)
                        * p.powi(k as i32)
                        * (1.0 - p).powi((m - k) as i32);
                    if p <= clopper_pearson_upper(k, m, 0.9) {
                        cover += prob;
                    }
                }
                assert!(cover >= 0.9 - 1e-9, "m {m}, p {p}: {cover}");
            }
        }
    }

    #[test]
    fn the_uniform_fill_takes_the_most_exposed_cells_first() {
        // Five outside cells (one impossible): q_out = 0.2 each.
        let mass = OutsideMass::uniform(vec![0.1, 0.0, 0.4, 0.2, 0.3]);
        assert!((mass.total() - 1.0).abs() < 1e-15);
        assert_eq!(mass.fill(0.0), 0.0);
        assert!((mass.fill(0.2) - 0.4).abs() < 1e-15);
        // 1.5 cells: 0.4 + half of 0.3.
        assert!((mass.fill(0.3) - 0.55).abs() < 1e-15);
        assert!((mass.fill(0.8) - 1.0).abs() < 1e-15);
        assert!((mass.fill(1.0) - 1.0).abs() < 1e-15);
        // Every set of cells of q_out-mass p has at most F(p) exposure.
        let p = [0.1, 0.0, 0.4, 0.2, 0.3];
        for set in 0u32..32 {
            let chosen: Vec<usize> = (0..5).filter(|&i| set >> i & 1 == 1).collect();
            let exposure: f64 = chosen.iter().map(|&i| p[i]).sum();
            assert!(exposure <= mass.fill(0.2 * chosen.len() as f64) + 1e-15);
        }
        let proportional = OutsideMass::Proportional { total: 0.5 };
        assert_eq!(proportional.fill(0.25), 0.125);
    }

    #[test]
    fn events_without_exposure_do_not_count_against_the_bound() {
        // Ten outside cells, five of them impossible (P = 0); 200 exploring
        // tests, 20 with the event, all in impossible cells: no failure
        // mass is seen, so the bound is that of 0 events in 200 tests.
        let mass = OutsideMass::uniform(vec![0.1, 0.0, 0.2, 0.0, 0.3, 0.0, 0.1, 0.0, 0.3, 0.0]);
        let mut tally = OutsideTally::default();
        let mut asked = 0;
        for k in 0..200 {
            if k % 10 == 0 {
                tally.add(0.0, || {
                    asked += 1;
                    true
                });
            } else {
                tally.tests += 1;
            }
        }
        assert_eq!(
            (tally.tests, tally.events, tally.mismatches, asked),
            (200, 0, 0, 0)
        );
        let upper = mass.upper(tally.tests, tally.events, 0.9);
        assert_eq!(upper, mass.fill(1.0 - 0.1f64.powf(1.0 / 200.0)));
        // Had they counted, k = 20 of 200 would allow p ≈ 0.14: more than
        // the exposure of the most exposed outside cell.
        assert!(mass.upper(200, 20, 0.9) > 0.3);
        // An event of positive weight counts, and its mismatch is asked.
        tally.add(2.0, || true);
        assert_eq!(
            (tally.tests, tally.events, tally.s1, tally.mismatches),
            (201, 1, 2.0, 1)
        );
    }

    #[test]
    fn the_guard_compares_the_unseen_mass_with_beta_times_the_estimate() {
        let mass = OutsideMass::Proportional { total: 1.0 };
        // 300 exploring tests without events: U = 1 − 0.1^{1/300} ≈ 0.00765.
        let tally = OutsideTally {
            tests: 300,
            ..Default::default()
        };
        let u = mass.upper(300, 0, 0.9);
        assert!((u - 0.007646).abs() < 1e-5);
        // Estimate S₁/n = 0.05 with n = 3000: β μ̂ = 0.01 ≥ U.
        assert!(tally.guarded(&mass, 0.9, 0.2, 150.0, 3000));
        // Estimate 0.02: β μ̂ = 0.004 < U.
        assert!(!tally.guarded(&mass, 0.9, 0.2, 60.0, 3000));
    }
}
