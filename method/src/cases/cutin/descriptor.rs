//! What the service and the command line know about the cut-in case.

use super::{CutIn, CutInError, CutInPreset};
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

/// The cut-in case's descriptor.
pub fn descriptor() -> CaseDescriptor {
    CaseDescriptor {
        name: "cut-in",
        summary: "Safety, two dimensions: a background vehicle cuts in at range R and range \
                  rate Ṙ; the event is an accident (paper Section IV.A).",
        presets: vec![
            Preset {
                name: "paper-code",
                summary: "the authors' code: 10 steps of 1 s, their speed update",
            },
            Preset {
                name: "paper-table",
                summary: "the paper's Table III: 100 steps of 0.1 s",
            },
        ],
        vehicles: vec!["idm", "fvdm", "switching-acc", "acc-aeb"],
        default_surrogate: "idm",
        // The paper's search; its recall is 1 on this grid.
        default_search: LibrarySearch::Cells(SearchMethod::Multistart {
            starts: 50,
            seed: 0,
        }),
        multistart_starts: 50,
        default_threshold: Some(Threshold::default()),
        scenarios: Scenarios::Grid,
        scenario_unit: "scenarios",
        build_unit: "searched",
        tables: vec![TableFormat {
            holds: "P(R, Ṙ): the joint exposure of range and range rate",
            doc: "docs/bring-your-own.md#cut-in-pr-ṙ",
        }],
        default_outside: OutsideSpread::Uniform,
        picture_axes: ["range R (m)", "range rate Ṙ (m/s)"],
        // The FVDM fails where the IDM's library does not.
        demo_vut: Some("fvdm"),
        validation: Some(Validation {
            pairs: vec![
                ("idm", "idm"),
                ("fvdm", "fvdm"),
                ("fvdm", "idm"),
                ("idm", "fvdm"),
                ("idm", "switching-acc"),
                ("idm", "acc-aeb"),
            ],
            quick_preset: None,
        }),
        reproduction: Some(Reproduction {
            preset: "paper-code",
            surrogate: "idm",
            search: LibrarySearch::Cells(SearchMethod::Multistart {
                starts: 50,
                seed: 0,
            }),
            epsilon: 0.05,
            beta: 0.3,
            vehicles: vec![
                ("idm", json!({"model": "idm"})),
                ("acc-aeb", json!({"model": "acc-aeb"})),
            ],
            takes_table: true,
            paper: PaperFigures {
                library_size: Some(184),
                library_tests: 51.0,
                ndd_tests: 9.63e4,
            },
        }),
    }
}

/// Opens the cut-in case with `preset` on `exposure` (the built-in model or
/// a table of `P(R, Ṙ)`).
pub fn open(
    preset: Option<&str>,
    exposure: &ExposureSource,
) -> Result<Arc<dyn ScenarioCase>, CaseError> {
    let preset: CutInPreset = match preset {
        None => CutInPreset::default(),
        Some(p) => p.parse().map_err(CaseError::Preset)?,
    };
    let (opened, note) = match exposure {
        ExposureSource::Builtin => (CutIn::builtin(preset), None),
        ExposureSource::Table { name, text } => {
            let (case, table) =
                CutIn::from_table(text, name.clone(), preset).map_err(|e: CutInError| {
                    CaseError::Exposure {
                        name: name.clone(),
                        reason: e.to_string(),
                    }
                })?;
            // The built-in model evaluated on the table's own grid, where
            // it puts any mass there.
            let distance = super::CutInExposureModel::default()
                .try_mass_on(case.exposure().grid().clone())
                .ok()
                .map(|model| case.exposure().total_variation(&model));
            let note = Some(table_note(name, table.mass.original_sum(), distance));
            (case, note)
        }
    };
    Ok(Arc::new(
        Registered::new(opened, preset.name(), descriptor()).with_note(note),
    ))
}

/// The built-in exposure of `preset` in the authors' layout: a header of
/// range-rate labels, then one line per range with its probabilities.
pub fn builtin_table(preset: Option<&str>) -> Result<String, CaseError> {
    use crate::number::Label;
    let preset: CutInPreset = match preset {
        None => CutInPreset::default(),
        Some(p) => p.parse().map_err(CaseError::Preset)?,
    };
    let case = CutIn::builtin(preset);
    let mass = case.exposure();
    let grid = mass.grid();
    let (ranges, rates) = (&grid.axes()[0], &grid.axes()[1]);
    let mut text = String::new();
    // Labels as the shortest text of their grid value, probabilities in
    // scientific notation (both read back to the same f64).
    for k in 0..rates.len() {
        text.push_str(&format!(",{}", Label(rates.value(k))));
    }
    text.push('\n');
    for i in 0..ranges.len() {
        text.push_str(&format!("{}", Label(ranges.value(i))));
        for k in 0..rates.len() {
            text.push_str(&format!(",{:e}", mass.p(i * rates.len() + k)));
        }
        text.push('\n');
    }
    Ok(text)
}
