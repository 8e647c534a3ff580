//! The adapter for grid cases (cut-in, highway-exit): a typed [`Case`] whose
//! vehicles are serde types, libraries of cells in the JSON library format,
//! and tests drawn as a cell and a weight before the vehicle runs.

mod building;
mod campaign;
mod exact;
mod sampling;
mod views;

pub use building::grid_library_summary;

use crate::case::Case;
use crate::descriptor::CaseDescriptor;
use crate::library::{Library, SearchMethod};
use crate::registry::vut::CampaignVehicle;
use crate::registry::{BuildRequest, CaseError, CaseIdentity, LibrarySearch};
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::sync::Arc;

pub(crate) struct Registered<C> {
    case: Arc<C>,
    preset: String,
    descriptor: CaseDescriptor,
    note: Option<String>,
}

impl<C> Registered<C>
where
    C: Case,
    C::Vehicle: DeserializeOwned,
{
    pub(crate) fn new(case: C, preset: &str, descriptor: CaseDescriptor) -> Self {
        Self {
            case: Arc::new(case),
            preset: preset.to_owned(),
            descriptor,
            note: None,
        }
    }

    /// The case with `note` on how its exposure was read
    /// ([`ScenarioCase::exposure_note`]).
    pub(crate) fn with_note(self, note: Option<String>) -> Self {
        Self { note, ..self }
    }

    fn vehicle(&self, spec: &serde_json::Value) -> Result<C::Vehicle, CaseError> {
        serde_json::from_value(spec.clone()).map_err(|e| CaseError::Vehicle {
            case: self.case.name(),
            reason: e.to_string(),
        })
    }

    /// A built-in model or an external program (both modes: a grid
    /// scenario is fixed before the test runs).
    fn campaign_vehicle(
        &self,
        spec: &serde_json::Value,
    ) -> Result<CampaignVehicle<C::Vehicle>, CaseError> {
        let modes = self.case.external_modes();
        // A program named without a mode gets the case's first.
        let mut spec = spec.clone();
        if let Some(object) = spec.as_object_mut() {
            if object.contains_key("external") && !object.contains_key("mode") {
                object.insert("mode".into(), modes[0].as_str().into());
            }
        }
        if let Some(vehicle) = self.case.resolve_vehicle(&spec) {
            return Ok(CampaignVehicle::Builtin(vehicle));
        }
        let vehicle =
            CampaignVehicle::parse(self.case.name(), &spec, true, |spec| self.vehicle(spec))?;
        if let CampaignVehicle::External(vut) = &vehicle {
            if !modes.contains(&vut.mode) {
                return Err(CaseError::Vehicle {
                    case: self.case.name(),
                    reason: format!(
                        "its programs run in {} mode: the program is the simulation",
                        modes[0].as_str()
                    ),
                });
            }
        }
        Ok(vehicle)
    }

    /// The cells with exposure, in cell order: the tests of an enumeration.
    fn enumerated_cells(&self) -> Arc<[usize]> {
        let exposure = self.case.exposure();
        (0..self.case.grid().len())
            .filter(|&c| exposure.p(c) > 0.0)
            .collect()
    }

    /// Refuses what was computed with a vehicle run here that failed.
    fn unfailed<T>(&self, value: T) -> Result<T, CaseError> {
        match self.case.failure() {
            None => Ok(value),
            Some(reason) => Err(CaseError::Build(reason)),
        }
    }

    /// A built-in model, for what runs on the coordinator (`purpose`).
    fn builtin(&self, spec: &serde_json::Value, purpose: &str) -> Result<C::Vehicle, CaseError> {
        self.campaign_vehicle(spec)?
            .into_builtin(self.case.name(), purpose)
    }

    fn library(&self, file: &[u8]) -> Result<Library, CaseError> {
        let text = std::str::from_utf8(file).map_err(|e| {
            CaseError::Library(crate::library::LibraryFileError::Json(e.to_string()))
        })?;
        let library = Library::from_json(text)?;
        library.check_matches(self.case.as_ref())?;
        Ok(library)
    }

    fn search(&self, request: &BuildRequest) -> Result<SearchMethod, CaseError> {
        match request.search {
            None => match self.descriptor.default_search {
                LibrarySearch::Cells(method) => Ok(method),
                LibrarySearch::Policy(_) => unreachable!("a grid case's default searches cells"),
            },
            Some(LibrarySearch::Cells(method)) => Ok(method),
            Some(LibrarySearch::Policy(_)) => Err(CaseError::Request {
                case: self.case.name(),
                reason: "its libraries are sets of grid cells: search.method is exhaustive \
                         or multistart"
                    .into(),
            }),
        }
    }
}

impl<C> CaseIdentity for Registered<C>
where
    C: Case + Send + 'static,
    C::Vehicle: DeserializeOwned + Serialize + Send + Sync + 'static,
{
    fn name(&self) -> &'static str {
        self.case.name()
    }

    fn preset(&self) -> String {
        self.preset.clone()
    }

    fn exposure_name(&self) -> &str {
        self.case.exposure_name()
    }

    fn exposure_fingerprint(&self) -> String {
        self.case.exposure().fingerprint()
    }

    fn total_scenarios(&self) -> usize {
        self.case.grid().len()
    }

    fn descriptor(&self) -> &CaseDescriptor {
        &self.descriptor
    }

    fn exposure_note(&self) -> Option<String> {
        self.note.clone()
    }

    fn failure(&self) -> Option<String> {
        self.case.failure()
    }

    fn normalise_vehicle(&self, spec: &serde_json::Value) -> Result<serde_json::Value, CaseError> {
        Ok(self.campaign_vehicle(spec)?.to_spec())
    }
}
