//! A library's picture: two maps over the same two axes, the exposure and
//! what the library samples, so one sees at a glance which part of the
//! naturalistic scenarios the library concentrates on (paper Figs. 5, 9).
//! Grids of more than two dimensions are projected by summing over the
//! other axes.

use crate::grid::Grid;

/// One map: `values[i · y_centres.len() + j]` at `(x_centres[i], y_centres[j])`.
#[derive(Debug, Clone, PartialEq)]
pub struct PictureMap {
    /// The map's title.
    pub title: String,
    /// The horizontal axis's title, with its unit.
    pub x_label: String,
    /// The horizontal cell centres, ascending.
    pub x_centres: Vec<f64>,
    /// The vertical axis's title, with its unit.
    pub y_label: String,
    /// The vertical cell centres, ascending.
    pub y_centres: Vec<f64>,
    /// The values, `x_centres.len() × y_centres.len()` of them.
    pub values: Vec<f64>,
}

/// The most bins a picture has along an axis: finer axes are binned, so
/// a picture holds at most `MAX_BINS²` values and as many rectangles
/// whatever the grid (a user case may have 10⁷ values on one axis, whose
/// picture, x against itself, once asked for 8 TB).
pub const MAX_BINS: usize = 240;

/// An axis's values merged into at most [`MAX_BINS`] bins of consecutive
/// values: `bin(i) = ⌊i · bins / n⌋`, each drawn at the mean of its values.
struct Bins {
    n: usize,
    bins: usize,
    centres: Vec<f64>,
}

impl Bins {
    fn of(values: &[f64]) -> Self {
        let n = values.len();
        let bins = n.min(MAX_BINS);
        let mut sums = vec![(0.0, 0usize); bins];
        for (i, v) in values.iter().enumerate() {
            let b = &mut sums[i * bins / n];
            *b = (b.0 + v, b.1 + 1);
        }
        let centres = sums.iter().map(|(s, k)| s / *k as f64).collect();
        Self { n, bins, centres }
    }

    fn bin(&self, i: usize) -> usize {
        i * self.bins / self.n
    }
}

/// `values` over `grid` summed onto its axes `x` and `y` (binned to at most
/// [`MAX_BINS`] each): `m(a, b) = Σ_{cells with x in a, y in b} values(cell)`.
pub fn project(
    grid: &Grid,
    values: impl Fn(usize) -> f64,
    x: usize,
    y: usize,
    title: &str,
) -> PictureMap {
    let (ax, ay) = (&grid.axes()[x], &grid.axes()[y]);
    let (bx, by) = (Bins::of(ax.values()), Bins::of(ay.values()));
    let mut map = vec![0.0; bx.bins * by.bins];
    for cell in 0..grid.len() {
        let v = values(cell);
        if v != 0.0 {
            let (i, j) = (grid.axis_index(cell, x), grid.axis_index(cell, y));
            map[bx.bin(i) * by.bins + by.bin(j)] += v;
        }
    }
    PictureMap {
        title: title.to_owned(),
        x_label: ax.name().to_owned(),
        x_centres: bx.centres,
        y_label: ay.name().to_owned(),
        y_centres: by.centres,
        values: map,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Axis;

    /// A fine axis against itself (a one-dimension user case): binned to
    /// MAX_BINS² values, mass kept, on the diagonal only.
    #[test]
    fn a_fine_axis_is_binned_and_keeps_its_mass() {
        let n = 1_000_000;
        let grid = Grid::new(vec![Axis::uniform("x", 0.0, 1.0, n).unwrap()]).unwrap();
        let map = project(&grid, |cell| cell as f64, 0, 0, "m");
        assert_eq!(map.values.len(), MAX_BINS * MAX_BINS);
        assert_eq!(map.x_centres.len(), MAX_BINS);
        let total: f64 = map.values.iter().sum();
        assert_eq!(total, (n * (n - 1) / 2) as f64);
        for a in 0..MAX_BINS {
            for b in 0..MAX_BINS {
                assert_eq!(map.values[a * MAX_BINS + b] > 0.0, a == b);
            }
        }
        // The first bin holds the values 0 to 4166 (n/240 = 4166.7): its
        // centre is their mean.
        assert_eq!(map.x_centres[0], 2083.0);
    }

    #[test]
    fn projection_sums_over_the_other_axes() {
        let grid = Grid::new(vec![
            Axis::uniform("a", 0.0, 1.0, 2).unwrap(),
            Axis::uniform("b", 0.0, 1.0, 3).unwrap(),
            Axis::uniform("c", 0.0, 1.0, 4).unwrap(),
        ])
        .unwrap();
        // value = 100·a + 10·b + c at the cell's indices.
        let value = |cell: usize| {
            let i = |k| grid.axis_index(cell, k) as f64;
            100.0 * i(0) + 10.0 * i(1) + i(2)
        };
        let map = project(&grid, value, 0, 2, "m");
        assert_eq!((map.x_label.as_str(), map.y_label.as_str()), ("a", "c"));
        assert_eq!(map.values.len(), 8);
        // m(a, c) = Σ_b (100a + 10b + c) = 300a + 30 + 3c.
        for a in 0..2 {
            for c in 0..4 {
                assert_eq!(
                    map.values[a * 4 + c],
                    300.0 * a as f64 + 30.0 + 3.0 * c as f64
                );
            }
        }
        let total: f64 = (0..grid.len()).map(value).sum();
        assert_eq!(map.values.iter().sum::<f64>(), total);
    }
}
