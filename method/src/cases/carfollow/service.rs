//! The adapter for the car-following case: libraries are policies in the
//! compact binary file format, and a test samples the BV's actions while it
//! runs, so its weight depends on what the vehicle under test does. The
//! coordinator checks a reported accident of a built-in vehicle by replaying
//! the test (300 steps, microseconds); an external program's cannot be
//! replayed there.

use super::adaptive::{run_follow_adaptive, FollowAdaptiveSettings, FollowPlanner};
use crate::adaptive::AdaptiveSettings;
use crate::cases::carfollow::case::{CarFollowing, PolicySolver};
use crate::cases::carfollow::file::{PolicyHeader, PolicyLibraryFile, MEDIA_TYPE, VERSION};
use crate::cases::carfollow::library::PolicyLibrary;
use crate::cases::carfollow::sampling::FollowSampler;
use crate::descriptor::CaseDescriptor;
use crate::estimator::StoppingRule;
use crate::exact::ExactReport;
use crate::external::{
    DriverError, ExternalFollower, ExternalVehicle, ExternalVut, TestStart, NOMINAL_LENGTH,
};
use crate::library::{ExposureRef, LibraryFileError};
use crate::progress::Progress;
use crate::registry::picture::PictureMap;
use crate::registry::vut::{runner, CampaignVehicle, Runner};
use crate::registry::{
    AdaptiveRun, BuildRequest, BuiltLibrary, CampaignTests, CaseError, LibrarySearch,
    LibrarySummary, PlannedTest, ScenarioCase, TestOutcome,
};
use crate::sampling::{OutsideSpread, Split};
use crate::vehicle::VehicleModel;
use std::sync::{Arc, Mutex, Weak};

use super::descriptor::NAME;

pub(super) struct FollowScenarioCase {
    case: CarFollowing,
    fingerprint: String,
    descriptor: CaseDescriptor,
    note: Option<String>,
}

impl FollowScenarioCase {
    pub(super) fn new(case: CarFollowing) -> Self {
        let fingerprint = case.fingerprint();
        Self {
            case,
            fingerprint,
            descriptor: super::descriptor::descriptor(),
            note: None,
        }
    }

    /// The case with `note` on how its exposure was read.
    pub(super) fn with_note(self, note: Option<String>) -> Self {
        Self { note, ..self }
    }

    fn vehicle(&self, spec: &serde_json::Value) -> Result<VehicleModel, CaseError> {
        CarFollowing::vehicle(spec).map_err(|reason| CaseError::Vehicle { case: NAME, reason })
    }

    /// A built-in model or an external program in step mode.
    fn campaign_vehicle(
        &self,
        spec: &serde_json::Value,
    ) -> Result<CampaignVehicle<VehicleModel>, CaseError> {
        CampaignVehicle::parse(NAME, spec, false, |spec| self.vehicle(spec))
    }

    /// The world block of each `reset` sent to a program.
    fn external_world(&self) -> serde_json::Value {
        let w = &self.case.world;
        serde_json::json!({
            "preset": self.case.preset.name(),
            "dt": w.dt,
            "steps_per_decision": w.steps_per_decision,
            "decisions": w.decisions,
            "steps": w.steps_per_decision * w.decisions,
            "acceleration": [w.vut_accel.0, w.vut_accel.1],
            "speed": [w.vut_speed.0, w.vut_speed.1],
            "lead_speed": [w.bv_speed.0, w.bv_speed.1],
            "lead_actions": {"min": w.u_min, "step": w.u_step, "count": w.actions},
            "accident_range": w.accident_range,
            "lanes": 1,
            "vehicle_length": NOMINAL_LENGTH,
        })
    }

    fn solver(&self, request: &BuildRequest) -> Result<PolicySolver, CaseError> {
        let bad = |reason: &str| CaseError::Request {
            case: NAME,
            reason: reason.into(),
        };
        if request.threshold.is_some() {
            return Err(bad(
                "its library holds every state with P(S|s) > 0; it takes no threshold",
            ));
        }
        let solver = match request.search {
            None => PolicySolver::DynamicProgramming,
            Some(LibrarySearch::Policy(solver)) => solver,
            Some(LibrarySearch::Cells(_)) => {
                return Err(bad(
                    "its library is a policy learned over states: search.method is \
                     dynamic-programming or temporal-difference",
                ))
            }
        };
        solver.validate().map_err(|reason| bad(&reason))?;
        Ok(solver)
    }

    /// Reads a library file and checks it was built for this preset and
    /// exposure.
    fn library(&self, file: &[u8]) -> Result<PolicyLibraryFile, CaseError> {
        let read =
            PolicyLibraryFile::from_bytes_for(file, self.case.grid.len(), self.case.world.actions)
                .map_err(|e| CaseError::PolicyFile(e.to_string()))?;
        let h = &read.header;
        if h.case != NAME {
            return Err(LibraryFileError::WrongCase {
                library: h.case.clone(),
                expected: NAME.into(),
            }
            .into());
        }
        if h.exposure.fingerprint != self.fingerprint {
            return Err(LibraryFileError::WrongExposure {
                library: format!("{} ({})", h.exposure.fingerprint, h.preset),
                campaign: format!("{} ({})", self.fingerprint, self.case.preset.name()),
            }
            .into());
        }
        Ok(read)
    }
}

/// Decoded libraries by a hash of their file, held weakly: campaigns on
/// the same library share one 11 MB table, which is freed with the last.
static DECODED: Mutex<Vec<(u64, Weak<PolicyLibrary>)>> = Mutex::new(Vec::new());

/// FNV-1a over the file's bytes.
fn file_hash(file: &[u8]) -> u64 {
    file.iter().fold(0xcbf2_9ce4_8422_2325, |hash, &byte| {
        (hash ^ u64::from(byte)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

impl FollowScenarioCase {
    fn shared_library(&self, file: &[u8]) -> Result<Arc<PolicyLibrary>, CaseError> {
        let hash = file_hash(file);
        let found = {
            let mut decoded = DECODED.lock().unwrap_or_else(|p| p.into_inner());
            decoded.retain(|(_, weak)| weak.strong_count() > 0);
            decoded
                .iter()
                .find(|(h, _)| *h == hash)
                .and_then(|(_, weak)| weak.upgrade())
        };
        // Each file is still read and checked against this case.
        let library = self.library(file)?.library;
        if let Some(shared) = found.filter(|s| **s == library) {
            return Ok(shared);
        }
        let library = Arc::new(library);
        let mut decoded = DECODED.lock().unwrap_or_else(|p| p.into_inner());
        decoded.push((hash, Arc::downgrade(&library)));
        Ok(library)
    }
}

impl ScenarioCase for FollowScenarioCase {
    fn name(&self) -> &'static str {
        NAME
    }

    fn preset(&self) -> String {
        self.case.preset.name().to_owned()
    }

    fn exposure_name(&self) -> &str {
        &self.case.exposure_name
    }

    fn exposure_fingerprint(&self) -> String {
        self.fingerprint.clone()
    }

    fn total_scenarios(&self) -> usize {
        self.case.grid.len()
    }

    fn descriptor(&self) -> &CaseDescriptor {
        &self.descriptor
    }

    fn exposure_note(&self) -> Option<String> {
        self.note.clone()
    }

    fn normalise_vehicle(&self, spec: &serde_json::Value) -> Result<serde_json::Value, CaseError> {
        Ok(self.campaign_vehicle(spec)?.to_spec())
    }

    fn check_request(&self, request: &BuildRequest) -> Result<(), CaseError> {
        self.solver(request).map(|_| ())
    }

    fn build_library_observed(
        &self,
        surrogate: &serde_json::Value,
        request: &BuildRequest,
        progress: &Progress,
    ) -> Result<BuiltLibrary, CaseError> {
        let solver = self.solver(request)?;
        let vehicle = self
            .campaign_vehicle(surrogate)?
            .into_builtin(NAME, "a library's surrogate")?;
        let learned = self
            .case
            .learn_observed(&vehicle, solver, progress)
            .map_err(CaseError::Build)?;
        let file = PolicyLibraryFile {
            header: PolicyHeader {
                version: VERSION,
                case: NAME.into(),
                preset: self.preset(),
                surrogate: serde_json::to_value(vehicle).expect("specifications serialise"),
                exposure: ExposureRef {
                    name: self.case.exposure_name.clone(),
                    fingerprint: self.fingerprint.clone(),
                },
                solver,
                iterations: learned.library.iterations,
                states: self.case.grid.len(),
                actions: self.case.world.actions,
                mu_s: learned.mu_s,
                library_states: learned.library_states,
                library_exposure: learned.library_exposure,
                sm_evaluations: learned.sm_evaluations,
            },
            library: learned.library,
        };
        Ok(BuiltLibrary {
            file: file.to_bytes(),
            media_type: MEDIA_TYPE,
            size: learned.library_states,
            sm_evaluations: learned.sm_evaluations,
            mu_s: learned.mu_s,
            w: learned.mu_s,
        })
    }

    fn campaign(
        &self,
        file: Option<&[u8]>,
        vut: &serde_json::Value,
        epsilon: f64,
        outside: OutsideSpread,
        _split: Split,
        seed: u64,
    ) -> Result<Arc<dyn CampaignTests>, CaseError> {
        let vut = self.campaign_vehicle(vut)?;
        let sampler = match file {
            Some(file) => FollowSampler::library(
                self.case.world,
                self.case.grid,
                &self.case.exposure,
                self.shared_library(file)?,
                epsilon,
                outside,
            )?,
            None => self.case.ndd_sampler(),
        };
        Ok(Arc::new(FollowCampaign {
            sampler,
            vut,
            seed,
            world: self.external_world(),
        }))
    }

    /// A policy is checked for its form only: checking its values would
    /// take solving the Bellman equation again.
    fn built_elsewhere(
        &self,
        file: &[u8],
        _surrogate: &serde_json::Value,
        _sample: usize,
    ) -> Result<BuiltLibrary, CaseError> {
        let summary = self.library_summary(file)?;
        Ok(BuiltLibrary {
            file: file.to_vec(),
            media_type: MEDIA_TYPE,
            size: summary.size,
            sm_evaluations: summary.sm_evaluations,
            mu_s: summary.mu_s,
            w: summary.w,
        })
    }

    fn library_summary(&self, file: &[u8]) -> Result<LibrarySummary, CaseError> {
        let read = PolicyLibraryFile::from_bytes(file)
            .map_err(|e| CaseError::PolicyFile(e.to_string()))?;
        let h = read.header;
        Ok(LibrarySummary {
            case: h.case,
            preset: h.preset,
            surrogate: h.surrogate,
            exposure: h.exposure,
            size: h.library_states,
            total: h.states,
            mu_s: h.mu_s,
            w: h.mu_s,
            gamma: None,
            search: match h.solver {
                PolicySolver::DynamicProgramming => {
                    format!("dynamic programming ({} sweeps)", h.iterations)
                }
                PolicySolver::TemporalDifference { alpha, seed } => format!(
                    "temporal difference (alpha {alpha}, seed {seed}, {} updates)",
                    h.iterations
                ),
            },
            sm_evaluations: h.sm_evaluations,
            recall: None,
        })
    }

    /// Initial states over range and range rate (summed over the BV's
    /// speed): `P(s)` beside the library's `q(s) = P(s) P(S|s) / μ_S`.
    fn library_picture(&self, file: &[u8]) -> Result<Vec<PictureMap>, CaseError> {
        let library = self.library(file)?.library;
        let (grid, initial) = (&self.case.grid, &self.case.initial);
        let mu: f64 = initial
            .iter()
            .zip(&library.challenge)
            .map(|(p, c)| p * c)
            .sum();
        let axis = |(first, n): (f64, usize)| -> Vec<f64> {
            (0..n).map(|k| first + k as f64 * grid.step).collect()
        };
        let map = |title: &str, value: &dyn Fn(usize) -> f64| {
            // s = (i_v · n_R + i_R) · n_Ṙ + i_Ṙ, so s mod (n_R · n_Ṙ) drops i_v.
            let plane = grid.range.1 * grid.range_rate.1;
            let mut values = vec![0.0; plane];
            for s in 0..grid.len() {
                values[s % plane] += value(s);
            }
            PictureMap {
                title: title.to_owned(),
                x_label: self.descriptor.picture_axes[0].into(),
                x_centres: axis(grid.range),
                y_label: self.descriptor.picture_axes[1].into(),
                y_centres: axis(grid.range_rate),
                values,
            }
        };
        Ok(vec![
            map("exposure P(s)", &|s| initial[s]),
            map("library q(s) = P(s) P(S|s) / μ", &|s| {
                if mu > 0.0 {
                    initial[s] * library.challenge[s] / mu
                } else {
                    0.0
                }
            }),
        ])
    }

    /// The policy learned toward the vehicle ([`super::adaptive`], with its
    /// own settings: `settings` are the grid cases').
    fn adaptive_campaign(
        &self,
        file: &[u8],
        vut: &serde_json::Value,
        epsilon: f64,
        _settings: AdaptiveSettings,
        rule: &StoppingRule,
        seed: u64,
    ) -> Result<AdaptiveRun, CaseError> {
        let vehicle = self
            .campaign_vehicle(vut)?
            .into_builtin(NAME, "an adaptive campaign in this process")?;
        let read = self.library(file)?;
        let surrogate = self.vehicle(&read.header.surrogate)?;
        let planner = FollowPlanner::new(
            Arc::new(self.case.clone()),
            &surrogate,
            self.shared_library(file)?,
            epsilon,
            OutsideSpread::Ndd,
            FollowAdaptiveSettings::default(),
        )?;
        let run = run_follow_adaptive(&planner, &vehicle, rule, seed)?;
        Ok(AdaptiveRun {
            driving: run.test_equivalents(self.case.world.decisions),
            result: run.result,
            library_tests: run.library_tests,
            search_tests: run.probes,
            stages: run.stages,
            support: Vec::new(),
            assumes: "the vehicle's failures lie in the region, connected to the accidents its \
                      tests met, where it is dangerous and unlike the surrogate \
                      (docs/adaptive-design.md)",
            search_kind: "probing",
        })
    }

    fn cell_exposures(&self) -> Result<Vec<f64>, CaseError> {
        Err(CaseError::NoExactAnswer(
            "car-following has no grid of scenarios: its tests are sequences of decisions".into(),
        ))
    }

    fn adaptive_tests(
        &self,
        _file: &[u8],
        _vut: &serde_json::Value,
        _epsilon: f64,
        _settings: AdaptiveSettings,
        _rule: &StoppingRule,
        _seed: u64,
    ) -> Result<Arc<dyn CampaignTests>, CaseError> {
        Err(no_adaptive())
    }

    fn exact_event_probability(&self, _: &serde_json::Value) -> Result<f64, CaseError> {
        Err(no_exact_answer())
    }

    fn exact_report(
        &self,
        _: &serde_json::Value,
        _: &[u8],
        _: f64,
        _: OutsideSpread,
        _: f64,
        _: f64,
    ) -> Result<ExactReport, CaseError> {
        Err(no_exact_answer())
    }
}

fn no_exact_answer() -> CaseError {
    CaseError::NoExactAnswer(
        "car-following scenarios are sequences of 33 dimensions: no enumeration gives an \
         exact P(A); compare with a long NDD campaign instead"
            .into(),
    )
}

/// A car-following campaign: test `i` samples its initial state and the
/// BV's 30 actions from the stream `(seed, i)` as the vehicle drives.
struct FollowCampaign {
    sampler: FollowSampler,
    vut: CampaignVehicle<VehicleModel>,
    seed: u64,
    world: serde_json::Value,
}

impl CampaignTests for FollowCampaign {
    fn external(&self) -> Option<&ExternalVut> {
        self.vut.external()
    }

    fn run_with(
        &self,
        index: u64,
        program: Option<&mut dyn ExternalVehicle>,
    ) -> Result<TestOutcome, DriverError> {
        let start = TestStart {
            case: NAME,
            mode: Default::default(),
            index,
            world: &self.world,
        };
        let test = match runner(&self.vut, program, start)? {
            Runner::Builtin(vut) => self.sampler.run(vut, self.seed, index),
            Runner::Program(vut, _) => {
                self.sampler
                    .run_with(&mut ExternalFollower { vut }, self.seed, index)?
            }
        };
        Ok(TestOutcome {
            event: test.accident,
            weight: test.weight(),
        })
    }

    /// In batches of [`super::batch::LANES`] for the IDM and the FVDM.
    fn run_span(&self, from: u64, to: u64) -> Option<Vec<TestOutcome>> {
        self.replay_many(&(from..to).collect::<Vec<u64>>())
    }

    fn replay_many(&self, indices: &[u64]) -> Option<Vec<TestOutcome>> {
        let CampaignVehicle::Builtin(vut) = &self.vut else {
            return None;
        };
        let follower = super::batch::BatchFollower::of(vut)?;
        Some(
            indices
                .chunks(super::batch::LANES)
                .flat_map(|lanes| self.sampler.run_batch(&follower, self.seed, lanes))
                .map(|test| TestOutcome {
                    event: test.accident,
                    weight: test.weight(),
                })
                .collect(),
        )
    }

    /// Replays a built-in vehicle's test. An external program's test
    /// cannot be replayed on the coordinator, and its weight depends on the
    /// program's trajectory: only its range is checked, `0 < w < ∞`.
    fn check_event(&self, index: u64, weight: f64) -> Result<(), String> {
        if self.vut.external().is_some() {
            return if weight.is_finite() && weight > 0.0 {
                Ok(())
            } else {
                Err(format!("event at test {index} reports weight {weight:e}"))
            };
        }
        let replay = self.run(index);
        if !replay.event {
            return Err(format!(
                "test {index} is reported as an accident, but replaying it gives none"
            ));
        }
        if replay.weight.to_bits() != weight.to_bits() {
            return Err(format!(
                "event at test {index} reports weight {weight:e}, but replaying it gives {:e}",
                replay.weight
            ));
        }
        Ok(())
    }

    fn planned(&self, _: u64) -> Option<PlannedTest> {
        None
    }

    fn replay(&self, index: u64) -> Option<TestOutcome> {
        self.vut.external().is_none().then(|| self.run(index))
    }
}

/// Why car-following has no adaptive campaigns (docs/adaptive-design.md).
fn no_adaptive() -> CaseError {
    CaseError::Unsupported(
        "adaptive campaigns run through the service on the grid cases (cut-in, \
         highway-exit); a car-following adaptive campaign probes the vehicle from grid states, \
         which workers cannot be leased yet: run it in process with `tslg library build --case \
         car-following -o POLICY` and `tslg evaluate --library POLICY --method adaptive`"
            .into(),
    )
}
