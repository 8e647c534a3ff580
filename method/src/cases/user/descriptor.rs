//! The descriptor of a user-defined case, from its file, and its opener.

use super::file::CaseFile;
use super::{intern, UserCase};
use crate::cases::{CaseDescriptor, Preset, Scenarios, TableFormat};
use crate::external::ProgramHost;
use crate::library::{LibrarySearch, SearchMethod, Threshold};
use crate::registry::cells::Registered;
use crate::registry::{CaseError, ExposureSource, ScenarioCase};
use crate::sampling::OutsideSpread;
use std::sync::Arc;

/// A user case as the service and the command line see it: one preset
/// (`default`), no built-in vehicles, its program as the default surrogate,
/// exhaustive search by default (each cell is one program run).
pub fn descriptor(file: &CaseFile) -> CaseDescriptor {
    let columns: Vec<&str> = file.dimensions.iter().map(|d| d.name.as_str()).collect();
    let label = |k: usize| -> &'static str {
        file.dimensions.get(k).map_or("", |d| {
            intern(&if d.unit.is_empty() {
                d.name.clone()
            } else {
                format!("{} ({})", d.name, d.unit)
            })
        })
    };
    CaseDescriptor {
        name: intern(&file.name),
        summary: intern(&file.summary),
        presets: vec![Preset {
            name: "default",
            summary: "the case file's grid and simulation",
        }],
        vehicles: Vec::new(),
        default_surrogate: intern(&file.program),
        default_search: LibrarySearch::Cells(SearchMethod::Exhaustive),
        multistart_starts: 50,
        default_threshold: Some(Threshold::default()),
        scenarios: Scenarios::Grid,
        scenario_unit: "scenarios",
        build_unit: "searched",
        tables: vec![TableFormat {
            holds: intern(&format!(
                "P({}): columns {}, probability",
                columns.join(", "),
                columns.join(",")
            )),
            doc: "docs/bring-your-own.md#user-defined-cases",
        }],
        default_outside: OutsideSpread::Uniform,
        picture_axes: [label(0), label(1)],
        demo_vut: None,
        validation: None,
        reproduction: None,
    }
}

/// Opens the case of `file` (its exposure table `table`, named
/// `table_name`) on `exposure` (the file's table, or one given in its
/// place), with `host` to run its programs in this process, if any.
pub fn open(
    file: CaseFile,
    table_name: &str,
    table: &str,
    preset: Option<&str>,
    exposure: &ExposureSource,
    host: Option<Arc<dyn ProgramHost>>,
) -> Result<Arc<dyn ScenarioCase>, CaseError> {
    if let Some(preset) = preset.filter(|&p| p != "default") {
        return Err(CaseError::Preset(format!(
            "case {} has one preset, `default` (its file's grid), not `{preset}`",
            file.name
        )));
    }
    let (name, text) = match exposure {
        ExposureSource::Builtin => (table_name, table),
        ExposureSource::Table { name, text } => (name.as_str(), text.as_str()),
    };
    // The descriptor interns its texts for the life of the process: made
    // only once the case opens, so refused definitions leak nothing (20,000
    // refused tables kept 42 MB).
    let descriptor_file = file.clone();
    let case =
        UserCase::open(file, name.to_owned(), text, host).map_err(|e| CaseError::Exposure {
            name: name.to_owned(),
            reason: e.to_string(),
        })?;
    Ok(Arc::new(Registered::new(
        case,
        "default",
        descriptor(&descriptor_file),
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A definition refused for its table interns nothing: each refused
    /// `POST /api/v1/cases` kept 2–3 KB for the life of the coordinator.
    #[test]
    fn a_refused_definition_leaks_nothing() {
        let summary = "a summary no other test has: refused-definition-probe";
        let text = format!(
            "name = \"leak-probe\"\nsummary = \"{summary}\"\nprogram = \"p\"\n\
             command = \"p\"\nexposure = \"e.csv\"\n[[dimensions]]\nname = \"x\"\n\
             lower = 0\nupper = 2\nstep = 1\n"
        );
        let file = CaseFile::parse(&text).unwrap();
        let refused = open(
            file.clone(),
            "e.csv",
            "not,a,table\n",
            None,
            &ExposureSource::Builtin,
            None,
        );
        assert!(matches!(refused, Err(CaseError::Exposure { .. })));
        assert!(!super::super::interned(summary));
        let opened = open(
            file,
            "e.csv",
            "x,probability\n0,0.5\n1,0.25\n2,0.25\n",
            None,
            &ExposureSource::Builtin,
            None,
        );
        assert!(opened.is_ok());
        assert!(
            super::super::interned(summary),
            "the probe sees what is interned"
        );
    }
}
