//! Car-following campaigns: each test an initial state and the background
//! vehicle's actions drawn from the policy while it runs.

use crate::adaptive::AdaptiveSettings;
use crate::cases::carfollow::adaptive::{
    run_follow_adaptive, FollowAdaptiveSettings, FollowPlanner,
};
use crate::cases::carfollow::sampling::FollowSampler;
use crate::estimator::StoppingRule;
use crate::external::{DriverError, ExternalFollower, ExternalVehicle, ExternalVut, TestStart};
use crate::registry::vut::{runner, CampaignVehicle, Runner};
use crate::registry::CampaignSampler;
use crate::registry::{AdaptiveRun, CampaignTests, CaseError, PlannedTest, TestOutcome};
use crate::sampling::{OutsideSpread, Split};
use crate::vehicle::VehicleModel;
use std::sync::Arc;

use super::FollowScenarioCase;
use crate::cases::carfollow::descriptor::NAME;

impl CampaignSampler for FollowScenarioCase {
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
            noise_seed: crate::noise::noise_seed(self.seed, index),
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

    /// In batches of [`crate::cases::carfollow::batch::LANES`] for the IDM and the FVDM.
    fn run_span(&self, from: u64, to: u64) -> Option<Vec<TestOutcome>> {
        self.replay_many(&(from..to).collect::<Vec<u64>>())
    }

    fn replay_many(&self, indices: &[u64]) -> Option<Vec<TestOutcome>> {
        let CampaignVehicle::Builtin(vut) = &self.vut else {
            return None;
        };
        let follower = crate::cases::carfollow::batch::BatchFollower::of(vut)?;
        Some(
            indices
                .chunks(crate::cases::carfollow::batch::LANES)
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
