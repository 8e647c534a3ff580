//! Scenario libraries: the critical scenarios `Φ = {x : V(x) > γ}` of a
//! surrogate model, with their criticality `V(x) = P(S|x) P(x)`.

mod definition;
mod exhaustive;
mod file;
mod head;
mod multistart;
mod policy_solver;
mod search;

pub(crate) use definition::Evaluated;
pub use definition::{
    ExposureRef, Library, LibraryCell, LibraryRequest, SearchMethod, SearchReport, Threshold,
    ThresholdError,
};
pub use file::LibraryFileError;
pub use head::{read_head, LibraryHead, POLICY_MAGIC};
pub use policy_solver::PolicySolver;
pub use search::LibrarySearch;

use crate::case::Case;
use crate::progress::Progress;

/// Builds a library of `surrogate` on `case`.
pub fn build_library<C: Case>(
    case: &C,
    surrogate: &C::Vehicle,
    surrogate_spec: serde_json::Value,
    preset: &str,
    request: &LibraryRequest,
) -> Library {
    build_library_observed(
        case,
        surrogate,
        surrogate_spec,
        preset,
        request,
        &Progress::default(),
    )
}

/// [`build_library`], counting the cells (exhaustive) or starts
/// (multistart) searched in `progress`.
pub fn build_library_observed<C: Case>(
    case: &C,
    surrogate: &C::Vehicle,
    surrogate_spec: serde_json::Value,
    preset: &str,
    request: &LibraryRequest,
    progress: &Progress,
) -> Library {
    let evaluated = match request.search {
        SearchMethod::Exhaustive => exhaustive::search(case, surrogate, progress),
        SearchMethod::Multistart { starts, seed } => {
            multistart::search(case, surrogate, &request.threshold, starts, seed, progress)
        }
    };
    library_of(case, surrogate_spec, preset, request, evaluated)
}

/// The exhaustive library of a surrogate whose runs on every cell with
/// exposure were done elsewhere (on workers): `events` are the cells where
/// it had the event, `P(S|x) = 1` there and 0 elsewhere, and `runs` the
/// surrogate runs made.
pub fn library_from_events<C: Case>(
    case: &C,
    surrogate_spec: serde_json::Value,
    preset: &str,
    threshold: Threshold,
    events: &[usize],
    runs: usize,
) -> Library {
    let exposure = case.exposure();
    let critical = events
        .iter()
        .map(|&cell| (cell, exposure.p(cell)))
        .filter(|&(_, v)| v > 0.0)
        .collect();
    library_of(
        case,
        surrogate_spec,
        preset,
        &LibraryRequest {
            threshold,
            search: SearchMethod::Exhaustive,
        },
        Evaluated {
            critical,
            sm_evaluations: runs,
        },
    )
}

/// The library the evaluated cells give under the request's threshold.
fn library_of<C: Case>(
    case: &C,
    surrogate_spec: serde_json::Value,
    preset: &str,
    request: &LibraryRequest,
    evaluated: Evaluated,
) -> Library {
    let grid = case.grid();
    let mu_s: f64 = evaluated.critical.iter().map(|&(_, v)| v).sum();
    let gamma = request.threshold.gamma(mu_s, grid.len());
    let mut cells: Vec<LibraryCell> = evaluated
        .critical
        .into_iter()
        .filter(|&(_, v)| v > gamma)
        .map(|(cell, criticality)| LibraryCell { cell, criticality })
        .collect();
    cells.sort_by_key(|c| c.cell);
    let w = cells.iter().map(|c| c.criticality).sum();
    Library {
        case: case.name().to_owned(),
        preset: preset.to_owned(),
        surrogate: surrogate_spec,
        exposure: ExposureRef {
            name: case.exposure_name().to_owned(),
            fingerprint: case.exposure().fingerprint(),
        },
        grid: grid.clone(),
        threshold: request.threshold,
        gamma,
        mu_s,
        w,
        search: SearchReport {
            method: request.search,
            sm_evaluations: evaluated.sm_evaluations,
            recall: None,
        },
        cells,
    }
}
