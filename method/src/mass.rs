//! Probability mass over the cells of a grid: the exposure `P(x)` of the NDD.

use crate::grid::Grid;
use crate::tolerance::MASS_SUM_TOLERANCE;
use thiserror::Error;

/// Why a set of cell masses is not a probability mass function.
#[derive(Debug, Error, PartialEq)]
pub enum MassError {
    /// Not one mass per grid cell.
    #[error("expected {expected} cell masses for the grid, got {actual}")]
    WrongLength {
        /// Cells of the grid.
        expected: usize,
        /// Masses given.
        actual: usize,
    },
    /// A NaN or infinite mass.
    #[error("cell {cell} (values {values:?}) has mass {value}, which is not a finite number")]
    NotFinite {
        /// The cell's index.
        cell: usize,
        /// The cell's scenario values.
        values: Vec<f64>,
        /// The mass.
        value: f64,
    },
    /// A negative mass.
    #[error("cell {cell} (values {values:?}) has negative mass {value}")]
    Negative {
        /// The cell's index.
        cell: usize,
        /// The cell's scenario values.
        values: Vec<f64>,
        /// The mass.
        value: f64,
    },
    /// The masses do not sum to 1 within the tolerance.
    #[error("the masses sum to {sum}, which differs from 1 by more than {tolerance}")]
    SumOff {
        /// The total mass.
        sum: f64,
        /// The accepted distance from 1.
        tolerance: f64,
    },
}

/// A probability mass function on a grid, normalised to sum to exactly 1
/// (up to rounding). Construction checks every cell.
#[derive(Debug, Clone, PartialEq)]
pub struct GridMass {
    grid: Grid,
    /// Shared: a distribution built on the exposure (an adaptive
    /// campaign's estimation stage) clones it without copying the grid's
    /// masses.
    mass: std::sync::Arc<[f64]>,
    /// The sum of the masses as given, before renormalisation.
    original_sum: f64,
}

impl GridMass {
    /// Validates `mass` (finite, non-negative, one per cell, summing to 1 within
    /// [`MASS_SUM_TOLERANCE`]) and renormalises it to sum to 1.
    pub fn new(grid: Grid, mass: Vec<f64>) -> Result<Self, MassError> {
        Self::check_cells(&grid, &mass)?;
        let sum: f64 = mass.iter().sum();
        if (sum - 1.0).abs() > MASS_SUM_TOLERANCE {
            return Err(MassError::SumOff {
                sum,
                tolerance: MASS_SUM_TOLERANCE,
            });
        }
        Ok(Self::renormalised(grid, mass, sum))
    }

    /// Normalises non-negative weights (e.g. a density evaluated at the cells)
    /// into a mass function. Fails only on bad cells or a zero total.
    pub fn from_weights(grid: Grid, weights: Vec<f64>) -> Result<Self, MassError> {
        Self::check_cells(&grid, &weights)?;
        let sum: f64 = weights.iter().sum();
        if !(sum > 0.0 && sum.is_finite()) {
            return Err(MassError::SumOff {
                sum,
                tolerance: MASS_SUM_TOLERANCE,
            });
        }
        Ok(Self::renormalised(grid, weights, sum))
    }

    fn check_cells(grid: &Grid, mass: &[f64]) -> Result<(), MassError> {
        if mass.len() != grid.len() {
            return Err(MassError::WrongLength {
                expected: grid.len(),
                actual: mass.len(),
            });
        }
        for (cell, &value) in mass.iter().enumerate() {
            if !value.is_finite() {
                return Err(MassError::NotFinite {
                    cell,
                    values: grid.values(cell),
                    value,
                });
            }
            if value < 0.0 {
                return Err(MassError::Negative {
                    cell,
                    values: grid.values(cell),
                    value,
                });
            }
        }
        Ok(())
    }

    fn renormalised(grid: Grid, mut mass: Vec<f64>, sum: f64) -> Self {
        for m in &mut mass {
            *m /= sum;
        }
        Self {
            grid,
            mass: mass.into(),
            original_sum: sum,
        }
    }

    /// The grid the masses live on.
    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// `P(x)` for one cell.
    pub fn p(&self, cell: usize) -> f64 {
        self.mass[cell]
    }

    /// `P(x)` for every cell, in cell order.
    pub fn masses(&self) -> &[f64] {
        &self.mass
    }

    /// The sum of the masses as supplied; `1 - original_sum` is the deviation
    /// that renormalisation removed.
    pub fn original_sum(&self) -> f64 {
        self.original_sum
    }

    /// Whether renormalisation changed the masses by more than rounding.
    pub fn was_renormalised(&self) -> bool {
        (self.original_sum - 1.0).abs() > 1e-12
    }

    /// Number of cells with positive mass.
    pub fn support_size(&self) -> usize {
        self.mass.iter().filter(|&&m| m > 0.0).count()
    }

    /// A 64-bit FNV-1a hash of the grid values and the masses, written as
    /// hex. A library records the fingerprint of the exposure it was built
    /// on, so that a campaign cannot silently pair it with another exposure.
    pub fn fingerprint(&self) -> String {
        const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
        const PRIME: u64 = 0x0000_0100_0000_01b3;
        let mut hash = OFFSET;
        let mut feed = |x: f64| {
            for byte in x.to_bits().to_le_bytes() {
                hash ^= u64::from(byte);
                hash = hash.wrapping_mul(PRIME);
            }
        };
        for axis in self.grid.axes() {
            axis.values().iter().copied().for_each(&mut feed);
        }
        self.mass.iter().copied().for_each(&mut feed);
        format!("{hash:016x}")
    }

    /// Total variation distance `½ Σ |P(x) − Q(x)|` to another mass on the same grid shape.
    pub fn total_variation(&self, other: &GridMass) -> f64 {
        assert_eq!(self.mass.len(), other.mass.len(), "grids differ in size");
        0.5 * self
            .mass
            .iter()
            .zip(other.mass.iter())
            .map(|(a, b)| (a - b).abs())
            .sum::<f64>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Axis;

    fn line(n: usize) -> Grid {
        Grid::new(vec![Axis::uniform("x", 0.0, 1.0, n).unwrap()]).unwrap()
    }

    #[test]
    fn small_deviation_is_renormalised_and_reported() {
        let m = GridMass::new(line(2), vec![0.5, 0.50005]).unwrap();
        assert!(m.was_renormalised());
        assert!((m.masses().iter().sum::<f64>() - 1.0).abs() < 1e-15);
        assert!((m.original_sum() - 1.00005).abs() < 1e-15);
    }

    #[test]
    fn bad_masses_name_the_cell() {
        assert_eq!(
            GridMass::new(line(2), vec![0.5, 0.6]),
            Err(MassError::SumOff {
                sum: 1.1,
                tolerance: MASS_SUM_TOLERANCE
            })
        );
        assert!(matches!(
            GridMass::new(line(2), vec![1.5, -0.5]),
            Err(MassError::Negative { cell: 1, .. })
        ));
        assert!(matches!(
            GridMass::new(line(3), vec![1.0]),
            Err(MassError::WrongLength {
                expected: 3,
                actual: 1
            })
        ));
    }
}
