//! The adapter for grid cases (cut-in, highway-exit): a typed [`Case`] whose
//! vehicles are serde types, libraries of cells in the JSON library format,
//! and tests drawn as a cell and a weight before the vehicle runs.

use super::adaptive_tests::AdaptiveCellCampaign;
use super::picture::{project, PictureMap};
use super::vut::{runner, CampaignVehicle, Runner};
use super::{
    AdaptiveRun, BuildRequest, BuiltLibrary, CampaignTests, CaseError, LibrarySearch,
    LibrarySummary, PlannedTest, ScenarioCase, TestOutcome,
};
use crate::adaptive::{run_adaptive, AdaptiveError, AdaptiveSettings, Planner};
use crate::case::Case;
use crate::descriptor::CaseDescriptor;
use crate::estimator::{z_for_confidence, StoppingRule};
use crate::exact::{event_cells, event_probability, exact_report, ExactReport};
use crate::external::{DriverError, ExternalVehicle, ExternalVut, TestStart};
use crate::library::{
    build_library_observed, library_from_events, Library, LibraryRequest, SearchMethod, Threshold,
};
use crate::progress::Progress;
use crate::sampling::{
    LibraryDistribution, NddDistribution, OutsideSpread, Split, TestDistribution,
};
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::{Arc, OnceLock};

/// The media type of the JSON library file.
const LIBRARY_MEDIA_TYPE: &str = "application/json";

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

    fn campaign(
        &self,
        file: Option<&[u8]>,
        vut: &serde_json::Value,
        epsilon: f64,
        outside: OutsideSpread,
        split: Split,
        seed: u64,
    ) -> Result<Arc<dyn CampaignTests>, CaseError> {
        let vehicle = self.campaign_vehicle(vut)?;
        let (distribution, surrogate) = match file {
            Some(file) => {
                let library = self.library(file)?;
                let distribution = TestDistribution::library(LibraryDistribution::new(
                    &library,
                    self.case.exposure(),
                    epsilon,
                    outside,
                    split,
                )?);
                (distribution, self.vehicle(&library.surrogate).ok())
            }
            None => (
                TestDistribution::Ndd(NddDistribution::new(self.case.exposure())),
                None,
            ),
        };
        Ok(Arc::new(CellCampaign {
            world: self.case.external_world(),
            case: Arc::clone(&self.case),
            vehicle,
            surrogate,
            distribution,
            seed,
            outcomes: OnceLock::new(),
        }))
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

    fn library_picture(&self, file: &[u8]) -> Result<Vec<PictureMap>, CaseError> {
        let library = self.library(file)?;
        let grid = self.case.grid();
        let exposure = self.case.exposure();
        let (x, y) = self.case.picture_axes();
        // The library's own distribution: q(x) = V(x) / W on its cells.
        let mut q = vec![0.0; grid.len()];
        for c in &library.cells {
            q[c.cell] = c.criticality / library.w;
        }
        // The axes' titles with their units, as the case names them.
        let [x_label, y_label] = self.descriptor.picture_axes;
        let labelled = |map: PictureMap| PictureMap {
            x_label: x_label.to_owned(),
            y_label: y_label.to_owned(),
            ..map
        };
        Ok(vec![
            labelled(project(
                grid,
                |cell| exposure.p(cell),
                x,
                y,
                "exposure P(x)",
            )),
            labelled(project(grid, |cell| q[cell], x, y, "library q(x) = V(x)/W")),
        ])
    }

    fn adaptive_campaign(
        &self,
        file: &[u8],
        vut: &serde_json::Value,
        epsilon: f64,
        settings: AdaptiveSettings,
        rule: &StoppingRule,
        seed: u64,
    ) -> Result<AdaptiveRun, CaseError> {
        let vehicle = self.builtin(vut, "an adaptive campaign in this process")?;
        let library = self.library(file)?;
        let run = run_adaptive(
            self.case.as_ref(),
            &vehicle,
            &library,
            epsilon,
            settings,
            rule,
            seed,
        )?;
        self.unfailed(AdaptiveRun::from_grid(run))
    }

    fn adaptive_tests(
        &self,
        file: &[u8],
        vut: &serde_json::Value,
        epsilon: f64,
        settings: AdaptiveSettings,
        rule: &StoppingRule,
        seed: u64,
    ) -> Result<Arc<dyn CampaignTests>, CaseError> {
        if rule.guard_outside {
            return Err(AdaptiveError::Guard.into());
        }
        let vehicle = self.campaign_vehicle(vut)?;
        let library = self.library(file)?;
        let planner = Planner::shared(Arc::clone(&self.case), &library, epsilon, settings)?;
        Ok(Arc::new(AdaptiveCellCampaign::new(
            planner, vehicle, settings, *rule, seed,
        )))
    }

    fn cell_exposures(&self) -> Result<Vec<f64>, CaseError> {
        let exposure = self.case.exposure();
        Ok((0..self.case.grid().len()).map(|c| exposure.p(c)).collect())
    }

    fn dimension_names(&self) -> Vec<String> {
        let axes = self.case.grid().axes();
        axes.iter().map(|a| a.name().to_owned()).collect()
    }

    fn cell_values(&self, cell: usize) -> Option<Vec<f64>> {
        let grid = self.case.grid();
        (cell < grid.len()).then(|| grid.values(cell))
    }

    fn library_criticalities(
        &self,
        file: &[u8],
    ) -> Result<std::collections::HashMap<usize, f64>, CaseError> {
        let library = self.library(file)?;
        Ok(library
            .cells
            .iter()
            .map(|c| (c.cell, c.criticality))
            .collect())
    }

    fn openscenario(&self, cell: usize) -> Option<String> {
        (cell < self.case.grid().len())
            .then(|| self.case.openscenario(cell))
            .flatten()
            .map(|scene| scene.to_xosc())
    }

    fn exact_event_probability(&self, spec: &serde_json::Value) -> Result<f64, CaseError> {
        let vehicle = self.builtin(spec, "an exact answer")?;
        self.unfailed(event_probability(
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
        let vehicle = self.builtin(spec, "an exact answer")?;
        let library = self.library(file)?;
        // The analytic figures are the mixture's (`Var_q(P A/q)`), which the
        // pooled variance of either split estimates.
        let q = LibraryDistribution::new(
            &library,
            self.case.exposure(),
            epsilon,
            outside,
            Split::Random,
        )?;
        self.unfailed(exact_report(
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
    vehicle: CampaignVehicle<C::Vehicle>,
    /// The library's surrogate, for the mismatch count.
    surrogate: Option<C::Vehicle>,
    distribution: TestDistribution,
    seed: u64,
    /// The world block of each `reset` sent to a program.
    world: serde_json::Value,
    /// The built-in vehicle's outcome per cell, for [`CampaignTests::replay`]:
    /// 0 not run yet, 1 no event, 2 event. Allocated on the first replay
    /// (the coordinator's copy), so workers never pay for it.
    outcomes: OnceLock<Vec<AtomicU8>>,
}

/// [`CellCampaign::outcomes`]' codes.
const NOT_RUN: u8 = 0;
const NO_EVENT: u8 = 1;
const EVENT: u8 = 2;

impl<C> CellCampaign<C>
where
    C: Case,
{
    /// The built-in `vehicle`'s outcome of `draw`, each cell simulated
    /// once and remembered.
    fn replay_draw(&self, vehicle: &C::Vehicle, draw: &crate::sampling::Draw) -> TestOutcome {
        let outcomes = self.outcomes.get_or_init(|| {
            (0..self.case.grid().len())
                .map(|_| AtomicU8::new(NOT_RUN))
                .collect()
        });
        let known = outcomes[draw.cell].load(Ordering::Relaxed);
        let event = if known == NOT_RUN {
            let event = self.case.is_event(vehicle, draw.cell);
            outcomes[draw.cell].store(if event { EVENT } else { NO_EVENT }, Ordering::Relaxed);
            event
        } else {
            known == EVENT
        };
        TestOutcome {
            event,
            weight: draw.weight,
        }
    }
}

impl<C> CampaignTests for CellCampaign<C>
where
    C: Case + Send + 'static,
    C::Vehicle: Send + Sync,
{
    fn external(&self) -> Option<&ExternalVut> {
        self.vehicle.external()
    }

    fn run_with(
        &self,
        index: u64,
        program: Option<&mut dyn ExternalVehicle>,
    ) -> Result<TestOutcome, DriverError> {
        let draw = self.distribution.draw(self.seed, index);
        let start = TestStart {
            case: self.case.name(),
            mode: Default::default(),
            index,
            world: &self.world,
        };
        let event = match runner(&self.vehicle, program, start)? {
            Runner::Builtin(vehicle) => self.case.is_event(vehicle, draw.cell),
            Runner::Program(program, mode) => self.case.external_event(program, mode, draw.cell)?,
        };
        Ok(TestOutcome {
            event,
            weight: draw.weight,
        })
    }

    fn run_span(&self, from: u64, to: u64) -> Option<Vec<TestOutcome>> {
        let CampaignVehicle::Builtin(vehicle) = &self.vehicle else {
            return None;
        };
        let draws = self.distribution.draws(self.seed, from, to);
        let cells: Vec<usize> = draws.iter().map(|d| d.cell).collect();
        let mut events = vec![false; cells.len()];
        self.case.events(vehicle, &cells, &mut events);
        Some(
            draws
                .iter()
                .zip(events)
                .map(|(draw, event)| TestOutcome {
                    event,
                    weight: draw.weight,
                })
                .collect(),
        )
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

    fn replay(&self, index: u64) -> Option<TestOutcome> {
        self.replay_explored(index).map(|(outcome, _)| outcome)
    }

    fn replay_explored(&self, index: u64) -> Option<(TestOutcome, bool)> {
        let CampaignVehicle::Builtin(vehicle) = &self.vehicle else {
            return None;
        };
        let draw = self.distribution.draw(self.seed, index);
        let outcome = self.replay_draw(vehicle, &draw);
        Some((outcome, self.distribution.explored(&draw)))
    }

    fn replay_explored_span(&self, from: u64, to: u64) -> Option<Vec<(TestOutcome, bool)>> {
        let CampaignVehicle::Builtin(vehicle) = &self.vehicle else {
            return None;
        };
        let mut outcomes = Vec::with_capacity(to.saturating_sub(from) as usize);
        self.distribution.draw_each(self.seed, from..to, |_, draw| {
            let outcome = self.replay_draw(vehicle, &draw);
            outcomes.push((outcome, self.distribution.explored(&draw)));
        });
        Some(outcomes)
    }

    fn replay_many(&self, indices: &[u64]) -> Option<Vec<TestOutcome>> {
        let CampaignVehicle::Builtin(vehicle) = &self.vehicle else {
            return None;
        };
        let mut outcomes = Vec::with_capacity(indices.len());
        self.distribution
            .draw_each(self.seed, indices.iter().copied(), |_, draw| {
                outcomes.push(self.replay_draw(vehicle, &draw));
            });
        Some(outcomes)
    }

    fn planned(&self, index: u64) -> Option<PlannedTest> {
        let draw = self.distribution.draw(self.seed, index);
        Some(PlannedTest {
            cell: draw.cell,
            scenario: self.case.grid().values(draw.cell),
            weight: draw.weight,
        })
    }

    fn explores(&self, index: u64) -> bool {
        self.distribution.explores(self.seed, index)
    }

    fn strata(&self) -> Option<f64> {
        self.distribution.strata()
    }

    fn outside_mass(&self) -> Option<&crate::outside::OutsideMass> {
        self.distribution.outside_mass()
    }

    fn run_cell(
        &self,
        index: u64,
        cell: usize,
        program: Option<&mut dyn ExternalVehicle>,
    ) -> Result<(bool, Option<f64>), DriverError> {
        if cell >= self.case.grid().len() {
            return Err(DriverError(format!(
                "test {index} names cell {cell}; the grid has {} cells",
                self.case.grid().len()
            )));
        }
        let start = TestStart {
            case: self.case.name(),
            mode: Default::default(),
            index,
            world: &self.world,
        };
        match runner(&self.vehicle, program, start)? {
            Runner::Builtin(vehicle) => {
                let (event, criticality) = self.case.event_and_criticality(vehicle, cell);
                Ok((event, Some(criticality)))
            }
            Runner::Program(program, mode) => self
                .case
                .external_event_and_criticality(program, mode, cell),
        }
    }

    fn surrogate_misses(&self, index: u64) -> bool {
        self.surrogate.as_ref().is_some_and(|surrogate| {
            !self
                .case
                .is_event(surrogate, self.distribution.draw(self.seed, index).cell)
        })
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
