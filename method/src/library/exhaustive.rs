//! Exhaustive search: the surrogate on every cell with positive exposure.
//! Cells with `P(x) = 0` have `V(x) = 0` without a simulation.

use super::Evaluated;
use crate::case::Case;
use crate::progress::Progress;
use rayon::prelude::*;

pub(crate) fn search<C: Case>(case: &C, surrogate: &C::Vehicle, progress: &Progress) -> Evaluated {
    let exposure = case.exposure();
    progress.start(exposure.grid().len() as u64);
    let (critical, evaluations) = (0..exposure.grid().len())
        .into_par_iter()
        .inspect(|_| progress.add(1))
        .filter(|&cell| exposure.p(cell) > 0.0)
        .map(|cell| {
            let v = case.surrogate_challenge(surrogate, cell) * exposure.p(cell);
            (v > 0.0).then_some((cell, v))
        })
        .fold(
            || (Vec::new(), 0usize),
            |(mut found, n), hit| {
                found.extend(hit);
                (found, n + 1)
            },
        )
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
