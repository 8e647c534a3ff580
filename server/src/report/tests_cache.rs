//! The coordinator's copy of each campaign's tests, built once (off the
//! async runtime) from the same plan the workers get. It checks the events
//! workers report and lists tests for clients that ask for them.

use crate::db::Database;
use crate::error::ServiceError;
use crate::report::explored::ExploredRanges;
use crate::store::campaigns::CampaignRow;
use crate::store::{campaigns, leases, libraries};
use anyhow::Context;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use tslg_method::adaptive::AdaptiveSettings;
use tslg_method::cases::open_case;
use tslg_method::registry::CampaignTests;

#[derive(Default)]
pub struct SamplerCache {
    samplers: Mutex<HashMap<i64, Arc<dyn CampaignTests>>>,
    /// Which tests of reported ranges explore, until the fold passes them.
    explored: Arc<ExploredRanges>,
}

impl SamplerCache {
    pub async fn get(
        &self,
        db: &Database,
        row: &CampaignRow,
    ) -> Result<Arc<dyn CampaignTests>, ServiceError> {
        if let Some(sampler) = self.lock().get(&row.id) {
            return Ok(switched(Arc::clone(sampler), row));
        }
        let tests = load(db, row, OnDivergence::Fail).await?;
        self.lock().insert(row.id, Arc::clone(&tests));
        Ok(switched(tests, row))
    }

    /// The campaign's tests, from the cache or built for this caller alone
    /// (a stopped campaign's are not kept: [`Self::forget`]).
    pub async fn peek(
        &self,
        db: &Database,
        row: &CampaignRow,
    ) -> Result<Arc<dyn CampaignTests>, ServiceError> {
        match self.cached(row.id) {
            Some(tests) => Ok(switched(tests, row)),
            None => Ok(switched(load(db, row, OnDivergence::Refuse).await?, row)),
        }
    }

    /// The tests of campaign `id` when they are built already.
    pub fn cached(&self, id: i64) -> Option<Arc<dyn CampaignTests>> {
        self.lock().get(&id).cloned()
    }

    /// Keeps tests already built for a campaign (at its creation).
    pub fn insert(&self, campaign_id: i64, tests: Arc<dyn CampaignTests>) {
        self.lock().insert(campaign_id, tests);
    }

    /// Drops the sampler of a campaign that has stopped, and the
    /// exploring tests kept for its fold.
    pub fn forget(&self, campaign_id: i64) {
        self.lock().remove(&campaign_id);
        self.explored.forget(campaign_id);
    }

    /// The exploring tests the coordinator found in reports it ran whole,
    /// kept for the folds that pass them.
    pub fn explored(&self) -> Arc<ExploredRanges> {
        Arc::clone(&self.explored)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<i64, Arc<dyn CampaignTests>>> {
        self.samplers
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

/// `tests` with the switch `row` records (issue 49): a campaign switches
/// once, in the fold's transaction, and every reader that sees the row
/// after it sees its switch. It is never cleared here: a request holding a
/// row read before the switch must not undo it for the others (its own
/// tests lie below the switch, where both draw alike).
pub fn switched(tests: Arc<dyn CampaignTests>, row: &CampaignRow) -> Arc<dyn CampaignTests> {
    if let Some(from) = row.explore_from() {
        tests.set_explore_from(Some(from));
    }
    tests
}

/// What [`load`] does with an adaptive campaign whose stages its copy
/// cannot reach ([`crate::report::stages::catch_up`]).
#[derive(Clone, Copy, PartialEq)]
enum OnDivergence {
    /// Fails the campaign (for its workers: the lease and report paths).
    Fail,
    /// Only refuses (a read: a view of its tests changes nothing).
    Refuse,
}

/// Builds campaign `row`'s tests off the async runtime, caught up with its
/// stored state.
async fn load(
    db: &Database,
    row: &CampaignRow,
    on_divergence: OnDivergence,
) -> Result<Arc<dyn CampaignTests>, ServiceError> {
    let file = match row.library_id {
        Some(id) if row.method.uses_library() => Some(
            db.read(move |conn| libraries::file(conn, id))
                .await?
                .with_context(|| format!("library {id} of campaign {} has no file", row.id))?
                .bytes,
        ),
        _ => None,
    };
    let row = row.clone();
    let built = row.clone();
    let tests = tokio::task::spawn_blocking(move || build(&built, file.as_deref()))
        .await
        .context("campaign build task failed")??;
    // An adaptive campaign's copy resolves again the stages its stored
    // state has passed.
    let caught_up = Arc::clone(&tests);
    let stored = row.clone();
    let diverged = db
        .read(move |conn| crate::report::stages::catch_up(conn, &stored, &caught_up))
        .await?;
    let Some(reason) = diverged else {
        return Ok(tests);
    };
    if on_divergence == OnDivergence::Fail && !fail_diverged(db, &row, &reason).await? {
        return Err(ServiceError::Conflict(format!(
            "campaign {} moved on while its stages were planned again; ask again",
            row.id
        )));
    }
    Err(ServiceError::Conflict(reason))
}

/// Fails adaptive campaign `row` whose stages its copy cannot reach
/// ([`crate::report::stages::catch_up`]), saying why, unless it moved on
/// meanwhile (then `false`); its leases end. It would otherwise hold its
/// workers on a stage no report can resolve.
async fn fail_diverged(
    db: &Database,
    row: &CampaignRow,
    reason: &str,
) -> Result<bool, ServiceError> {
    let (id, stage) = (row.id, (row.stage_start, row.stage_end));
    let detail = reason.to_string();
    let failed = db
        .write(move |conn| -> Result<bool, ServiceError> {
            let now = campaigns::get(conn, id)?;
            if now.status.is_final() || (now.stage_start, now.stage_end) != stage {
                return Ok(false);
            }
            campaigns::set_failed(conn, id, &detail)?;
            leases::cancel_active(conn, id)?;
            Ok(true)
        })
        .await?;
    if failed {
        tracing::error!(campaign = id, %reason, "adaptive campaign failed");
    }
    Ok(failed)
}

fn build(row: &CampaignRow, file: Option<&[u8]>) -> anyhow::Result<Arc<dyn CampaignTests>> {
    let case = open_case(&row.case_name, Some(&row.preset), &row.exposure_source())?;
    let vut: serde_json::Value = serde_json::from_str(&row.vut)?;
    if row.method.enumerates_cells() {
        return Ok(case.enumeration(&vut)?);
    }
    if row.method.in_stages() {
        let file = file.context("an adaptive campaign needs its library file")?;
        return Ok(case.adaptive_tests(
            file,
            &vut,
            row.epsilon,
            // The width stored at creation, not the one its stage length
            // implies now: a campaign created before the widening keeps
            // the stages it planned (migrations/…36_search_width.sql).
            AdaptiveSettings {
                search_width: row.search_width.max(0) as u64,
                ..tslg_client::wire::adaptive_settings(
                    row.vehicle_noise,
                    row.adaptive_search,
                    row.stage_tests.max(0) as u64,
                )
            },
            &row.rule(),
            row.seed(),
        )?);
    }
    Ok(case.campaign(
        file,
        &vut,
        row.epsilon,
        tslg_client::wire::outside_spread(row.outside),
        tslg_client::wire::split(row.split),
        row.seed(),
    )?)
}
