//! The adapter for grid cases (cut-in, highway-exit): a typed [`Case`] whose
//! vehicles are serde types, libraries of cells in the JSON library format,
//! and tests drawn as a cell and a weight before the vehicle runs.

use super::{
    BuildRequest, BuiltLibrary, CampaignTests, CaseError, LibrarySearch, PlannedTest, ScenarioCase,
    TestOutcome,
};
use crate::case::Case;
use crate::estimator::z_for_confidence;
use crate::exact::{event_cells, event_probability, exact_report, ExactReport};
use crate::library::{build_library, Library, LibraryRequest, SearchMethod};
use crate::sampling::{LibraryDistribution, NddDistribution, OutsideSpread, TestDistribution};
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::sync::Arc;

/// The media type of the JSON library file.
const LIBRARY_MEDIA_TYPE: &str = "application/json";

pub(super) struct Registered<C> {
    case: Arc<C>,
    preset: String,
}

impl<C> Registered<C>
where
    C: Case,
    C::Vehicle: DeserializeOwned,
{
    pub(super) fn new(case: C, preset: &str) -> Self {
        Self {
            case: Arc::new(case),
            preset: preset.to_owned(),
        }
    }

    fn vehicle(&self, spec: &serde_json::Value) -> Result<C::Vehicle, CaseError> {
        serde_json::from_value(spec.clone()).map_err(|e| CaseError::Vehicle {
            case: self.case.name(),
            reason: e.to_string(),
        })
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
            None => Ok(SearchMethod::Multistart {
                starts: 50,
                seed: 0,
            }),
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

impl<C> ScenarioCase for Registered<C>
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

    fn default_outside(&self) -> OutsideSpread {
        OutsideSpread::Uniform
    }

    fn normalise_vehicle(&self, spec: &serde_json::Value) -> Result<serde_json::Value, CaseError> {
        let vehicle = self.vehicle(spec)?;
        Ok(serde_json::to_value(vehicle).expect("vehicle specifications serialise"))
    }

    fn check_request(&self, request: &BuildRequest) -> Result<(), CaseError> {
        self.search(request).map(|_| ())
    }

    fn build_library(
        &self,
        surrogate: &serde_json::Value,
        request: &BuildRequest,
    ) -> Result<BuiltLibrary, CaseError> {
        let vehicle = self.vehicle(surrogate)?;
        let spec = serde_json::to_value(&vehicle).expect("vehicle specifications serialise");
        let request = LibraryRequest {
            threshold: request.threshold.unwrap_or_default(),
            search: self.search(request)?,
        };
        let library = build_library(self.case.as_ref(), &vehicle, spec, &self.preset, &request);
        Ok(BuiltLibrary {
            file: library.to_json().into_bytes(),
            media_type: LIBRARY_MEDIA_TYPE,
            size: library.size(),
            sm_evaluations: library.search.sm_evaluations,
            mu_s: library.mu_s,
            w: library.w,
        })
    }

    fn campaign(
        &self,
        file: Option<&[u8]>,
        vut: &serde_json::Value,
        epsilon: f64,
        outside: OutsideSpread,
        seed: u64,
    ) -> Result<Arc<dyn CampaignTests>, CaseError> {
        let vehicle = self.vehicle(vut)?;
        let distribution = match file {
            Some(file) => TestDistribution::library(LibraryDistribution::new(
                &self.library(file)?,
                self.case.exposure(),
                epsilon,
                outside,
            )?),
            None => TestDistribution::Ndd(NddDistribution::new(self.case.exposure())),
        };
        Ok(Arc::new(CellCampaign {
            case: Arc::clone(&self.case),
            vehicle,
            distribution,
            seed,
        }))
    }

    fn exact_event_probability(&self, spec: &serde_json::Value) -> Result<f64, CaseError> {
        let vehicle = self.vehicle(spec)?;
        Ok(event_probability(
            self.case.as_ref(),
            &event_cells(self.case.as_ref(), &vehicle),
        ))
    }

    fn exact_report(
        &self,
        spec: &serde_json::Value,
        file: &[u8],
        epsilon: f64,
        outside: OutsideSpread,
        beta: f64,
        confidence: f64,
    ) -> Result<ExactReport, CaseError> {
        let vehicle = self.vehicle(spec)?;
        let library = self.library(file)?;
        let q = LibraryDistribution::new(&library, self.case.exposure(), epsilon, outside)?;
        Ok(exact_report(
            self.case.as_ref(),
            &vehicle,
            &q,
            beta,
            z_for_confidence(confidence),
        ))
    }
}

/// A grid campaign: test `i` draws its cell and weight from the stream
/// `(seed, i)`, then the vehicle runs that scenario.
struct CellCampaign<C: Case> {
    case: Arc<C>,
    vehicle: C::Vehicle,
    distribution: TestDistribution,
    seed: u64,
}

impl<C> CampaignTests for CellCampaign<C>
where
    C: Case + Send + 'static,
    C::Vehicle: Send + Sync,
{
    fn run(&self, index: u64) -> TestOutcome {
        let draw = self.distribution.draw(self.seed, index);
        TestOutcome {
            event: self.case.is_event(&self.vehicle, draw.cell),
            weight: draw.weight,
        }
    }

    fn check_event(&self, index: u64, weight: f64) -> Result<(), String> {
        let expected = self.distribution.draw(self.seed, index).weight;
        if expected.to_bits() == weight.to_bits() {
            Ok(())
        } else {
            Err(format!(
                "event at test {index} reports weight {weight:e}, but the campaign's sampler \
                 gives {expected:e}"
            ))
        }
    }

    fn planned(&self, index: u64) -> Option<PlannedTest> {
        let draw = self.distribution.draw(self.seed, index);
        Some(PlannedTest {
            cell: draw.cell,
            scenario: self.case.grid().values(draw.cell),
            weight: draw.weight,
        })
    }
}
