//! The adapter for the car-following case: libraries are policies in the
//! compact binary file format, and a test samples the BV's actions while it
//! runs, so its weight depends on what the vehicle under test does. The
//! coordinator checks a reported accident of a built-in vehicle by replaying
//! the test (300 steps, microseconds); an external program's cannot be
//! replayed there.

mod campaign;
mod library;

use crate::cases::carfollow::case::{CarFollowing, PolicySolver};
use crate::cases::carfollow::file::PolicyLibraryFile;
use crate::cases::carfollow::library::PolicyLibrary;
use crate::descriptor::CaseDescriptor;
use crate::exact::ExactReport;
use crate::external::NOMINAL_LENGTH;
use crate::library::LibraryFileError;
use crate::registry::picture::PictureMap;
use crate::registry::vut::CampaignVehicle;
use crate::registry::{BuildRequest, CaseError, CaseIdentity, LibrarySearch};
use crate::registry::{CaseViews, ExactAnswers};
use crate::sampling::OutsideSpread;
use crate::vehicle::VehicleModel;
use std::sync::{Arc, Mutex, Weak};

use crate::cases::carfollow::descriptor::NAME;

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
        let vehicle = CarFollowing::vehicle(spec)
            .map_err(|reason| CaseError::Vehicle { case: NAME, reason })?;
        if vehicle.is_noisy() {
            return Err(CaseError::Vehicle {
                case: NAME,
                reason: "a built-in model's noise runs on the grid cases (cut-in); a \
                         car-following test draws its leader's actions per decision, and no \
                         noise stream is defined beside them: run a noisy program instead"
                    .into(),
            });
        }
        Ok(vehicle)
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

impl CaseIdentity for FollowScenarioCase {
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
}

impl ExactAnswers for FollowScenarioCase {
    fn cell_exposures(&self) -> Result<Vec<f64>, CaseError> {
        Err(CaseError::NoExactAnswer(
            "car-following has no grid of scenarios: its tests are sequences of decisions".into(),
        ))
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

impl CaseViews for FollowScenarioCase {
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
}

fn no_exact_answer() -> CaseError {
    CaseError::NoExactAnswer(
        "car-following scenarios are sequences of 33 dimensions: no enumeration gives an \
         exact P(A); compare with a long NDD campaign instead"
            .into(),
    )
}
