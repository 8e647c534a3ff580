//! N-dimensional scenario grids.
//!
//! A scenario `x` is a point of a finite grid `X = A₁ × … × A_d`: one value per
//! axis. Cells are numbered in row-major order (the last axis varies fastest),
//! so a grid of 45 ranges × 76 range rates numbers cell `(i, j)` as `76 i + j`.

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Why an axis or grid could not be built.
#[derive(Debug, Error, PartialEq)]
pub enum GridError {
    /// An axis with no values.
    #[error("axis `{axis}` has no values")]
    EmptyAxis {
        /// The axis's name.
        axis: String,
    },
    /// A NaN or infinite axis value.
    #[error("axis `{axis}` value {index} is not finite ({value})")]
    NonFinite {
        /// The axis's name.
        axis: String,
        /// Position of the value on the axis.
        index: usize,
        /// The value.
        value: f64,
    },
    /// Axis values out of order or repeated.
    #[error("axis `{axis}` values must increase strictly, but value {index} ({value}) does not exceed the one before it ({previous})")]
    NotIncreasing {
        /// The axis's name.
        axis: String,
        /// Position of the value on the axis.
        index: usize,
        /// The value.
        value: f64,
        /// The value before it.
        previous: f64,
    },
    /// A grid without axes.
    #[error("a grid needs at least one axis")]
    NoAxes,
    /// More cells than a `usize` counts.
    #[error("the grid has {0} cells, more than the supported {max}", max = usize::MAX)]
    TooLarge(u128),
}

/// One dimension of a grid: a named, strictly increasing list of values.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Axis {
    name: String,
    values: Vec<f64>,
}

impl Axis {
    /// An axis with explicit values, e.g. the labels read from a table.
    pub fn new(name: impl Into<String>, values: Vec<f64>) -> Result<Self, GridError> {
        let name = name.into();
        if values.is_empty() {
            return Err(GridError::EmptyAxis { axis: name });
        }
        for (index, &value) in values.iter().enumerate() {
            if !value.is_finite() {
                return Err(GridError::NonFinite {
                    axis: name,
                    index,
                    value,
                });
            }
            if index > 0 && value <= values[index - 1] {
                return Err(GridError::NotIncreasing {
                    axis: name,
                    index,
                    value,
                    previous: values[index - 1],
                });
            }
        }
        Ok(Self { name, values })
    }

    /// `count` equally spaced values `start + k·step`, `k = 0 … count-1`.
    /// Values are computed from `k` (not accumulated) so they carry no drift.
    pub fn uniform(
        name: impl Into<String>,
        start: f64,
        step: f64,
        count: usize,
    ) -> Result<Self, GridError> {
        let values = (0..count).map(|k| start + step * k as f64).collect();
        Self::new(name, values)
    }

    /// The axis's name, with its unit.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The values (cell centres), strictly increasing.
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// Number of values.
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// Whether the axis has no values (never, once built).
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// The value at `index`.
    pub fn value(&self, index: usize) -> f64 {
        self.values[index]
    }

    /// Index of the value nearest to `value` (ties go to the lower index).
    pub fn nearest_index(&self, value: f64) -> usize {
        let upper = self.values.partition_point(|&v| v < value);
        if upper == 0 {
            return 0;
        }
        if upper == self.values.len() {
            return upper - 1;
        }
        if value - self.values[upper - 1] <= self.values[upper] - value {
            upper - 1
        } else {
            upper
        }
    }
}

/// A Cartesian product of axes with row-major cell numbering.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "GridRepr", into = "GridRepr")]
pub struct Grid {
    axes: Vec<Axis>,
    /// `strides[k]` = product of the lengths of the axes after `k`.
    strides: Vec<usize>,
    cells: usize,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct GridRepr {
    axes: Vec<Axis>,
}

impl TryFrom<GridRepr> for Grid {
    type Error = GridError;
    fn try_from(repr: GridRepr) -> Result<Self, GridError> {
        // Re-validate each axis: serde bypasses `Axis::new`.
        let axes = repr
            .axes
            .into_iter()
            .map(|a| Axis::new(a.name, a.values))
            .collect::<Result<Vec<_>, _>>()?;
        Grid::new(axes)
    }
}

impl From<Grid> for GridRepr {
    fn from(grid: Grid) -> Self {
        GridRepr { axes: grid.axes }
    }
}

impl Grid {
    /// The product grid of `axes` (row-major: the last axis varies fastest).
    pub fn new(axes: Vec<Axis>) -> Result<Self, GridError> {
        if axes.is_empty() {
            return Err(GridError::NoAxes);
        }
        // Checked: 130 axes of two values overflow even a u128 (a panic in
        // debug, a wrap to 0 in release), and a library file names its axes.
        let total = axes
            .iter()
            .try_fold(1u128, |n, a| n.checked_mul(a.len() as u128))
            .unwrap_or(u128::MAX);
        let cells = usize::try_from(total).map_err(|_| GridError::TooLarge(total))?;
        // Every stride divides `cells`, which fits: no product below overflows.
        let mut strides = vec![1; axes.len()];
        for k in (0..axes.len() - 1).rev() {
            strides[k] = strides[k + 1] * axes[k + 1].len();
        }
        Ok(Self {
            axes,
            strides,
            cells,
        })
    }

    /// The axes, in order.
    pub fn axes(&self) -> &[Axis] {
        &self.axes
    }

    /// Number of axes (the scenario's dimension).
    pub fn dimensions(&self) -> usize {
        self.axes.len()
    }

    /// `N(X)`, the number of cells.
    pub fn len(&self) -> usize {
        self.cells
    }

    /// Whether the grid has no cells (never, once built).
    pub fn is_empty(&self) -> bool {
        self.cells == 0
    }

    /// The per-axis indices of `cell`.
    pub fn multi_index(&self, cell: usize) -> Vec<usize> {
        self.strides
            .iter()
            .zip(&self.axes)
            .map(|(&stride, axis)| (cell / stride) % axis.len())
            .collect()
    }

    /// The cell at per-axis indices `index` (which must be in range).
    pub fn cell(&self, index: &[usize]) -> usize {
        debug_assert_eq!(index.len(), self.axes.len());
        index.iter().zip(&self.strides).map(|(i, s)| i * s).sum()
    }

    /// Index of `cell` along axis `axis`.
    pub fn axis_index(&self, cell: usize, axis: usize) -> usize {
        (cell / self.strides[axis]) % self.axes[axis].len()
    }

    /// The scenario values of `cell`, one per axis.
    pub fn values(&self, cell: usize) -> Vec<f64> {
        (0..self.axes.len())
            .map(|k| self.axes[k].value(self.axis_index(cell, k)))
            .collect()
    }

    /// Value of `cell` on axis `axis`.
    pub fn value(&self, cell: usize, axis: usize) -> f64 {
        self.axes[axis].value(self.axis_index(cell, axis))
    }

    /// The cell whose values are nearest to `values`, axis by axis.
    pub fn nearest_cell(&self, values: &[f64]) -> usize {
        let index: Vec<usize> = self
            .axes
            .iter()
            .zip(values)
            .map(|(axis, &v)| axis.nearest_index(v))
            .collect();
        self.cell(&index)
    }

    /// The Moore neighbourhood of `cell`: every cell whose per-axis indices
    /// differ by at most one (diagonals included), excluding `cell` itself.
    /// A grid of dimension d has up to 3ᵈ − 1 neighbours.
    pub fn neighbours(&self, cell: usize) -> Vec<usize> {
        self.neighbours_at(cell, 1)
    }

    /// The cells whose per-axis indices differ from `cell`'s by `-step`,
    /// 0 or `step` (not all 0): the Moore neighbourhood on the lattice of
    /// every `step`-th index (`adaptive::Lattice`).
    pub fn neighbours_at(&self, cell: usize, step: usize) -> Vec<usize> {
        assert!(step > 0, "neighbours at a step of at least 1");
        let base = self.multi_index(cell);
        let d = base.len();
        let step = step as i64;
        let mut out = Vec::with_capacity(3usize.pow(d as u32) - 1);
        let mut offset = vec![-1i64; d];
        loop {
            if offset.iter().any(|&o| o != 0) {
                let mut index = Vec::with_capacity(d);
                let inside = base
                    .iter()
                    .zip(&offset)
                    .zip(&self.axes)
                    .all(|((&b, &o), axis)| {
                        let i = b as i64 + o * step;
                        index.push(i.max(0) as usize);
                        i >= 0 && (i as usize) < axis.len()
                    });
                if inside {
                    out.push(self.cell(&index));
                }
            }
            // Odometer increment over {-1, 0, 1}^d.
            let mut k = d;
            loop {
                if k == 0 {
                    return out;
                }
                k -= 1;
                if offset[k] < 1 {
                    offset[k] += 1;
                    break;
                }
                offset[k] = -1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid_3x4() -> Grid {
        Grid::new(vec![
            Axis::uniform("a", 0.0, 1.0, 3).unwrap(),
            Axis::uniform("b", 10.0, 0.5, 4).unwrap(),
        ])
        .unwrap()
    }

    #[test]
    fn cells_are_row_major_and_round_trip() {
        let g = grid_3x4();
        assert_eq!(g.len(), 12);
        assert_eq!(g.cell(&[1, 2]), 6);
        assert_eq!(g.multi_index(6), vec![1, 2]);
        assert_eq!(g.values(6), vec![1.0, 11.0]);
        for c in 0..g.len() {
            assert_eq!(g.cell(&g.multi_index(c)), c);
        }
    }

    /// 130 axes of two values: 2¹³⁰ cells overflow a u128 (a panic in
    /// debug, a wrap to 0 in release): refused as too large. A library
    /// file's grid is read through here.
    #[test]
    fn a_product_past_any_integer_is_too_large() {
        let axes = vec![Axis::uniform("a", 0.0, 1.0, 2).unwrap(); 130];
        assert_eq!(Grid::new(axes).unwrap_err(), GridError::TooLarge(u128::MAX));
        let axes = vec![Axis::uniform("a", 0.0, 1.0, 2).unwrap(); 65];
        assert_eq!(Grid::new(axes).unwrap_err(), GridError::TooLarge(1 << 65));
    }

    #[test]
    fn moore_neighbours_at_corner_edge_and_interior() {
        let g = grid_3x4();
        let mut corner = g.neighbours(0);
        corner.sort();
        assert_eq!(corner, vec![1, 4, 5]);
        assert_eq!(g.neighbours(g.cell(&[1, 1])).len(), 8);
        assert_eq!(g.neighbours(g.cell(&[0, 1])).len(), 5);
    }

    #[test]
    fn nearest_index_rounds_to_the_closest_label() {
        let a = Axis::uniform("r", -20.0, 0.4, 76).unwrap();
        assert_eq!(a.nearest_index(-2.39), 44);
        assert_eq!(a.nearest_index(-100.0), 0);
        assert_eq!(a.nearest_index(100.0), 75);
    }

    #[test]
    fn bad_axes_are_rejected_with_the_place() {
        assert_eq!(
            Axis::new("r", vec![1.0, 1.0]),
            Err(GridError::NotIncreasing {
                axis: "r".into(),
                index: 1,
                value: 1.0,
                previous: 1.0
            })
        );
        assert!(matches!(
            Axis::new("r", vec![]),
            Err(GridError::EmptyAxis { .. })
        ));
        assert!(matches!(
            Axis::new("r", vec![f64::NAN]),
            Err(GridError::NonFinite { index: 0, .. })
        ));
    }
}
