//! The guard's allocation in an adaptive campaign: what share of each
//! estimation stage explores once the estimate is known but the bound on
//! the failure mass off the support is not yet within β.
//!
//! From the switch on the estimate starts again ([`super::AdaptiveState`]),
//! every stage exploring the same share ε. A stage of the support `K`
//! (exposure `P_K`) draws `(1 − ε) n` of its `n` tests by exposure in `K`,
//! each failing with probability `μ_in/P_K` and carrying `P_K`, and `ε n`
//! by exposure off `K` (mass `P_O = 1 − P_K`), carrying `P_O`. The campaign
//! stops when both hold:
//!
//! - **the rule**, `z √(A/((1 − ε) n) + B/(ε n)) ≤ β μ`, with each
//!   stratum's per-test variance `A = P_K μ_in − μ_in²` and
//!   `B = P_O μ_out − μ_out²`;
//! - **the guard**, `P_O (p_U(k, m) − k/m) ≤ β μ` on its `m = ε n`
//!   exploring tests, `k = m μ_out/P_O` of them failing (`p_U` the
//!   one-sided Clopper–Pearson bound at the campaign's confidence): it
//!   holds from `M` exploring tests, `M ≈ ln(1/(1 − c)) P_O/(β μ)` when
//!   nothing fails off `K`.
//!
//! With share ε the campaign thus needs
//!
//! `n(ε) = max(M/ε, z² (A/(1 − ε) + B/ε)/(β μ)²)`
//!
//! tests, and the share is the one that needs fewest, among the multiples
//! of 1/20 from 0.10 to 0.95 (a stage of a multiple of 20 tests then holds
//! exactly its share). Where `B` is negligible the best share is about
//! `M/(M + a)`, `a = z² A/(β μ)²`, and the tests `M + a`: the guard's
//! exploring tests plus what the support's own variance needs. A fixed
//! share of 0.95 (the library campaign's, [`crate::sampling::LATE_SHARE`])
//! leaves the support 5 % of the tests, which a noisy vehicle's support
//! (many cells that fail now and then, `P_K` near 0.1) needs twenty times
//! over: the noisy IDM at σ 1.5 then needed 444,230 tests, seven times the
//! NDD's (docs/statistics.md, "Noisy vehicles").
//!
//! The inputs are estimates from the tests before the switch, which the
//! restarted estimate does not use: the share is fixed by the past alone,
//! as every stage's plan is, so the estimate stays unbiased, and a share
//! off the optimum costs tests, never coverage.

use crate::outside::clopper_pearson_upper;

/// The shares the guard's stages may explore: `k/20` for `k` in 2..=19.
const SHARES: std::ops::RangeInclusive<u32> = 2..=19;

/// What the allocation reads at the switch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AllocationInputs {
    /// The estimate `μ̂` (positive: the rule held).
    pub estimate: f64,
    /// Its part from the exploring tests, `μ̂_out = S₁,out/n`.
    pub outside_estimate: f64,
    /// The exposure off the support, `P_O`.
    pub outside_mass: f64,
    /// β.
    pub beta: f64,
    /// The rule's `z`.
    pub z: f64,
    /// The rule's confidence `c` (of the guard's Clopper–Pearson bound).
    pub confidence: f64,
}

impl AllocationInputs {
    /// `M`: the fewest exploring tests from which the guard holds, when a
    /// share `μ_out/P_O` of them fails (found by doubling, then bisection:
    /// the excess `p_U(k, m) − k/m` falls with `m`); `None` when no number
    /// of tests up to 10¹² makes it hold.
    pub fn exploring_need(&self) -> Option<u64> {
        let target = self.beta * self.estimate;
        let off = self.outside_mass;
        if off <= 0.0 {
            return Some(0);
        }
        let rate = (self.outside_estimate / off).clamp(0.0, 1.0);
        let holds = |m: u64| {
            let k = (m as f64 * rate).round() as u64;
            off * (clopper_pearson_upper(k, m, self.confidence) - k as f64 / m as f64) <= target
        };
        // Double from below (the Beta inversions stay at the sizes the
        // answer has), then bisect within the last doubling.
        const LIMIT: u64 = 1_000_000_000_000;
        let mut hi = 1u64;
        while !holds(hi) {
            if hi >= LIMIT {
                return None;
            }
            hi = (hi * 2).min(LIMIT);
        }
        let mut lo = if hi == 1 { 1 } else { hi / 2 + 1 };
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            if holds(mid) {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        Some(lo)
    }

    /// `n(ε)`, the tests share `epsilon` needs (see the module).
    pub fn tests_needed(&self, epsilon: f64, exploring_need: u64) -> f64 {
        let inside = (self.estimate - self.outside_estimate).max(0.0);
        let outside = self.outside_estimate.max(0.0);
        let a = ((1.0 - self.outside_mass) * inside - inside * inside).max(0.0);
        let b = (self.outside_mass * outside - outside * outside).max(0.0);
        let scale = (self.z / (self.beta * self.estimate)).powi(2);
        let rule = scale * (a / (1.0 - epsilon) + b / epsilon);
        (exploring_need as f64 / epsilon).max(rule)
    }

    /// The share of each guard's stage that explores: the one of
    /// `0.10, 0.15, …, 0.95` that needs fewest tests (the larger on a tie);
    /// 0.95 when the guard cannot be met in any number of tests.
    pub fn guard_share(&self) -> f64 {
        let Some(need) = self.exploring_need() else {
            return share(*SHARES.end());
        };
        guard_shares()
            .rev()
            .min_by(|&x, &y| {
                self.tests_needed(x, need)
                    .total_cmp(&self.tests_needed(y, need))
            })
            .expect("shares to choose from")
    }
}

/// The shares a guard's stage may explore, `0.10, 0.15, …, 0.95`.
pub fn guard_shares() -> impl DoubleEndedIterator<Item = f64> {
    SHARES.map(share)
}

/// `k/20`.
fn share(k: u32) -> f64 {
    f64::from(k) / 20.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn inputs(estimate: f64, outside_estimate: f64, outside_mass: f64) -> AllocationInputs {
        AllocationInputs {
            estimate,
            outside_estimate,
            outside_mass,
            beta: 0.2,
            z: 1.6448536269514722,
            confidence: 0.9,
        }
    }

    #[test]
    fn the_exploring_need_is_the_first_m_where_the_guard_holds() {
        // Nothing failing off K: 1 − 0.1^{1/m} ≤ β μ / P_O, so
        // m ≥ ln(0.1)/ln(1 − β μ/P_O), about ln(10) P_O/(β μ).
        let x = inputs(1e-3, 0.0, 0.9);
        let need = x.exploring_need().unwrap();
        let exact = (0.1f64.ln() / (1.0f64 - 0.2 * 1e-3 / 0.9).ln()).ceil() as u64;
        assert_eq!(need, exact);
        assert!(
            (need as f64 - 10f64.ln() * 0.9 / 2e-4).abs() < 2.0,
            "{need}"
        );
        // With failures off K the excess over k/m falls more slowly: more
        // tests, and at m − 1 the guard does not hold yet.
        let y = inputs(1e-3, 3e-4, 0.9);
        let more = y.exploring_need().unwrap();
        assert!(more > need, "{more} vs {need}");
        let excess = |m: u64| {
            let k = (m as f64 * 3e-4 / 0.9).round() as u64;
            0.9 * (clopper_pearson_upper(k, m, 0.9) - k as f64 / m as f64)
        };
        assert!(excess(more) <= 2e-4 && excess(more - 1) > 2e-4);
        // Everything in K: nothing to rule out.
        assert_eq!(inputs(1e-3, 0.0, 0.0).exploring_need(), Some(0));
    }

    #[test]
    fn the_share_is_the_one_of_fewest_tests_by_enumeration() {
        for &(mu, out, mass) in &[
            (1e-3, 0.0, 0.99),
            (1.1e-3, 1e-5, 0.917),
            (6e-3, 1e-3, 0.7),
            (1e-3, 2e-4, 0.999),
            (5e-2, 0.0, 0.5),
        ] {
            let x = inputs(mu, out, mass);
            let need = x.exploring_need().unwrap();
            let chosen = x.guard_share();
            let fewest = (2..=19)
                .map(|k| x.tests_needed(k as f64 / 20.0, need))
                .fold(f64::INFINITY, f64::min);
            assert_eq!(x.tests_needed(chosen, need), fewest, "{mu} {out} {mass}");
            assert!((0.1..=0.95).contains(&chosen));
        }
    }

    #[test]
    fn a_support_with_much_exposure_gets_more_of_the_tests() {
        // A noisy vehicle's support: P_K 0.083, nearly every failure in it.
        // The guard's exploring need is about 2.3 P_O/(β μ) ≈ 9,300; the
        // support's variance needs z² P_K μ/(β μ)² ≈ 4,900 tests: the share
        // is about 9,300/(9,300 + 4,900), and the tests some 14,000, where
        // 0.95 needs 4,900/0.05 ≈ 98,000.
        let x = inputs(1.14e-3, 0.0, 0.917);
        let need = x.exploring_need().unwrap();
        let share = x.guard_share();
        assert!((0.6..=0.7).contains(&share), "{share}");
        let best = x.tests_needed(share, need);
        let late = x.tests_needed(0.95, need);
        assert!(best < 15_000.0 && late > 90_000.0, "{best} {late}");
        // A support of little exposure (a deterministic vehicle's failures)
        // explores nearly every test.
        assert_eq!(inputs(1e-3, 0.0, 0.999).guard_share(), 0.95);
    }
}
