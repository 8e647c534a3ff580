//! The fewest tests a guarded campaign can expect on a noisy vehicle, were
//! it told every cell's failure rate: the ceiling of what any learning of
//! the support can reach, printed by `tslg exact` beside the NDD's tests.
//!
//! A guarded campaign (docs/statistics.md, "What the library leaves out")
//! samples a support `K` and rules out the failure mass off it with
//! exploring tests drawn by exposure. Its interval covers whatever the
//! vehicle does off `K`, and that is what it pays for: the guard's
//! Clopper–Pearson excess on the `m` exploring tests, `P_O (p_U(k, m) −
//! k/m)`, must fall within `β μ`, which takes about
//! `M ≈ ln(1/(1 − c)) P_O/(β μ)` exploring tests when nothing fails off
//! `K` ([`crate::adaptive::allocation`]). Told every cell's rate `p(x)`,
//! a campaign would choose `K` among the failing cells, sample it
//! ([`InsideSampling`]) by exposure as tslg's guard does (per-test variance
//! `A = P_K μ_K − μ_K²`) or by `q ∝ P(x) √p(x)` (`A = (Σ_K P √p)² − μ_K²`,
//! the least of any sampling of one run a test, which a campaign that
//! learned every rate could use), and explore share `ε` off it
//! (`B = P_O μ_O − μ_O²`), needing
//!
//! `n(K, ε) = max(M/ε, z² (A/(1 − ε) + B/ε)/(β μ)²)`
//!
//! tests. The floor is the least `n` over the shares a campaign may choose
//! and over the supports made of the cells with the highest rates (every
//! prefix of the cells sorted by rate, highest first): leaving a rarely
//! failing cell of much exposure out of a `K` sampled by exposure pays,
//! since `M` then bounds a small mass instead of the variance carrying it.
//! Cells that never fail are never in `K`: a support cell is one the
//! campaign samples, and a cell assumed safe untested is what the guard
//! exists to check. Other supports may do a little better (over every set
//! of failing cells of small random vehicles, by up to about 10 %), so the
//! figure is the best of a natural family, not a proven minimum.
//!
//! Against the NDD's `z² (1 − μ)/(β² μ)` tests, the exploring part alone is
//! `M/n_NDD ≈ ln(1/(1 − c)) β P_O/z²`, 0.17 `P_O` at β 0.2 and c 0.9: a
//! vehicle whose failing cells hold little exposure is tested at most
//! about `z²/(ln(1/(1 − c)) β)` ≈ 5.9 times faster than by the NDD, and one
//! whose failing cells hold much exposure gains less (sampled by exposure,
//! `n/n_NDD ≳ 0.17 P_O + P_K`: under a third of the NDD's tests only while
//! the failing cells hold less than about a fifth of the exposure).
//! A real campaign must also learn `K` from its own tests, which this floor
//! does not count: it is a floor, not a forecast.

use crate::adaptive::{guard_shares, AllocationInputs};
use rayon::prelude::*;

/// How a guarded campaign samples its support `K`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InsideSampling {
    /// By exposure, as tslg's guard does: `A = P_K μ_K − μ_K²`.
    Exposure,
    /// By `q ∝ P(x) √p(x)`, the rates known: `A = (Σ_K P √p)² − μ_K²`.
    RootRate,
}

/// The floor of both ways of sampling the support.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GuardFloors {
    /// Sampling the support by exposure, as tslg's guard does.
    pub exposure: GuardFloor,
    /// Sampling it by `P √p`.
    pub root_rate: GuardFloor,
}

impl GuardFloors {
    /// Both floors of `cells` (see [`guard_floor`]).
    pub fn of(cells: &[(f64, f64)], beta: f64, z: f64, confidence: f64) -> Option<Self> {
        Some(Self {
            exposure: guard_floor(cells, InsideSampling::Exposure, beta, z, confidence)?,
            root_rate: guard_floor(cells, InsideSampling::RootRate, beta, z, confidence)?,
        })
    }
}

/// The best guarded campaign of a vehicle whose rates are known.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GuardFloor {
    /// The tests it needs, `n(K, ε)` at the best support and share.
    pub tests: f64,
    /// The exposure of its support, `P_K`.
    pub support_exposure: f64,
    /// The share of the failure mass inside its support, `μ_K/μ`.
    pub support_failure_share: f64,
    /// The share of its tests that explores off the support, `ε`.
    pub exploring_share: f64,
}

/// The floor of a vehicle with cells of exposure `P(x)` and failure rate
/// `p(x)`, given as `(P, p)` pairs (cells without exposure are ignored);
/// `None` when it never fails (there is nothing to estimate) or when no
/// support makes the guard hold.
pub fn guard_floor(
    cells: &[(f64, f64)],
    inside: InsideSampling,
    beta: f64,
    z: f64,
    confidence: f64,
) -> Option<GuardFloor> {
    let total: f64 = cells.iter().map(|&(p, _)| p.max(0.0)).sum();
    // Exposure as a probability, whatever the grid's sum.
    let mut sorted: Vec<(f64, f64)> = cells
        .iter()
        .filter(|&&(p, _)| p > 0.0)
        .map(|&(p, rate)| (p / total, rate.clamp(0.0, 1.0)))
        .collect();
    let mu: f64 = sorted.iter().map(|&(p, rate)| p * rate).sum();
    if mu.is_nan() || mu <= 0.0 {
        return None;
    }
    // Highest rate first; among equal rates the least exposure first, so
    // that a prefix buys the most failure mass for its exposure.
    sorted.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.total_cmp(&b.0)));
    let failing = sorted.iter().take_while(|&&(_, rate)| rate > 0.0).count();
    // The prefix sums of exposure, failure mass and `P √p`, from the empty
    // support to the one holding every failing cell.
    let mut prefixes = Vec::with_capacity(failing + 1);
    let (mut exposure, mut mass, mut root) = (0.0, 0.0, 0.0);
    prefixes.push((exposure, mass, root));
    for &(p, rate) in &sorted[..failing] {
        exposure += p;
        mass += p * rate;
        root += p * rate.sqrt();
        prefixes.push((exposure, mass, root));
    }
    let scale = (z / (beta * mu)).powi(2);
    prefixes
        .into_par_iter()
        .filter_map(|(inside_exposure, inside_mass, root)| {
            let outside_mass = (1.0 - inside_exposure).max(0.0);
            let outside = (mu - inside_mass).max(0.0);
            let need = AllocationInputs {
                estimate: mu,
                outside_estimate: outside,
                outside_mass,
                beta,
                z,
                confidence,
            }
            .exploring_need()?;
            let second = match inside {
                InsideSampling::Exposure => inside_exposure * inside_mass,
                InsideSampling::RootRate => root * root,
            };
            let a = (second - inside_mass * inside_mass).max(0.0);
            let b = (outside_mass * outside - outside * outside).max(0.0);
            // Nothing off a support that holds every cell: nothing to explore.
            let shares: Vec<f64> = if outside_mass > 0.0 {
                guard_shares().collect()
            } else {
                vec![0.0]
            };
            shares
                .into_iter()
                .map(|epsilon| {
                    let tests = if epsilon > 0.0 {
                        let rule = scale * (a / (1.0 - epsilon) + b / epsilon);
                        (need as f64 / epsilon).max(rule)
                    } else {
                        scale * a
                    };
                    GuardFloor {
                        tests,
                        support_exposure: inside_exposure,
                        support_failure_share: inside_mass / mu,
                        exploring_share: epsilon,
                    }
                })
                .min_by(|x, y| x.tests.total_cmp(&y.tests))
        })
        .min_by(|x, y| x.tests.total_cmp(&y.tests))
}

#[cfg(test)]
mod tests {
    use super::*;

    const BETA: f64 = 0.2;
    const C: f64 = 0.9;
    const Z: f64 = 1.6448536269514722;
    const ROOT: InsideSampling = InsideSampling::RootRate;

    /// The fewest exploring tests with none failing whose Clopper–Pearson
    /// bound `1 − (1 − c)^{1/m}` times `P_O` is within `β μ`, by counting.
    fn zero_failure_need(outside_mass: f64, mu: f64) -> f64 {
        (1u64..)
            .find(|&m| outside_mass * (1.0 - (1.0 - C).powf(1.0 / m as f64)) <= BETA * mu)
            .unwrap() as f64
    }

    #[test]
    fn a_deterministic_failure_cell_is_the_support_and_the_guard_is_the_cost() {
        // One cell of exposure 0.01 always fails, the rest never: K is that
        // cell (A = 0: the support's tests all fail and carry P_K), nothing
        // fails off it (B = 0), so only the guard costs: M/0.95 tests.
        let floor = guard_floor(&[(0.01, 1.0), (0.99, 0.0)], ROOT, BETA, Z, C).unwrap();
        let need = zero_failure_need(0.99, 0.01);
        assert_eq!(need, 1139.0);
        assert!((floor.tests - need / 0.95).abs() < 1e-9, "{floor:?}");
        assert_eq!(floor.support_exposure, 0.01);
        assert_eq!(floor.support_failure_share, 1.0);
        assert_eq!(floor.exploring_share, 0.95);
    }

    #[test]
    fn exposure_is_taken_as_a_probability_whatever_its_sum() {
        let cells = [(0.002, 0.5), (0.01, 0.05), (0.3, 0.001), (0.688, 0.0)];
        let doubled: Vec<_> = cells.iter().map(|&(p, r)| (2.0 * p, r)).collect();
        let (a, b) = (
            guard_floor(&cells, ROOT, BETA, Z, C).unwrap(),
            guard_floor(&doubled, ROOT, BETA, Z, C).unwrap(),
        );
        assert!((a.tests - b.tests).abs() < 1e-6 * a.tests, "{a:?} {b:?}");
    }

    #[test]
    fn a_rarely_failing_cell_of_much_exposure_is_left_out_when_the_support_is_sampled_by_exposure()
    {
        // 0.3 of the exposure fails once in 10⁴ runs: 3 % of the failure
        // mass. Sampled by exposure inside K it would cost its exposure in
        // variance, so the guard bounds it instead (12,106 tests against
        // 28,988 with it inside, counted by the allocation's formula);
        // sampled by √p it costs little inside, and is taken in (9,467).
        let cells = [(0.001, 0.97), (0.3, 1e-4), (0.699, 0.0)];
        let mu = 0.001 * 0.97 + 0.3 * 1e-4;
        let by_exposure = guard_floor(&cells, InsideSampling::Exposure, BETA, Z, C).unwrap();
        assert_eq!(by_exposure.support_exposure, 0.001);
        assert!((by_exposure.support_failure_share - 0.00097 / mu).abs() < 1e-12);
        assert!(
            (by_exposure.tests - 12_106.3).abs() < 1.0,
            "{by_exposure:?}"
        );
        let by_root = guard_floor(&cells, InsideSampling::RootRate, BETA, Z, C).unwrap();
        assert!((by_root.support_exposure - 0.301).abs() < 1e-12);
        assert!((by_root.tests - 9_467.1).abs() < 1.0, "{by_root:?}");
    }

    #[test]
    fn spreading_the_same_failures_over_more_exposure_raises_the_floor() {
        // μ = 10⁻³ each time, on exposure 0.001, 0.01, 0.1, 0.5: the floor
        // rises, and against the NDD it never beats z²/(ln(1/(1 − c)) β).
        let ndd = Z * Z * (1.0 - 1e-3) / (BETA * BETA * 1e-3);
        let ceiling = Z * Z / ((1.0 / (1.0 - C)).ln() * BETA);
        let mut last = 0.0;
        for exposure in [0.001, 0.01, 0.1, 0.5] {
            let cells = [(exposure, 1e-3 / exposure), (1.0 - exposure, 0.0)];
            let floor = guard_floor(&cells, ROOT, BETA, Z, C).unwrap();
            assert!(floor.tests > last, "{exposure}: {floor:?}");
            assert!(ndd / floor.tests <= ceiling, "{exposure}: {floor:?}");
            last = floor.tests;
        }
        // Concentrated, it is near the ceiling; spread over half the
        // exposure, near the NDD.
        let concentrated = guard_floor(&[(0.001, 1.0), (0.999, 0.0)], ROOT, BETA, Z, C).unwrap();
        assert!(ndd / concentrated.tests > 0.9 * ceiling);
        assert!(ndd / last < 2.0, "{last}");
    }

    #[test]
    fn a_vehicle_that_never_fails_has_no_floor() {
        assert_eq!(
            guard_floor(&[(0.5, 0.0), (0.5, 0.0)], ROOT, BETA, Z, C),
            None
        );
        assert_eq!(guard_floor(&[], ROOT, BETA, Z, C), None);
    }
}
