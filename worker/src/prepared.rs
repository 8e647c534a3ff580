//! A campaign made ready to run: its plan, the library file downloaded once
//! per library (JSON for grid cases, the binary Q-table for car-following)
//! and the campaign's tests built from them, cached per campaign.

use std::collections::HashMap;
use std::sync::Arc;
use tslg_api::CampaignPlan;
use tslg_client::{wire, CallError, Client};
use tslg_method::cases::open_case;
use tslg_method::cases::user;
use tslg_method::external::ProgramHost;
use tslg_method::progress::Progress;
use tslg_method::registry::{BuildRequest, CampaignTests, CaseIdentity, ScenarioCase};

/// Refuses a case whose exposure is not the coordinator's.
fn same_exposure(case: &dyn CaseIdentity, plan: &CampaignPlan) -> anyhow::Result<()> {
    let fingerprint = case.exposure_fingerprint();
    anyhow::ensure!(
        fingerprint == plan.exposure_fingerprint,
        "campaign {}: this worker's exposure has fingerprint {fingerprint}, the coordinator's {}",
        plan.campaign_id,
        plan.exposure_fingerprint
    );
    Ok(())
}

/// What the worker needs to run any test of one campaign.
pub struct PreparedCampaign {
    /// The campaign's tests: scenario, weight and simulation of any index.
    pub tests: Arc<dyn CampaignTests>,
    /// An adaptive campaign's near-miss criticality (its leases name their
    /// tests' cells).
    pub near_miss: Option<f64>,
    /// Another campaign's: the criticality of every test at or below this
    /// is reported, as evidence (`CampaignPlan::criticality_below`).
    pub criticality_below: Option<f64>,
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
        same_exposure(case.as_ref(), plan)?;
        let outside = wire::outside_spread(plan.outside);
        let split = wire::split(plan.split);
        // The worker's copy of the campaign's tests: the one place here a
        // method's sampler is chosen (an adaptive campaign's leases list
        // theirs; its draws from the library serve the checks).
        let tests = if plan.method.enumerates_cells() {
            // A library build's surrogate runs.
            case.enumeration(&plan.vut)?
        } else {
            case.campaign(library, &plan.vut, plan.epsilon, outside, split, plan.seed)?
        };
        Ok(Self {
            tests,
            near_miss: plan.near_miss,
            criticality_below: plan.criticality_below,
        })
    }
}

/// A library build this worker runs whole (a campaign of method `build`):
/// the case, the surrogate and the search, as `tslg library build` gets
/// them.
pub struct WholeBuild {
    case: Arc<dyn ScenarioCase>,
    surrogate: serde_json::Value,
    request: BuildRequest,
}

impl WholeBuild {
    /// The build of `plan`; a user-defined case runs its programs through
    /// `host` (this worker's).
    fn new(plan: &CampaignPlan, host: Option<Arc<dyn ProgramHost>>) -> anyhow::Result<Self> {
        let exposure = wire::exposure_source(&plan.exposure);
        let case = match &plan.user_case {
            Some(definition) => {
                let name = user::registry::register(wire::user_case_definition(definition))?;
                let registered = user::registry::get(&name)
                    .ok_or_else(|| anyhow::anyhow!("case {name} is not registered"))?;
                registered.open(Some(&plan.preset), &exposure, host)?
            }
            None => open_case(&plan.case, Some(&plan.preset), &exposure)?,
        };
        same_exposure(case.as_ref(), plan)?;
        let request = BuildRequest {
            threshold: plan.build_threshold.map(wire::threshold),
            search: plan.build_search.map(wire::library_search),
        };
        case.check_request(&request)?;
        Ok(Self {
            case,
            surrogate: plan.vut.clone(),
            request,
        })
    }

    /// Builds the library: its file, or why the build failed (CPU work on
    /// every thread of the current rayon pool: call off the async runtime).
    pub fn run(&self) -> Result<Vec<u8>, String> {
        self.case
            .build_library_observed(&self.surrogate, &self.request, &Progress::default())
            .map(|built| built.file)
            .map_err(|e| e.to_string())
    }
}

/// What a lease's campaign asks of this worker.
#[derive(Clone)]
pub enum Prepared {
    /// Tests to run and report.
    Tests(Arc<PreparedCampaign>),
    /// A library to build and upload.
    Build(Arc<WholeBuild>),
}

impl Prepared {
    /// The campaign's tests; `None` for a library build.
    pub fn tests(self) -> Option<Arc<PreparedCampaign>> {
        match self {
            Prepared::Tests(p) => Some(p),
            Prepared::Build(_) => None,
        }
    }
}

/// Campaigns and libraries this worker has prepared.
#[derive(Default)]
pub struct Cache {
    /// The programs a user-defined case's library build runs through.
    host: Option<Arc<dyn ProgramHost>>,
    campaigns: HashMap<i64, Prepared>,
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
    /// A cache whose library builds run programs through `host`.
    pub fn with_host(host: Arc<dyn ProgramHost>) -> Self {
        Self {
            host: Some(host),
            ..Self::default()
        }
    }

    /// The prepared campaign, fetching its plan (and library) on first use.
    pub async fn get(&mut self, client: &Client, campaign: i64) -> Result<Prepared, PrepareError> {
        if let Some(p) = self.campaigns.get(&campaign) {
            return Ok(p.clone());
        }
        let plan = client.plan(campaign).await?;
        let library = match (plan.method.uses_library(), plan.library_id) {
            (true, Some(id)) => Some(self.library(client, id).await?),
            (true, None) => {
                return Err(PrepareError::Unusable(format!(
                    "{} campaign without a library",
                    plan.method
                )))
            }
            (false, _) => None,
        };
        let host = self.host.clone();
        let prepared = tokio::task::spawn_blocking(move || {
            if plan.method.runs_whole() {
                return WholeBuild::new(&plan, host).map(|b| Prepared::Build(Arc::new(b)));
            }
            PreparedCampaign::new(&plan, library.as_deref().map(Vec::as_slice))
                .map(|p| Prepared::Tests(Arc::new(p)))
        })
        .await
        .map_err(|e| PrepareError::Unusable(e.to_string()))?
        .map_err(|e| PrepareError::Unusable(format!("{e:#}")))?;
        // Keep the cache small: campaigns come and go, libraries stay.
        if self.campaigns.len() >= 64 {
            self.campaigns.clear();
        }
        self.campaigns.insert(campaign, prepared.clone());
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
