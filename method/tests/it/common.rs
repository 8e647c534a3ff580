//! Helpers shared by the integration tests.

/// The authors' cut-in table's text (`tslg_testkit::authors_table`: from
/// `TSLG_SHARED_DATA` or `../shared/data`), or `None` after the test
/// recorded its skip: it is a reference fixture, not part of the product.
pub fn shared_table() -> Option<String> {
    let path = tslg_testkit::authors_table()?;
    Some(std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())))
}

use tslg_method::case::Case;
use tslg_method::cases::cutin::CutIn;
use tslg_method::library::{build_library, Library, LibraryRequest, SearchMethod, Threshold};
use tslg_method::sampling::{LibraryDistribution, OutsideSpread, Split};
use tslg_method::vehicle::VehicleModel;

pub fn vehicle(name: &str) -> VehicleModel {
    VehicleModel::builtin(name).expect("built-in model")
}

/// A library of the built-in `surrogate` with the default threshold (m = 1).
pub fn library(case: &CutIn, surrogate: &str, search: SearchMethod) -> Library {
    let sm = vehicle(surrogate);
    build_library(
        case,
        &sm,
        serde_json::to_value(sm).expect("serialisable"),
        case.preset().name(),
        &LibraryRequest {
            threshold: Threshold::default(),
            search,
        },
    )
}

pub fn median(values: &mut [u64]) -> f64 {
    values.sort_unstable();
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2] as f64
    } else {
        (values[n / 2 - 1] + values[n / 2]) as f64 / 2.0
    }
}

/// The paper's ε-greedy distribution of `library` on `case`'s exposure: ε
/// spread uniformly outside the library, each test exploring with
/// probability ε (the random split).
pub fn paper_q(case: &CutIn, library: &Library, epsilon: f64) -> LibraryDistribution {
    LibraryDistribution::new(
        library,
        case.exposure(),
        epsilon,
        OutsideSpread::Uniform,
        Split::Random,
    )
    .expect("a non-empty library on its own grid")
}
