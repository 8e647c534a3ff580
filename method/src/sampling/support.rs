//! The distribution of an adaptive campaign's estimation stage
//! ([`crate::adaptive`]): the exposure restricted to the support `K` with
//! share `1 − ε`, and restricted to the rest of the grid with share `ε`,
//! tests split between them by the stratified rule.
//!
//! `q(x) = (1 − ε) P(x)/P(K)` on `K` and `ε P(x)/P(X∖K)` off it, so every
//! weight `P/q` is one of two constants, `P(K)/(1 − ε)` and `P(X∖K)/ε`.
//!
//! The support changes as the campaign learns, so building a stage must
//! not cost what the grid costs: an alias table over `X∖K` would take
//! O(N) each time (about 30 µs on cut-in's 3,420 cells, milliseconds on
//! highway-exit's 1.6 × 10⁶; `method/benches/adaptive.rs`). Off `K`, a test
//! draws from the exposure's own alias table, built once per campaign, and
//! draws again while the cell lies in `K` (rejection sampling: accepted
//! with probability `P(X∖K)`). After [`MAX_REJECTIONS`] rejections, which
//! happens only when `K` holds most of the exposure, it draws exactly by a
//! scan of the cells off `K`. Either way the cell is distributed as `P`
//! restricted to `X∖K`, and depends on the test's random stream alone.

use super::draw::Draw;
use super::ndd::NddDistribution;
use super::share::stratified_explores;
use crate::mass::GridMass;
use crate::test_stream::{test_rng, TestRng};
use rand::Rng;
use std::sync::Arc;

/// Draws from the exposure before an exploring test falls back to a scan.
pub const MAX_REJECTIONS: usize = 64;

/// An estimation stage's distribution on its support.
#[derive(Debug, Clone)]
pub struct SupportDistribution {
    exposure: GridMass,
    /// The exposure's alias table, shared by every stage of a campaign.
    everywhere: Arc<NddDistribution>,
    /// The support's cells, increasing.
    support: Vec<usize>,
    /// `Σ P` over the support's first k + 1 cells: a draw inside is a
    /// binary search (O(log |K|)), and a new support costs one pass to
    /// build (an alias table would cost several).
    cumulative: Vec<f64>,
    /// `P(K)/(1 − ε)` and `P(X∖K)/ε`.
    inside_weight: f64,
    outside_weight: f64,
    /// The exploring share in force: 0 when nothing with exposure lies off
    /// the support.
    epsilon: f64,
}

impl SupportDistribution {
    /// The distribution on `support` (increasing cells with exposure, not
    /// empty) exploring the rest with share `epsilon`; `everywhere` is
    /// `exposure`'s own table and `exposed` its number of cells with
    /// exposure ([`GridMass::support_size`], counted once per campaign).
    ///
    /// # Panics
    /// When `support` is empty, not increasing, or holds a cell without
    /// exposure.
    pub fn new(
        exposure: &GridMass,
        everywhere: Arc<NddDistribution>,
        exposed: usize,
        support: Vec<usize>,
        epsilon: f64,
    ) -> Self {
        assert!(
            support.windows(2).all(|w| w[0] < w[1]),
            "the support is increasing"
        );
        assert!(!support.is_empty(), "a support with cells");
        let mut total = 0.0;
        let cumulative: Vec<f64> = support
            .iter()
            .map(|&c| {
                let p = exposure.p(c);
                assert!(p > 0.0, "support cells have exposure");
                total += p;
                total
            })
            .collect();
        let inside_mass = total;
        let outside_mass = (1.0 - inside_mass).max(0.0);
        // Explore only when a cell off the support has exposure (`1 − P(K)`
        // alone would leave rounding's 10⁻¹⁶ where nothing lies).
        let epsilon = if support.len() < exposed {
            epsilon
        } else {
            0.0
        };
        Self {
            exposure: exposure.clone(),
            everywhere,
            support,
            cumulative,
            inside_weight: inside_mass / (1.0 - epsilon),
            outside_weight: if epsilon > 0.0 {
                outside_mass / epsilon
            } else {
                0.0
            },
            epsilon,
        }
    }

    /// Test `index` of the campaign seeded `seed`.
    pub fn draw(&self, seed: u64, index: u64) -> Draw {
        self.draw_from(&mut test_rng(seed, index), index)
    }

    /// [`Self::draw`] from test `index`'s stream `rng`.
    pub fn draw_from(&self, rng: &mut TestRng, index: u64) -> Draw {
        if !stratified_explores(self.epsilon, index) {
            return Draw {
                cell: self.sample_inside(rng),
                weight: self.inside_weight,
            };
        }
        Draw {
            cell: self.sample_outside(rng),
            weight: self.outside_weight,
        }
    }

    /// Whether `cell` is in the support.
    pub fn contains(&self, cell: usize) -> bool {
        self.support.binary_search(&cell).is_ok()
    }

    /// The exploring share in force.
    pub fn epsilon(&self) -> f64 {
        self.epsilon
    }

    /// `P(X∖K)`, the exposure its exploring tests sample: 0 when nothing
    /// with exposure lies off the support (and no test explores).
    pub fn outside_exposure(&self) -> f64 {
        self.outside_weight * self.epsilon
    }

    /// A support cell, drawn from `P` restricted there: the first whose
    /// cumulative mass exceeds a uniform share of the total.
    fn sample_inside<R: Rng + ?Sized>(&self, rng: &mut R) -> usize {
        let total = self.cumulative[self.cumulative.len() - 1];
        let u = rng.random::<f64>() * total;
        let k = self.cumulative.partition_point(|&c| c <= u);
        self.support[k.min(self.support.len() - 1)]
    }

    /// A cell off the support, drawn from `P` restricted there.
    fn sample_outside<R: Rng + ?Sized>(&self, rng: &mut R) -> usize {
        for _ in 0..MAX_REJECTIONS {
            let cell = self.everywhere.sample(rng);
            if !self.contains(cell) {
                return cell;
            }
        }
        // The support holds most of the exposure: draw exactly by a scan.
        let off = |c: &usize| self.exposure.p(*c) > 0.0 && !self.contains(*c);
        let cells = 0..self.exposure.grid().len();
        let total: f64 = cells.clone().filter(off).map(|c| self.exposure.p(c)).sum();
        let mut u = rng.random::<f64>() * total;
        let mut last = 0;
        for c in cells.filter(off) {
            last = c;
            u -= self.exposure.p(c);
            if u < 0.0 {
                return c;
            }
        }
        last
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{Axis, Grid};

    /// A grid of 12 cells with uneven exposure.
    fn exposure() -> GridMass {
        let grid = Grid::new(vec![Axis::uniform("x", 0.0, 1.0, 12).unwrap()]).unwrap();
        let raw: Vec<f64> = (0..12).map(|c| 1.0 + c as f64).collect();
        let total: f64 = raw.iter().sum();
        GridMass::new(grid, raw.iter().map(|m| m / total).collect()).unwrap()
    }

    #[test]
    fn draws_follow_the_restricted_exposure_and_weigh_p_over_q() {
        let p = exposure();
        let everywhere = Arc::new(NddDistribution::new(&p));
        // A support holding most of the mass, so both the rejections and
        // the scan are exercised, and a small one.
        for support in [vec![1, 4, 7], (1..12).collect::<Vec<_>>()] {
            let d = SupportDistribution::new(&p, Arc::clone(&everywhere), 12, support.clone(), 0.1);
            let inside: f64 = support.iter().map(|&c| p.p(c)).sum();
            let n = 200_000u64;
            let mut counts = [0u64; 12];
            for i in 0..n {
                let draw = d.draw(3, i);
                counts[draw.cell] += 1;
                let q = if support.contains(&draw.cell) {
                    0.9 * p.p(draw.cell) / inside
                } else {
                    0.1 * p.p(draw.cell) / (1.0 - inside)
                };
                assert!((draw.weight - p.p(draw.cell) / q).abs() < 1e-12 * draw.weight);
                // Exactly the stratified share explores.
                assert_eq!(!support.contains(&draw.cell), stratified_explores(0.1, i));
            }
            for (c, &count) in counts.iter().enumerate() {
                let q = if support.contains(&c) {
                    0.9 * p.p(c) / inside
                } else {
                    0.1 * p.p(c) / (1.0 - inside)
                };
                let expected = n as f64 * q;
                let sd = (expected * (1.0 - q)).sqrt();
                assert!(
                    (count as f64 - expected).abs() < 5.0 * sd,
                    "cell {c}: {count} against {expected}"
                );
            }
        }
    }

    #[test]
    fn a_support_holding_every_exposed_cell_does_not_explore() {
        let p = exposure();
        let everywhere = Arc::new(NddDistribution::new(&p));
        let d = SupportDistribution::new(&p, everywhere, 12, (0..12).collect(), 0.1);
        assert_eq!(d.epsilon(), 0.0);
        for i in 0..100 {
            let draw = d.draw(1, i);
            assert!((draw.weight - 1.0).abs() < 1e-12);
        }
    }
}
