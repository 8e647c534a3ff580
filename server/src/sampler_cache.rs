//! The coordinator's copy of each campaign's test sampler, built once (off
//! the async runtime) from the same plan the workers get. It checks the
//! weights workers report and lists tests for clients that ask for them.

use crate::db::Database;
use crate::error::ApiError;
use crate::store::campaigns::CampaignRow;
use crate::store::libraries;
use anyhow::Context;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use tslg_method::library::Library;
use tslg_method::registry::{open_case, CampaignSampler};

#[derive(Default)]
pub struct SamplerCache {
    samplers: Mutex<HashMap<i64, Arc<CampaignSampler>>>,
}

impl SamplerCache {
    pub async fn get(
        &self,
        db: &Database,
        row: &CampaignRow,
    ) -> Result<Arc<CampaignSampler>, ApiError> {
        if let Some(sampler) = self.lock().get(&row.id) {
            return Ok(Arc::clone(sampler));
        }
        let body = match row.library_id {
            Some(id) if row.method == "library" => Some(
                libraries::body(&db.read, id)
                    .await?
                    .with_context(|| format!("library {id} of campaign {} has no body", row.id))?,
            ),
            _ => None,
        };
        let row = row.clone();
        let id = row.id;
        let sampler = tokio::task::spawn_blocking(move || build(&row, body.as_deref()))
            .await
            .context("sampler build task failed")??;
        let sampler = Arc::new(sampler);
        self.lock().insert(id, Arc::clone(&sampler));
        Ok(sampler)
    }

    /// Drops the sampler of a campaign that has stopped.
    pub fn forget(&self, campaign_id: i64) {
        self.lock().remove(&campaign_id);
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<i64, Arc<CampaignSampler>>> {
        self.samplers
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

fn build(row: &CampaignRow, library: Option<&str>) -> anyhow::Result<CampaignSampler> {
    let case = open_case(&row.case_name, Some(&row.preset), &row.exposure_source())?;
    let library = library.map(Library::from_json).transpose()?;
    Ok(CampaignSampler::new(
        case,
        library.as_ref(),
        row.epsilon,
        row.outside().as_str().parse().map_err(anyhow::Error::msg)?,
        row.seed(),
    )?)
}
