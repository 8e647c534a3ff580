//! A campaign made ready to run: its plan, the library file downloaded once
//! per library (JSON for grid cases, the binary Q-table for car-following)
//! and the campaign's tests built from them, cached per campaign.

use std::collections::HashMap;
use std::sync::Arc;
use tslg_api::{CampaignPlan, Method};
use tslg_client::{wire, CallError, Client};
use tslg_method::cases::open_case;
use tslg_method::registry::CampaignTests;

/// What the worker needs to run any test of one campaign.
pub struct PreparedCampaign {
    /// The campaign's tests: scenario, weight and simulation of any index.
    pub tests: Arc<dyn CampaignTests>,
    /// An adaptive campaign's near-miss criticality (its leases name their
    /// tests' cells).
    pub near_miss: Option<f64>,
}

impl PreparedCampaign {
    /// Builds the sampler and vehicle from a plan (CPU work: call off the
    /// async runtime).
    pub fn new(plan: &CampaignPlan, library: Option<&[u8]>) -> anyhow::Result<Self> {
        if let Some(definition) = &plan.user_case {
            tslg_method::cases::user::registry::register(wire::user_case_definition(definition))?;
        }
        let case = open_case(
            &plan.case,
            Some(&plan.preset),
            &wire::exposure_source(&plan.exposure),
        )?;
        let fingerprint = case.exposure_fingerprint();
        anyhow::ensure!(
            fingerprint == plan.exposure_fingerprint,
            "campaign {}: this worker's exposure has fingerprint {fingerprint}, the coordinator's {}",
            plan.campaign_id,
            plan.exposure_fingerprint
        );
        let outside = wire::outside_spread(plan.outside);
        let split = wire::split(plan.split);
        let tests = if plan.method == Method::Enumerate {
            // A library build's surrogate runs.
            case.enumeration(&plan.vut)?
        } else {
            case.campaign(library, &plan.vut, plan.epsilon, outside, split, plan.seed)?
        };
        Ok(Self {
            tests,
            near_miss: plan.near_miss,
        })
    }
}

/// Campaigns and libraries this worker has prepared.
#[derive(Default)]
pub struct Cache {
    campaigns: HashMap<i64, Arc<PreparedCampaign>>,
    /// Library files by id: a library is downloaded once, whatever number
    /// of campaigns use it.
    libraries: HashMap<i64, Arc<Vec<u8>>>,
}

/// Why a campaign could not be prepared.
#[derive(Debug, thiserror::Error)]
pub enum PrepareError {
    /// The coordinator could not be reached or refused.
    #[error(transparent)]
    Call(#[from] CallError),
    /// The plan needs what this worker lacks (e.g. an unknown case or program).
    #[error("campaign cannot run on this worker: {0}")]
    Unusable(String),
}

impl Cache {
    /// The prepared campaign, fetching its plan (and library) on first use.
    pub async fn get(
        &mut self,
        client: &Client,
        campaign: i64,
    ) -> Result<Arc<PreparedCampaign>, PrepareError> {
        if let Some(p) = self.campaigns.get(&campaign) {
            return Ok(Arc::clone(p));
        }
        let plan = client.plan(campaign).await?;
        let library = match (plan.method, plan.library_id) {
            (Method::Library | Method::Adaptive, Some(id)) => Some(self.library(client, id).await?),
            (Method::Library | Method::Adaptive, None) => {
                return Err(PrepareError::Unusable(
                    "library campaign without a library".into(),
                ))
            }
            (Method::Ndd | Method::Enumerate, _) => None,
        };
        let prepared = tokio::task::spawn_blocking(move || {
            PreparedCampaign::new(&plan, library.as_deref().map(Vec::as_slice))
        })
        .await
        .map_err(|e| PrepareError::Unusable(e.to_string()))?
        .map_err(|e| PrepareError::Unusable(format!("{e:#}")))?;
        let prepared = Arc::new(prepared);
        // Keep the cache small: campaigns come and go, libraries stay.
        if self.campaigns.len() >= 64 {
            self.campaigns.clear();
        }
        self.campaigns.insert(campaign, Arc::clone(&prepared));
        Ok(prepared)
    }

    async fn library(&mut self, client: &Client, id: i64) -> Result<Arc<Vec<u8>>, PrepareError> {
        if let Some(l) = self.libraries.get(&id) {
            return Ok(Arc::clone(l));
        }
        let file = Arc::new(client.library_file(id).await?);
        self.libraries.insert(id, Arc::clone(&file));
        Ok(file)
    }
}
