//! Floors for coverage tests, from the binomial.
//!
//! A coverage test runs `n` seeded campaigns and counts the intervals that
//! cover the exact answer. With a method that covers at its nominal level
//! `p₀`, that count is `X ~ Binomial(n, p₀)`; the test's floor is the
//! largest `k` with `P(X < k | p₀) ≤ α`, so a sound method fails on a fresh
//! set of seeds with probability at most `α` (the seeds are fixed, so a
//! passing test passes on every run). The seed count is chosen so that a
//! real regression, coverage `p₁` (0.80 where 0.90 is nominal), falls
//! below the floor with probability `P(X < k | p₁) ≥ 0.95`: the test's
//! power, which [`CoverageCheck::new`] checks before any campaign runs.

use statrs::distribution::{Binomial, DiscreteCDF};

/// The largest `k` with `P(X < k) ≤ alpha` for `X ~ Binomial(runs,
/// nominal)`: the count of covering intervals a coverage test asserts.
pub fn coverage_floor(runs: u64, nominal: f64, alpha: f64) -> u64 {
    let x = Binomial::new(nominal, runs).expect("a probability and a count");
    // P(X < k) = P(X ≤ k − 1) grows with k; k = 0 always qualifies.
    (1..=runs)
        .take_while(|&k| x.cdf(k - 1) <= alpha)
        .last()
        .unwrap_or(0)
}

/// `P(X < floor)` for `X ~ Binomial(runs, coverage)`: the chance that a
/// method covering at `coverage` fails the test.
pub fn power_against(runs: u64, floor: u64, coverage: f64) -> f64 {
    if floor == 0 {
        return 0.0;
    }
    Binomial::new(coverage, runs)
        .expect("a probability and a count")
        .cdf(floor - 1)
}

/// A coverage test's plan: its runs, its floor, and the power it has.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoverageCheck {
    /// Seeded campaigns.
    pub runs: u64,
    /// The coverage the method claims.
    pub nominal: f64,
    /// The chance a sound method fails on a fresh set of seeds.
    pub alpha: f64,
    /// Covering intervals needed: [`coverage_floor`].
    pub floor: u64,
}

/// The regression every coverage test must catch: 0.10 below nominal.
pub const REGRESSION: f64 = 0.10;

/// The chance of catching it that the seed count must give.
pub const POWER: f64 = 0.95;

impl CoverageCheck {
    /// The floor of `runs` campaigns at `nominal` and `alpha`; panics
    /// (before any campaign runs) when the plan cannot catch a method
    /// covering [`REGRESSION`] below nominal with probability [`POWER`].
    pub fn new(runs: u64, nominal: f64, alpha: f64) -> Self {
        let floor = coverage_floor(runs, nominal, alpha);
        let power = power_against(runs, floor, nominal - REGRESSION);
        assert!(
            power >= POWER,
            "{runs} runs with floor {floor} catch coverage {:.2} with probability {power:.3} \
             only (< {POWER}): use more runs",
            nominal - REGRESSION
        );
        Self {
            runs,
            nominal,
            alpha,
            floor,
        }
    }

    /// Panics unless `covered` of the runs' intervals reach the floor.
    pub fn assert_covers(&self, covered: u64, what: &str) {
        assert!(
            covered >= self.floor,
            "{what}: {covered} of {} intervals cover; the floor at nominal {} (α {}) is {}",
            self.runs,
            self.nominal,
            self.alpha,
            self.floor
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The floor against a direct sum of binomial terms.
    #[test]
    fn the_floor_is_the_binomial_quantile() {
        fn below(n: u64, p: f64, k: u64) -> f64 {
            let mut term = (1.0 - p).powi(n as i32); // P(X = 0)
            let mut sum = 0.0;
            for j in 0..k {
                sum += term;
                term *= (n - j) as f64 / (j + 1) as f64 * p / (1.0 - p);
            }
            sum
        }
        for (n, p, alpha) in [(200, 0.9, 0.01), (60, 0.9, 0.01), (400, 0.8, 0.05)] {
            let k = coverage_floor(n, p, alpha);
            assert!(below(n, p, k) <= alpha, "{n} {p}: {k}");
            assert!(
                below(n, p, k + 1) > alpha,
                "{n} {p}: {k} is not the largest"
            );
            assert!((power_against(n, k, p - 0.1) - below(n, p - 0.1, k)).abs() < 1e-9);
        }
        // 200 runs at 0.90: a sound method reaches 170 but for 1 % of seed
        // sets; a method at 0.80 falls below it 95.7 % of the time (180 runs: 92 %).
        assert_eq!(coverage_floor(200, 0.9, 0.01), 170);
        assert!(power_against(200, 170, 0.8) >= 0.95);
    }

    /// 60 runs cannot tell 0.80 from 0.90; 200 can.
    #[test]
    fn too_few_runs_are_refused() {
        let refused = std::panic::catch_unwind(|| CoverageCheck::new(60, 0.9, 0.01));
        assert!(refused.is_err());
        let check = CoverageCheck::new(200, 0.9, 0.01);
        assert_eq!(check.floor, coverage_floor(200, 0.9, 0.01));
    }
}
