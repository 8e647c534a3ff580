//! Building and reading a grid case's libraries: exhaustive and multistart
//! searches, enumerations run on workers, files built elsewhere.

use super::campaign::CellCampaign;
use super::Registered;
use crate::case::Case;
use crate::library::{
    build_library_observed, library_from_events, Library, LibraryRequest, SearchMethod, Threshold,
};
use crate::progress::Progress;
use crate::registry::{
    BuildRequest, BuiltLibrary, CampaignTests, CaseError, LibraryBuilder, LibrarySummary,
};
use crate::sampling::TestDistribution;
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::sync::{Arc, OnceLock};

/// The media type of the JSON library file.
const LIBRARY_MEDIA_TYPE: &str = "application/json";

impl<C> LibraryBuilder for Registered<C>
where
    C: Case + Send + 'static,
    C::Vehicle: DeserializeOwned + Serialize + Send + Sync + 'static,
{
    fn check_request(&self, request: &BuildRequest) -> Result<(), CaseError> {
        self.search(request).map(|_| ())
    }

    fn build_library_observed(
        &self,
        surrogate: &serde_json::Value,
        request: &BuildRequest,
        progress: &Progress,
    ) -> Result<BuiltLibrary, CaseError> {
        let vehicle = self.builtin(surrogate, "a library's surrogate")?;
        if self.case.is_noisy(&vehicle) {
            return Err(CaseError::Request {
                case: self.case.name(),
                reason: crate::noise::NOISY_SURROGATE.into(),
            });
        }
        let spec = serde_json::to_value(&vehicle).expect("vehicle specifications serialise");
        let request = LibraryRequest {
            threshold: request.threshold.unwrap_or_default(),
            search: self.search(request)?,
        };
        let library = self.unfailed(build_library_observed(
            self.case.as_ref(),
            &vehicle,
            spec,
            &self.preset,
            &request,
            progress,
        ))?;
        Ok(grid_built(&library, library.to_json().into_bytes()))
    }

    fn library_summary(&self, file: &[u8]) -> Result<LibrarySummary, CaseError> {
        grid_library_summary(file)
    }

    fn built_elsewhere(
        &self,
        file: &[u8],
        surrogate: &serde_json::Value,
        sample: usize,
    ) -> Result<BuiltLibrary, CaseError> {
        let library = self.library(file)?;
        // A program surrogate runs on workers only: nothing to run here.
        if let Ok(vehicle) = self.builtin(surrogate, "a library's surrogate") {
            let step = (library.cells.len() / sample.max(1)).max(1);
            for c in library.cells.iter().step_by(step).take(sample) {
                let v = self.case.surrogate_challenge(&vehicle, c.cell)
                    * self.case.exposure().p(c.cell);
                if (v - c.criticality).abs() > 1e-12 * v.abs().max(c.criticality.abs()) {
                    return Err(CaseError::Unsupported(format!(
                        "library cell {} records criticality {:e}; the surrogate gives {v:e} \
                         there",
                        c.cell, c.criticality
                    )));
                }
            }
        }
        Ok(grid_built(&library, file.to_vec()))
    }

    fn enumeration(
        &self,
        surrogate: &serde_json::Value,
    ) -> Result<Arc<dyn CampaignTests>, CaseError> {
        if crate::noise::spec_is_noisy(surrogate) {
            return Err(CaseError::Request {
                case: self.case.name(),
                reason: crate::noise::NOISY_SURROGATE.into(),
            });
        }
        Ok(Arc::new(CellCampaign {
            world: self.case.external_world(),
            case: Arc::clone(&self.case),
            vehicle: self.campaign_vehicle(surrogate)?,
            surrogate: None,
            distribution: TestDistribution::Enumeration(self.enumerated_cells()),
            seed: 0,
            outcomes: OnceLock::new(),
        }))
    }

    fn enumeration_len(&self) -> u64 {
        self.case.exposure().support_size() as u64
    }

    fn library_from_enumeration(
        &self,
        surrogate: &serde_json::Value,
        threshold: Option<Threshold>,
        events: &[u64],
    ) -> Result<BuiltLibrary, CaseError> {
        let spec = self.campaign_vehicle(surrogate)?.to_spec();
        let cells = self.enumerated_cells();
        let event_cells: Vec<usize> = events
            .iter()
            .map(|&i| {
                cells.get(i as usize).copied().ok_or_else(|| {
                    CaseError::Build(format!(
                        "event at test {i} beyond the enumeration's {} cells",
                        cells.len()
                    ))
                })
            })
            .collect::<Result<_, _>>()?;
        let library = library_from_events(
            self.case.as_ref(),
            spec,
            &self.preset,
            threshold.unwrap_or_default(),
            &event_cells,
            cells.len(),
        );
        Ok(grid_built(&library, library.to_json().into_bytes()))
    }
}

/// A grid library as a build's result, with its file `file`.
fn grid_built(library: &Library, file: Vec<u8>) -> BuiltLibrary {
    BuiltLibrary {
        file,
        media_type: LIBRARY_MEDIA_TYPE,
        size: library.size(),
        sm_evaluations: library.search.sm_evaluations,
        mu_s: library.mu_s,
        w: library.w,
    }
}

/// What a grid library file holds (any grid case: the file is
/// self-describing).
pub fn grid_library_summary(file: &[u8]) -> Result<LibrarySummary, CaseError> {
    let text = std::str::from_utf8(file)
        .map_err(|e| CaseError::Library(crate::library::LibraryFileError::Json(e.to_string())))?;
    let library = Library::from_json(text)?;
    Ok(LibrarySummary {
        case: library.case.clone(),
        preset: library.preset.clone(),
        surrogate: library.surrogate.clone(),
        exposure: library.exposure.clone(),
        size: library.size(),
        total: library.total_scenarios(),
        mu_s: library.mu_s,
        w: library.w,
        gamma: Some(library.gamma),
        search: match library.search.method {
            SearchMethod::Exhaustive => "exhaustive".to_owned(),
            SearchMethod::Multistart { starts, seed } => {
                format!("multistart ({starts} starts, seed {seed})")
            }
        },
        sm_evaluations: library.search.sm_evaluations,
        recall: library.search.recall,
    })
}
