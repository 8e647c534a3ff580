//! Exhaustive search: the surrogate on every cell with positive exposure.
//! Cells with `P(x) = 0` have `V(x) = 0` without a simulation.

use super::definition::Evaluated;
use crate::case::{parallel_chunk, Case};
use crate::progress::Progress;
use rayon::prelude::*;

pub(crate) fn search<C: Case>(case: &C, surrogate: &C::Vehicle, progress: &Progress) -> Evaluated {
    let exposure = case.exposure();
    progress.start(exposure.grid().len() as u64);
    let all: Vec<usize> = (0..exposure.grid().len()).collect();
    // Chunks of cells in parallel, each in the case's batches.
    let (critical, evaluations) = all
        .par_chunks(parallel_chunk(all.len()))
        .map(|chunk| {
            let cells: Vec<usize> = chunk
                .iter()
                .copied()
                .filter(|&cell| exposure.p(cell) > 0.0)
                .collect();
            let mut challenges = vec![0.0; cells.len()];
            case.surrogate_challenges(surrogate, &cells, &mut challenges);
            progress.add(chunk.len() as u64);
            let found: Vec<(usize, f64)> = cells
                .iter()
                .zip(challenges)
                .filter_map(|(&cell, challenge)| {
                    let v = challenge * exposure.p(cell);
                    (v > 0.0).then_some((cell, v))
                })
                .collect();
            (found, cells.len())
        })
        .reduce(
            || (Vec::new(), 0),
            |(mut a, n), (b, m)| {
                a.extend(b);
                (a, n + m)
            },
        );
    Evaluated {
        critical,
        sm_evaluations: evaluations,
    }
}
