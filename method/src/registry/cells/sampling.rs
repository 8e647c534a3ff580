//! A grid case's campaigns: the library or the NDD sampled, and adaptive
//! campaigns in stages.

use super::campaign::CellCampaign;
use super::Registered;
use crate::adaptive::{run_adaptive, AdaptiveSettings, Planner};
use crate::case::Case;
use crate::estimator::StoppingRule;
use crate::registry::adaptive_tests::AdaptiveCellCampaign;
use crate::registry::vut::CampaignVehicle;
use crate::registry::CampaignSampler;
use crate::registry::{AdaptiveRun, CampaignTests, CaseError};
use crate::sampling::{
    LibraryDistribution, NddDistribution, OutsideSpread, Split, TestDistribution,
};
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::sync::{Arc, OnceLock};

impl<C> CampaignSampler for Registered<C>
where
    C: Case + Send + 'static,
    C::Vehicle: DeserializeOwned + Serialize + Send + Sync + 'static,
{
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
        let vehicle = self.campaign_vehicle(vut)?;
        let library = self.library(file)?;
        let noisy_builtin =
            matches!(&vehicle, CampaignVehicle::Builtin(v) if self.case.is_noisy(v));
        let settings = AdaptiveSettings {
            noisy: settings.noisy || noisy_builtin,
            ..settings
        };
        let planner = Planner::shared(Arc::clone(&self.case), &library, epsilon, settings)?;
        Ok(Arc::new(AdaptiveCellCampaign::new(
            planner, vehicle, settings, *rule, seed,
        )))
    }
}
