//! Building and reading car-following libraries (policies): dynamic
//! programming or TD learning over every state, and files built elsewhere.

use crate::cases::carfollow::case::PolicySolver;
use crate::cases::carfollow::file::{PolicyHeader, PolicyLibraryFile, MEDIA_TYPE, VERSION};
use crate::library::ExposureRef;
use crate::progress::Progress;
use crate::registry::LibraryBuilder;
use crate::registry::{BuildRequest, BuiltLibrary, CaseError, CaseIdentity, LibrarySummary};

use super::FollowScenarioCase;
use crate::cases::carfollow::descriptor::NAME;

impl LibraryBuilder for FollowScenarioCase {
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
        // Checked against this case's table before anything is allocated:
        // a 292-byte header declaring 2²⁸ values made the coordinator
        // allocate and fill 2 GiB per upload.
        let read =
            PolicyLibraryFile::from_bytes_for(file, self.case.grid.len(), self.case.world.actions)
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
}
