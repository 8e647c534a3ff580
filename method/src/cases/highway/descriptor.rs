//! What the service and the command line know about the highway-exit case.

use super::{HighwayExit, HighwayPreset};
use crate::case::Case;
use crate::cases::table_note::table_note;
use crate::cases::{
    CaseDescriptor, PaperFigures, Preset, Reproduction, Scenarios, TableFormat, Validation,
};
use crate::library::{LibrarySearch, SearchMethod, Threshold};
use crate::registry::cells::Registered;
use crate::registry::{CaseError, ExposureSource, ScenarioCase};
use crate::sampling::OutsideSpread;
use serde_json::json;
use std::sync::Arc;

const NAME: &str = "highway-exit";

/// The highway-exit case's descriptor.
pub fn descriptor() -> CaseDescriptor {
    CaseDescriptor {
        name: NAME,
        summary: "Functionality, four dimensions: the vehicle must change lanes to take an \
                  exit between two background vehicles (positions p₁, p₂ and speeds v₁, \
                  v₂); the event is missing the exit (paper Section IV.B).",
        presets: vec![
            Preset {
                name: "paper",
                summary: "the paper's 61 × 21 × 61 × 21 grid (1.64 × 10⁶ scenarios)",
            },
            Preset {
                name: "coarse",
                summary: "a 16 × 6 × 16 × 6 grid (9,216 scenarios) with exact answers in \
                          seconds",
            },
        ],
        vehicles: vec!["mobil", "gap-seeker"],
        default_surrogate: "mobil",
        // MOBIL's failures are scattered islands that a 100-start multistart
        // finds 3% of (docs/models.md); all 1.64 × 10⁶ scenarios take
        // seconds to enumerate.
        default_search: LibrarySearch::Cells(SearchMethod::Exhaustive),
        multistart_starts: 100,
        default_threshold: Some(Threshold::default()),
        scenarios: Scenarios::Grid,
        scenario_unit: "scenarios",
        build_unit: "searched",
        tables: vec![TableFormat {
            holds: "P(v₁, R, v₂): leader speed, range p₁ − p₂ and follower speed of \
                    car-following events, and optionally the range of p₁",
            doc: "docs/bring-your-own.md#highway-exit-pv1-r-v2",
        }],
        default_outside: OutsideSpread::Uniform,
        picture_axes: [
            "first background vehicle's position p₁ (m)",
            "second background vehicle's position p₂ (m)",
        ],
        demo_vut: None,
        validation: Some(Validation {
            pairs: vec![("mobil", "mobil"), ("mobil", "gap-seeker")],
            quick_preset: Some("coarse"),
        }),
        reproduction: Some(Reproduction {
            preset: "paper",
            surrogate: "mobil",
            search: LibrarySearch::Cells(SearchMethod::Exhaustive),
            epsilon: 0.1,
            beta: 0.2,
            vehicles: vec![
                (
                    "mobil p 0.3",
                    json!({"model": "mobil", "politeness": 0.3, "wait_cost": 0.5}),
                ),
                ("gap-seeker", json!({"model": "gap-seeker"})),
            ],
            takes_table: false,
            paper: PaperFigures {
                library_size: Some(1895),
                library_tests: 2.6e3,
                ndd_tests: 6.6e5,
            },
        }),
    }
}

/// Opens the highway-exit case with `preset` on its built-in exposure.
pub fn open(
    preset: Option<&str>,
    exposure: &ExposureSource,
) -> Result<Arc<dyn ScenarioCase>, CaseError> {
    let preset: HighwayPreset = match preset {
        None => HighwayPreset::default(),
        Some(p) => p.parse().map_err(CaseError::Preset)?,
    };
    let (opened, note) = match exposure {
        ExposureSource::Builtin => (HighwayExit::builtin(preset), None),
        ExposureSource::Table { name, text } => {
            let (case, sum) = HighwayExit::from_table(text, name.clone(), preset).map_err(|e| {
                CaseError::Exposure {
                    name: name.clone(),
                    reason: e.to_string(),
                }
            })?;
            let distance = case
                .exposure()
                .total_variation(HighwayExit::builtin(preset).exposure());
            (case, Some(table_note(name, sum, Some(distance))))
        }
    };
    Ok(Arc::new(
        Registered::new(opened, preset.name(), descriptor()).with_note(note),
    ))
}

/// The built-in `P(v₁, R, v₂)` on `preset`'s grid, as a long table.
pub fn builtin_table(preset: Option<&str>) -> Result<String, CaseError> {
    let preset: HighwayPreset = match preset {
        None => HighwayPreset::default(),
        Some(p) => p.parse().map_err(CaseError::Preset)?,
    };
    let (dp, dv) = preset.steps();
    Ok(super::table::builtin_table(
        &super::ExitExposureModel::default(),
        &super::exit_grid(dp, dv),
    ))
}
