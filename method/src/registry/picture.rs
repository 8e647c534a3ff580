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

/// `values` over `grid` summed onto its axes `x` and `y`:
/// `m(a, b) = Σ_{cells with x = a, y = b} values(cell)`.
pub fn project(
    grid: &Grid,
    values: impl Fn(usize) -> f64,
    x: usize,
    y: usize,
    title: &str,
) -> PictureMap {
    let (ax, ay) = (&grid.axes()[x], &grid.axes()[y]);
    let mut map = vec![0.0; ax.len() * ay.len()];
    for cell in 0..grid.len() {
        let v = values(cell);
        if v != 0.0 {
            map[grid.axis_index(cell, x) * ay.len() + grid.axis_index(cell, y)] += v;
        }
    }
    PictureMap {
        title: title.to_owned(),
        x_label: ax.name().to_owned(),
        x_centres: ax.values().to_vec(),
        y_label: ay.name().to_owned(),
        y_centres: ay.values().to_vec(),
        values: map,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Axis;

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
