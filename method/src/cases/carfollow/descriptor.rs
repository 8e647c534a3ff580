//! What the service and the command line know about the car-following case.

use super::{CarFollowing, FollowPreset};
use crate::cases::{CaseDescriptor, PaperFigures, Preset, Reproduction, Scenarios, TableFormat};
use crate::library::{LibrarySearch, PolicySolver};
use crate::registry::CaseError;
use crate::sampling::OutsideSpread;
use serde_json::json;

/// The case's name.
pub const NAME: &str = "car-following";

/// The car-following case's descriptor.
pub fn descriptor() -> CaseDescriptor {
    CaseDescriptor {
        name: NAME,
        summary: "Safety, 33 dimensions: the vehicle follows a background vehicle for 30 s \
                  whose 30 accelerations are drawn one per second; the event is an accident \
                  (paper Section V). Libraries are policies over 45,885 states.",
        presets: vec![
            Preset {
                name: "paper",
                summary: "the built-in exposure (docs/models.md, car-following, Exposure)",
            },
            Preset {
                name: "risky",
                summary: "short headways and harsh braking: NDD baselines in seconds",
            },
        ],
        vehicles: vec!["idm", "fvdm", "switching-acc", "acc-aeb"],
        default_surrogate: "idm",
        default_search: LibrarySearch::Policy(PolicySolver::DynamicProgramming),
        multistart_starts: 0,
        default_threshold: None,
        scenarios: Scenarios::Sequential,
        scenario_unit: "states",
        build_unit: "surrogate transitions",
        tables: vec![TableFormat {
            holds: "P(s) over the initial states (v, R, Ṙ) and P(u | v), the BV's \
                    acceleration law at each speed, in one file",
            doc: "docs/bring-your-own.md#car-following-ps-and-pu--v",
        }],
        default_outside: OutsideSpread::Ndd,
        picture_axes: ["range R (m)", "range rate Ṙ (m/s)"],
        demo_vut: None,
        validation: None,
        reproduction: Some(Reproduction {
            preset: "paper",
            surrogate: "idm",
            search: LibrarySearch::Policy(PolicySolver::DynamicProgramming),
            epsilon: 0.1,
            beta: 0.2,
            vehicles: vec![("acc-aeb", json!({"model": "acc-aeb"}))],
            takes_table: false,
            paper: PaperFigures {
                library_size: None,
                library_tests: 50.0,
                ndd_tests: 1.875e7,
            },
        }),
    }
}

/// The built-in `P(s)` and `P(u|v)` of `preset`, as tables.
pub fn builtin_table(preset: Option<&str>) -> Result<String, CaseError> {
    let preset: FollowPreset = match preset {
        None => FollowPreset::default(),
        Some(p) => p.parse().map_err(CaseError::Preset)?,
    };
    let case = CarFollowing::new(preset);
    Ok(case.exposure.to_tables(&case.world, &case.grid))
}
