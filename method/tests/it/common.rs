//! Helpers shared by the integration tests.

use std::path::PathBuf;

/// The authors' cut-in table from `../shared/data`, or `None` (after printing
/// why) when it is absent: it is a reference fixture, not part of the product.
pub fn shared_table() -> Option<String> {
    let path = std::env::var_os("TSLG_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"))
        .join("cutin_ndd_spmd.csv");
    match std::fs::read_to_string(&path) {
        Ok(text) => Some(text),
        Err(e) => {
            eprintln!(
                "SKIPPED: this test needs the authors' cut-in table at {} ({e}); \
                 set TSLG_SHARED_DATA to the folder that holds it",
                path.display()
            );
            None
        }
    }
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
