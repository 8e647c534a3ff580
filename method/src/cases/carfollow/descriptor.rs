//! What the service and the command line know about the car-following case.

use super::service::FollowScenarioCase;
use super::{CarFollowing, FollowPreset};
use crate::cases::{
    builtin_exposure_only, CaseDescriptor, PaperFigures, Preset, Reproduction, Scenarios,
};
use crate::library::{LibrarySearch, PolicySolver};
use crate::registry::{CaseError, ExposureSource, ScenarioCase};
use crate::sampling::OutsideSpread;
use serde_json::json;
use std::sync::Arc;

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
                summary: "the built-in exposure of SPEC §6",
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
        tables: Vec::new(),
        default_outside: OutsideSpread::Ndd,
        picture_axes: ["range R (m)", "range rate Ṙ (m/s)"],
        demo_vut: None,
        validation: None,
        reproduction: Reproduction {
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
        },
    }
}

/// Opens the car-following case with `preset` on its built-in exposure.
pub fn open(
    preset: Option<&str>,
    exposure: &ExposureSource,
) -> Result<Arc<dyn ScenarioCase>, CaseError> {
    let preset: FollowPreset = match preset {
        None => FollowPreset::default(),
        Some(p) => p.parse().map_err(CaseError::Preset)?,
    };
    builtin_exposure_only(NAME, exposure)?;
    Ok(Arc::new(FollowScenarioCase::new(CarFollowing::new(preset))))
}
