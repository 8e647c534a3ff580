//! The built-in cut-in exposure model: a parametric joint density of the
//! range `R` and range rate `Ṙ` at the cut-in moment, fitted by maximum
//! likelihood to the authors' SPMD cut-in table (≈415,000 events).
//!
//! `p(R, Ṙ) ∝ f(R) · g(Ṙ | R)` with
//! - range: `f(R) = (1 − exp(−(R/λ)^k)) · exp(−R/θ)`, a Weibull-shaped rise
//!   (few cut-ins into tiny gaps) and a slow exponential decay;
//! - range rate: a two-component mixture of asymmetric Laplace densities with
//!   a common mode `m(R) = m₀ + m₁R`,
//!   `g = w(R) AL(Ṙ − m; a(R), b(R)) + (1 − w(R)) AL(Ṙ − m; c(R), d(R))`,
//!   `AL(z; l, r) = exp(z/l)/(l + r)` for `z < 0` and `exp(−z/r)/(l + r)` otherwise,
//!   scales linear in `R` (`a = a₀ + a₁R`, …) and weight `w(R) = 1/(1 + exp(−(w₀ + w₁R)))`.
//!   The narrow component is the bulk of cut-ins at nearly equal speed; the
//!   wide one the heavy tails (fast approaches), which widen with range.
//!
//! The density is evaluated at each cell's values and normalised over the
//! grid. Fit quality against the table, on the table's own grid (checked by
//! `tests/cutin_paper.rs`): total variation distance 0.058, KL(table ‖ model)
//! 0.018 nats; the range marginal is within TV 0.029 and the range-rate
//! marginal within TV 0.020. The model is smooth, so unlike the table it gives
//! every cell some (tiny) exposure.

use crate::grid::{Axis, Grid};
use crate::mass::GridMass;

/// Fitted parameters (see the module documentation for the formula).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CutInExposureModel {
    /// Weibull shape k of the range's rise.
    pub k: f64,
    /// Weibull scale λ of the range's rise (m).
    pub lambda: f64,
    /// Decay length θ of the range (m).
    pub theta: f64,
    /// Intercept m₀ of the range-rate mode (m/s).
    pub m0: f64,
    /// Slope m₁ of the range-rate mode (1/s).
    pub m1: f64,
    /// `(a₀, a₁)`: left scale of the narrow component, `a = a₀ + a₁R` (m/s).
    pub a: (f64, f64),
    /// `(b₀, b₁)`: right scale of the narrow component (m/s).
    pub b: (f64, f64),
    /// `(c₀, c₁)`: left scale of the wide component (m/s).
    pub c: (f64, f64),
    /// `(d₀, d₁)`: right scale of the wide component (m/s).
    pub d: (f64, f64),
    /// `(w₀, w₁)`: logit of the narrow component's weight, `w₀ + w₁R`.
    pub w: (f64, f64),
}

impl Default for CutInExposureModel {
    /// The maximum-likelihood fit to the SPMD cut-in table.
    fn default() -> Self {
        Self {
            k: 2.330_026,
            lambda: 12.928_31,
            theta: 437.063_6,
            m0: -0.185_463_4,
            m1: -0.001_399_219,
            a: (0.217_353_5, 0.013_096_76),
            b: (0.715_411_2, 0.001_362_188),
            c: (0.773_304_7, 0.057_621_66),
            d: (2.581_134, 0.004_939_956),
            w: (0.812_871_6, -0.030_678_24),
        }
    }
}

fn asymmetric_laplace(z: f64, left: f64, right: f64) -> f64 {
    let tail = if z < 0.0 { z / left } else { -z / right };
    tail.exp() / (left + right)
}

impl CutInExposureModel {
    /// Unnormalised density at `(range, range_rate)`; zero for `R ≤ 0`.
    pub fn density(&self, range: f64, range_rate: f64) -> f64 {
        if range <= 0.0 {
            return 0.0;
        }
        let f = (1.0 - (-(range / self.lambda).powf(self.k)).exp()) * (-range / self.theta).exp();
        let linear = |(c0, c1): (f64, f64)| c0 + c1 * range;
        let z = range_rate - (self.m0 + self.m1 * range);
        let w = 1.0 / (1.0 + (-linear(self.w)).exp());
        let g = w * asymmetric_laplace(z, linear(self.a), linear(self.b))
            + (1.0 - w) * asymmetric_laplace(z, linear(self.c), linear(self.d));
        f * g
    }

    /// The model as a mass on a (range, range rate) grid whose ranges it
    /// reaches (the built-in grid).
    pub fn mass_on(&self, grid: Grid) -> GridMass {
        self.try_mass_on(grid)
            .expect("the density is positive on the built-in grid")
    }

    /// The model as a mass on any (range, range rate) grid: an error where
    /// its density underflows to 0 on every cell (ranges of kilometres and
    /// more: `exp(−R/θ)` with θ 437 m), as on a user's table far outside
    /// the SPMD data.
    pub fn try_mass_on(&self, grid: Grid) -> Result<GridMass, crate::mass::MassError> {
        assert_eq!(grid.dimensions(), 2, "the cut-in grid is two-dimensional");
        let weights = (0..grid.len())
            .map(|cell| self.density(grid.value(cell, 0), grid.value(cell, 1)))
            .collect();
        GridMass::from_weights(grid, weights)
    }
}

/// The default cut-in grid of the specification: cell centres of 2 m range
/// bins over (0, 90] (R = 1, 3, …, 89) and range rates −20, −19.6, …, 10 m/s:
/// 45 × 76 = 3,420 cells.
pub fn default_grid() -> Grid {
    Grid::new(vec![
        Axis::uniform("range", 1.0, 2.0, 45).expect("valid axis"),
        Axis::uniform("range_rate", -20.0, 0.4, 76).expect("valid axis"),
    ])
    .expect("valid grid")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_exposure_is_a_proper_mass_peaked_near_zero_range_rate() {
        let mass = CutInExposureModel::default().mass_on(default_grid());
        assert_eq!(mass.grid().len(), 3420);
        let g = mass.grid();
        let mode = (0..g.len())
            .max_by(|&a, &b| mass.p(a).total_cmp(&mass.p(b)))
            .unwrap();
        let v = g.values(mode);
        assert!(v[1].abs() <= 0.4, "mode range rate {}", v[1]);
        assert!((5.0..30.0).contains(&v[0]), "mode range {}", v[0]);
        // Fast approaches (Ṙ ≤ −10 m/s) are rare but present.
        let fast: f64 = (0..g.len())
            .filter(|&c| g.value(c, 1) <= -10.0)
            .map(|c| mass.p(c))
            .sum();
        // The SPMD table has 3.40% of cut-ins at Ṙ ≤ −10 m/s.
        assert!((0.030..0.038).contains(&fast), "fast approach mass {fast}");
    }
}
