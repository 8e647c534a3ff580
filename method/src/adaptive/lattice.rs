//! The lattice an adaptive campaign searches on a fine grid (issue 54).
//!
//! The search tests every untested neighbour of a seed (a failure or a near
//! miss), so it walks a failure region cell by cell: its cost is the
//! region's volume. In 4-D that is 80 neighbours a cell, and the highway
//! paper grid's 5 m and 1 m/s steps make a region of a few thousand
//! cells. The estimation stage does not need those cells tested, only a
//! support `K` that holds the failures (it samples `K` by exposure; any `K`
//! planned from past results keeps every stage unbiased). So on a fine grid
//! the search walks a coarser lattice, every `s`-th point of each axis, and
//! a seed puts its whole *block* (the cells nearest its lattice point) in
//! `K`: the search's cost is the region's volume in blocks, `sᵈ` times
//! fewer tests, and `K` holds whole blocks at the region's boundary, where
//! some cells fail and some do not (what the estimation stage's variance
//! pays for).
//!
//! The stride is the smallest power of two that leaves at most
//! [`MAX_LATTICE_POINTS`] lattice points: 1 (the grid itself, every cell
//! its own block) on cut-in's 3,420 cells and highway-exit's coarse 9,216,
//! 4 on the paper's 1,640,961 (its lattice is the coarse grid's 9,216
//! points).

use crate::grid::Grid;
use crate::mass::GridMass;
use std::collections::HashMap;

/// The most lattice points a search walks: a grid with more is searched on
/// a coarser lattice.
pub const MAX_LATTICE_POINTS: usize = 16_384;

/// Every `stride`-th point of each axis of a grid, and the blocks of cells
/// nearest to them.
#[derive(Debug, Clone)]
pub struct Lattice {
    stride: usize,
    /// Each axis's length.
    lengths: Vec<usize>,
}

impl Lattice {
    /// The lattice of `grid` ([`MAX_LATTICE_POINTS`]).
    pub fn of(grid: &Grid) -> Self {
        let lengths: Vec<usize> = grid.axes().iter().map(|a| a.len()).collect();
        let points = |s: usize| -> usize { lengths.iter().map(|&n| (n - 1) / s + 1).product() };
        let mut stride = 1;
        while points(stride) > MAX_LATTICE_POINTS && lengths.iter().any(|&n| n > stride) {
            stride *= 2;
        }
        Self::with_stride(grid, stride)
    }

    /// The lattice of every `stride`-th index of `grid`'s axes (1: the
    /// grid itself, every cell its own block).
    ///
    /// # Panics
    /// When `stride` is 0.
    pub fn with_stride(grid: &Grid, stride: usize) -> Self {
        assert!(stride > 0, "a lattice's stride is at least 1");
        Self {
            stride,
            lengths: grid.axes().iter().map(|a| a.len()).collect(),
        }
    }

    /// The stride: 1 when the grid itself is searched.
    pub fn stride(&self) -> usize {
        self.stride
    }

    /// The lattice index nearest to index `i` of an axis of `n` points.
    fn snap(&self, i: usize, n: usize) -> usize {
        let s = self.stride;
        let last = (n - 1) / s * s;
        ((i + s / 2) / s * s).min(last)
    }

    /// The lattice point (a cell of the grid) whose block holds `cell`.
    pub fn point(&self, grid: &Grid, cell: usize) -> usize {
        let index: Vec<usize> = grid
            .multi_index(cell)
            .into_iter()
            .zip(&self.lengths)
            .map(|(i, &n)| self.snap(i, n))
            .collect();
        grid.cell(&index)
    }

    /// The lattice points next to `point` (each index `±stride` or equal,
    /// not all equal): `3ᵈ − 1` inside the grid at most.
    pub fn neighbours(&self, grid: &Grid, point: usize) -> Vec<usize> {
        grid.neighbours_at(point, self.stride)
    }

    /// The cells whose lattice point is `point`, increasing.
    pub fn block(&self, grid: &Grid, point: usize) -> Vec<usize> {
        let base = grid.multi_index(point);
        // Per axis, the indices that snap to the point's.
        let ranges: Vec<(usize, usize)> = base
            .iter()
            .zip(&self.lengths)
            .map(|(&b, &n)| {
                let from = (0..=b).rev().take_while(|&i| self.snap(i, n) == b).last();
                let to = (b..n).take_while(|&i| self.snap(i, n) == b).last();
                (from.unwrap_or(b), to.unwrap_or(b))
            })
            .collect();
        let mut cells = Vec::new();
        let mut index: Vec<usize> = ranges.iter().map(|r| r.0).collect();
        loop {
            cells.push(grid.cell(&index));
            let mut k = index.len();
            loop {
                if k == 0 {
                    cells.sort_unstable();
                    return cells;
                }
                k -= 1;
                if index[k] < ranges[k].1 {
                    index[k] += 1;
                    break;
                }
                index[k] = ranges[k].0;
            }
        }
    }

    /// The exposure of every block with exposure, by lattice point (empty
    /// on stride 1, where a block is its cell): one pass over the grid in
    /// cell order, the per-axis snaps looked up.
    pub fn block_masses(&self, grid: &Grid, exposure: &GridMass) -> HashMap<usize, f64> {
        let mut masses = HashMap::new();
        if self.stride == 1 {
            return masses;
        }
        let snaps: Vec<Vec<usize>> = self
            .lengths
            .iter()
            .map(|&n| (0..n).map(|i| self.snap(i, n)).collect())
            .collect();
        let mut index = vec![0usize; self.lengths.len()];
        let mut snapped = index.clone();
        for cell in 0..grid.len() {
            let p = exposure.p(cell);
            if p > 0.0 {
                for (k, s) in snapped.iter_mut().enumerate() {
                    *s = snaps[k][index[k]];
                }
                *masses.entry(grid.cell(&snapped)).or_insert(0.0) += p;
            }
            // The next cell: the last axis varies fastest.
            for k in (0..index.len()).rev() {
                index[k] += 1;
                if index[k] < self.lengths[k] {
                    break;
                }
                index[k] = 0;
            }
        }
        masses
    }
}

/// The increasing union of two increasing lists.
pub fn merged(a: &[usize], b: &[usize]) -> Vec<usize> {
    let mut out = Vec::with_capacity(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        match a[i].cmp(&b[j]) {
            std::cmp::Ordering::Less => {
                out.push(a[i]);
                i += 1;
            }
            std::cmp::Ordering::Greater => {
                out.push(b[j]);
                j += 1;
            }
            std::cmp::Ordering::Equal => {
                out.push(a[i]);
                i += 1;
                j += 1;
            }
        }
    }
    out.extend_from_slice(&a[i..]);
    out.extend_from_slice(&b[j..]);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Axis;

    fn grid(lengths: &[usize]) -> Grid {
        Grid::new(
            lengths
                .iter()
                .enumerate()
                .map(|(k, &n)| {
                    Axis::new(format!("a{k}"), (0..n).map(|i| i as f64).collect()).unwrap()
                })
                .collect(),
        )
        .unwrap()
    }

    /// The highway paper grid's shape is searched on its coarse grid; the
    /// blocks tile the grid, each cell in the block of its lattice point.
    #[test]
    fn the_blocks_tile_the_grid_and_the_paper_grid_is_searched_on_the_coarse_one() {
        let paper = grid(&[61, 21, 61, 21]);
        let lattice = Lattice::of(&paper);
        assert_eq!(lattice.stride(), 4);
        let small = grid(&[13, 7]);
        assert_eq!(Lattice::of(&small).stride(), 1);
        let fine = grid(&[300, 300]);
        let lattice = Lattice::of(&fine);
        assert_eq!(lattice.stride(), 4, "75 × 75 = 5,625 points");
        let mut seen = vec![0u32; fine.len()];
        let points: std::collections::BTreeSet<usize> =
            (0..fine.len()).map(|c| lattice.point(&fine, c)).collect();
        for &p in &points {
            assert!(fine.multi_index(p).iter().all(|i| i % 4 == 0), "{p}");
            for c in lattice.block(&fine, p) {
                assert_eq!(lattice.point(&fine, c), p);
                seen[c] += 1;
            }
        }
        assert!(seen.iter().all(|&n| n == 1), "every cell in one block");
        assert_eq!(points.len(), 75 * 75);
        // An inner point has 8 neighbours at ±4; a corner 3.
        let inner = fine.cell(&[40, 40]);
        let mut n: Vec<Vec<usize>> = lattice
            .neighbours(&fine, inner)
            .iter()
            .map(|&c| fine.multi_index(c))
            .collect();
        n.sort();
        assert_eq!(n.len(), 8);
        assert_eq!(n[0], vec![36, 36]);
        assert_eq!(n[7], vec![44, 44]);
        assert_eq!(lattice.neighbours(&fine, 0).len(), 3);
        // The blocks' exposure, in one pass, is their cells' sum.
        let weights: Vec<f64> = (0..fine.len()).map(|c| ((c * 7919) % 13) as f64).collect();
        let mass = GridMass::from_weights(fine.clone(), weights).unwrap();
        let masses = lattice.block_masses(&fine, &mass);
        for &p in &points {
            let summed: f64 = lattice.block(&fine, p).iter().map(|&c| mass.p(c)).sum();
            assert!(
                (masses.get(&p).copied().unwrap_or(0.0) - summed).abs() < 1e-15,
                "{p}"
            );
        }
        // The last point's block runs to the axis's end: 299 snaps to 296.
        assert_eq!(
            lattice.point(&fine, fine.cell(&[299, 0])),
            fine.cell(&[296, 0])
        );
    }
}
