//! The cases a service can run, behind one object-safe interface, so the
//! coordinator and the worker handle every case with the same code: a case is
//! opened by name with a preset and an exposure source, vehicles are given as
//! JSON specifications, and tests are answered by cell index. Adding a case
//! means one arm in [`open_case`].

use crate::case::Case;
use crate::cutin::{CutIn, CutInError, CutInPreset};
use crate::estimator::z_for_confidence;
use crate::exact::{event_cells, event_probability, exact_report, ExactReport};
use crate::highway::{HighwayExit, HighwayPreset};
use crate::library::{build_library, Library, LibraryFileError, LibraryRequest};
use crate::mass::GridMass;
use crate::sampling::{
    Draw, LibraryDistribution, NddDistribution, OutsideSpread, SamplingError, TestDistribution,
};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use thiserror::Error;

/// Names of the cases [`open_case`] knows.
pub const CASES: [&str; 2] = ["cut-in", "highway-exit"];

/// Where a case's exposure `P(x)` comes from.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ExposureSource {
    /// The case's documented built-in exposure model.
    Builtin,
    /// A table in the layout of SPEC §4 (see [`crate::ndd_table`]).
    Table { name: String, text: String },
}

/// Why a case, a vehicle or a library could not be used.
#[derive(Debug, Error, PartialEq)]
pub enum CaseError {
    #[error("unknown case `{0}`; known cases: {known}", known = CASES.join(", "))]
    UnknownCase(String),
    #[error("{0}")]
    Preset(String),
    #[error("exposure table `{name}` rejected: {reason}")]
    Exposure { name: String, reason: String },
    #[error("invalid vehicle for case {case}: {reason}")]
    Vehicle { case: &'static str, reason: String },
    #[error(transparent)]
    Library(#[from] LibraryFileError),
    #[error(transparent)]
    Sampling(#[from] SamplingError),
}

/// Whether the vehicle has the event in a scenario cell.
pub type EventTest = Arc<dyn Fn(usize) -> bool + Send + Sync>;

/// A case opened for a service: everything the coordinator and the worker
/// need, without knowing which case it is.
pub trait ScenarioCase: Send + Sync {
    /// `cut-in`, …
    fn name(&self) -> &'static str;
    /// The simulation preset in force.
    fn preset(&self) -> String;
    fn exposure(&self) -> &GridMass;
    fn exposure_name(&self) -> &str;
    /// The scenario's parameters (grid values) of a cell.
    fn scenario(&self, cell: usize) -> Vec<f64> {
        self.exposure().grid().values(cell)
    }
    /// The vehicle specification validated and written out in full (every
    /// parameter with its value), as it is stored.
    fn normalise_vehicle(&self, spec: &serde_json::Value) -> Result<serde_json::Value, CaseError>;
    /// The event test of a vehicle under test.
    fn event_test(&self, vehicle: &serde_json::Value) -> Result<EventTest, CaseError>;
    /// The exact `P(A)` of a vehicle by enumeration of the grid.
    fn exact_event_probability(&self, vehicle: &serde_json::Value) -> Result<f64, CaseError>;
    /// `P(A)` with the expected tests of a library campaign (ε spread
    /// outside `library` by `outside`) and of the NDD baseline to relative
    /// half-width `beta` at `confidence`: the analytic acceleration ratio
    /// (SPEC §3).
    fn exact_report(
        &self,
        vehicle: &serde_json::Value,
        library: &Library,
        epsilon: f64,
        outside: OutsideSpread,
        beta: f64,
        confidence: f64,
    ) -> Result<ExactReport, CaseError>;
    /// Builds a library of `surrogate` (CPU-heavy: call off any async runtime).
    fn build_library(
        &self,
        surrogate: &serde_json::Value,
        request: &LibraryRequest,
    ) -> Result<Library, CaseError>;
    /// Checks that `library` was built for this case and exposure.
    fn check_library(&self, library: &Library) -> Result<(), CaseError>;
}

/// Opens `case` with `preset` (the case's default when `None`) on `exposure`.
pub fn open_case(
    case: &str,
    preset: Option<&str>,
    exposure: &ExposureSource,
) -> Result<Arc<dyn ScenarioCase>, CaseError> {
    match case {
        "cut-in" => {
            let preset: CutInPreset = match preset {
                None => CutInPreset::default(),
                Some(p) => p.parse().map_err(CaseError::Preset)?,
            };
            let opened = match exposure {
                ExposureSource::Builtin => CutIn::builtin(preset),
                ExposureSource::Table { name, text } => {
                    CutIn::from_table(text, name.clone(), preset)
                        .map(|(case, _)| case)
                        .map_err(|e: CutInError| CaseError::Exposure {
                            name: name.clone(),
                            reason: e.to_string(),
                        })?
                }
            };
            let preset_name = preset.name().to_owned();
            Ok(Arc::new(Registered {
                case: Arc::new(opened),
                preset: preset_name,
            }))
        }
        "highway-exit" => {
            let preset: HighwayPreset = match preset {
                None => HighwayPreset::default(),
                Some(p) => p.parse().map_err(CaseError::Preset)?,
            };
            if let ExposureSource::Table { name, .. } = exposure {
                return Err(CaseError::Exposure {
                    name: name.clone(),
                    reason: "the highway-exit case has only its built-in exposure model \
                             (docs/models.md); omit the table"
                        .into(),
                });
            }
            Ok(Arc::new(Registered {
                case: Arc::new(HighwayExit::builtin(preset)),
                preset: preset.name().to_owned(),
            }))
        }
        other => Err(CaseError::UnknownCase(other.to_owned())),
    }
}

/// Everything needed to reproduce any test of a campaign from its index:
/// the case, the test distribution and the seed (SPEC §7). The coordinator
/// and the worker build the same sampler from the same plan.
pub struct CampaignSampler {
    pub case: Arc<dyn ScenarioCase>,
    pub distribution: TestDistribution,
    pub seed: u64,
}

impl CampaignSampler {
    /// Tests from `library` with exploration share `epsilon` spread
    /// outside it by `outside`, or from the NDD when `library` is `None`.
    pub fn new(
        case: Arc<dyn ScenarioCase>,
        library: Option<&Library>,
        epsilon: f64,
        outside: OutsideSpread,
        seed: u64,
    ) -> Result<Self, CaseError> {
        let distribution = match library {
            Some(library) => {
                case.check_library(library)?;
                TestDistribution::library(LibraryDistribution::new(
                    library,
                    case.exposure(),
                    epsilon,
                    outside,
                )?)
            }
            None => TestDistribution::Ndd(NddDistribution::new(case.exposure())),
        };
        Ok(Self {
            case,
            distribution,
            seed,
        })
    }

    /// The scenario cell and weight of test `index`.
    pub fn draw(&self, index: u64) -> Draw {
        self.distribution.draw(self.seed, index)
    }
}

/// The adapter from a typed [`Case`] whose vehicles are serde types.
struct Registered<C> {
    case: Arc<C>,
    preset: String,
}

impl<C> Registered<C>
where
    C: Case,
    C::Vehicle: DeserializeOwned,
{
    fn vehicle(&self, spec: &serde_json::Value) -> Result<C::Vehicle, CaseError> {
        serde_json::from_value(spec.clone()).map_err(|e| CaseError::Vehicle {
            case: self.case.name(),
            reason: e.to_string(),
        })
    }
}

impl<C> ScenarioCase for Registered<C>
where
    C: Case + Send + 'static,
    C::Vehicle: DeserializeOwned + Serialize + Send + 'static,
{
    fn name(&self) -> &'static str {
        self.case.name()
    }

    fn preset(&self) -> String {
        self.preset.clone()
    }

    fn exposure(&self) -> &GridMass {
        self.case.exposure()
    }

    fn exposure_name(&self) -> &str {
        self.case.exposure_name()
    }

    fn normalise_vehicle(&self, spec: &serde_json::Value) -> Result<serde_json::Value, CaseError> {
        let vehicle = self.vehicle(spec)?;
        Ok(serde_json::to_value(vehicle).expect("vehicle specifications serialise"))
    }

    fn event_test(&self, spec: &serde_json::Value) -> Result<EventTest, CaseError> {
        let vehicle = self.vehicle(spec)?;
        let case = Arc::clone(&self.case);
        Ok(Arc::new(move |cell| case.is_event(&vehicle, cell)))
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
        library: &Library,
        epsilon: f64,
        outside: OutsideSpread,
        beta: f64,
        confidence: f64,
    ) -> Result<ExactReport, CaseError> {
        let vehicle = self.vehicle(spec)?;
        self.check_library(library)?;
        let q = LibraryDistribution::new(library, self.case.exposure(), epsilon, outside)?;
        Ok(exact_report(
            self.case.as_ref(),
            &vehicle,
            &q,
            beta,
            z_for_confidence(confidence),
        ))
    }

    fn build_library(
        &self,
        surrogate: &serde_json::Value,
        request: &LibraryRequest,
    ) -> Result<Library, CaseError> {
        let vehicle = self.vehicle(surrogate)?;
        let spec = serde_json::to_value(&vehicle).expect("vehicle specifications serialise");
        Ok(build_library(
            self.case.as_ref(),
            &vehicle,
            spec,
            &self.preset,
            request,
        ))
    }

    fn check_library(&self, library: &Library) -> Result<(), CaseError> {
        library.check_matches(self.case.as_ref())?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::library::{SearchMethod, Threshold};
    use serde_json::json;

    #[test]
    fn the_registered_cut_in_case_answers_like_the_typed_one() {
        let case = open_case("cut-in", None, &ExposureSource::Builtin).unwrap();
        let typed = CutIn::builtin(CutInPreset::default());
        let idm = crate::vehicle::VehicleModel::builtin("idm").unwrap();
        let test = case.event_test(&json!({"model": "idm"})).unwrap();
        let events = event_cells(&typed, &idm);
        let mine: Vec<usize> = (0..typed.grid().len()).filter(|&c| test(c)).collect();
        assert_eq!(mine, events);
        let p = case
            .exact_event_probability(&json!({"model": "idm"}))
            .unwrap();
        assert_eq!(p, event_probability(&typed, &events));
        let library = case
            .build_library(
                &json!({"model": "idm"}),
                &LibraryRequest {
                    threshold: Threshold::default(),
                    search: SearchMethod::Exhaustive,
                },
            )
            .unwrap();
        assert_eq!(library.size(), 287);
        case.check_library(&library).unwrap();
    }

    #[test]
    fn bad_names_vehicles_and_tables_get_precise_errors() {
        let err = open_case("lane-keep", None, &ExposureSource::Builtin)
            .err()
            .unwrap();
        assert_eq!(
            err.to_string(),
            "unknown case `lane-keep`; known cases: cut-in, highway-exit"
        );
        let err = open_case("cut-in", Some("fast"), &ExposureSource::Builtin)
            .err()
            .unwrap();
        assert!(err.to_string().contains("fast"), "{err}");
        let table = ExposureSource::Table {
            name: "t.csv".into(),
            text: "range,range_rate\n1,x".into(),
        };
        let err = open_case("cut-in", None, &table).err().unwrap();
        assert!(
            err.to_string()
                .starts_with("exposure table `t.csv` rejected: "),
            "{err}"
        );
        let case = open_case("cut-in", None, &ExposureSource::Builtin).unwrap();
        let err = case
            .event_test(&json!({"model": "idm", "alpha": -1.0}))
            .err()
            .unwrap();
        assert!(err.to_string().contains("alpha"), "{err}");
        let err = case.event_test(&json!({"model": "tesla"})).err().unwrap();
        assert!(err.to_string().contains("unknown variant `tesla`"), "{err}");
    }

    #[test]
    fn the_highway_exit_case_opens_by_name_with_its_presets_and_only_its_own_exposure() {
        let coarse = open_case("highway-exit", Some("coarse"), &ExposureSource::Builtin).unwrap();
        assert_eq!(
            (coarse.name(), coarse.preset()),
            ("highway-exit", "coarse".into())
        );
        assert_eq!(coarse.exposure().grid().len(), 16 * 6 * 16 * 6);
        assert_eq!(coarse.scenario(0), vec![-100.0, 20.0, -100.0, 20.0]);
        let spec = coarse
            .normalise_vehicle(&json!({"model": "gap-seeker"}))
            .unwrap();
        assert_eq!(spec["front_gap"], json!(0.8), "every parameter written out");
        let err = coarse
            .normalise_vehicle(&json!({"model": "mobil", "politeness": 2}))
            .unwrap_err();
        assert!(err.to_string().contains("politeness"), "{err}");
        assert!(coarse.normalise_vehicle(&json!({"model": "idm"})).is_err());
        let table = ExposureSource::Table {
            name: "t.csv".into(),
            text: "0,1\n1,1".into(),
        };
        let err = open_case("highway-exit", None, &table).err().unwrap();
        assert!(
            err.to_string().contains("only its built-in exposure"),
            "{err}"
        );
        let err = open_case("highway-exit", Some("fine"), &ExposureSource::Builtin)
            .err()
            .unwrap();
        assert!(err.to_string().contains("presets are paper"), "{err}");
    }
}
