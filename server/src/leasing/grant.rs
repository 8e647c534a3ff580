//! A lease request granted: the claim the store takes for it ([`super::claim`]),
//! turned into the lease the worker gets (an adaptive campaign's, or one
//! asked for with `include_tests`, lists its tests), and a lease given back
//! when it cannot be handed out or its worker left meanwhile. The route
//! (`routes/leases.rs`) holds a waiting request and answers.

use crate::error::ServiceError;
use crate::leasing::claim as claiming;
use crate::leasing::fence;
use crate::state::AppState;
use crate::store::campaigns;
use tslg_api::{Lease, LeaseFence, LeaseKey, LeaseRequest, TestCase};

/// Why a held lease request ended without a lease.
pub enum Ended {
    /// The store failed.
    Failed(ServiceError),
    /// Its worker left while it was held.
    Left,
}

/// Gives back a lease granted to a worker that has left.
pub async fn give_back(state: &AppState, worker: &str, lease: &Lease) {
    let fence = LeaseFence {
        worker: worker.to_owned(),
        attempt: lease.attempt,
        key: lease.key.clone(),
    };
    match fence::release_as(&state.db, lease.id, &fence, fence::Giver::Coordinator).await {
        Ok(_) => tracing::info!(
            lease = lease.id,
            worker,
            "a lease granted as its worker left; given back"
        ),
        Err(e) => {
            tracing::warn!(lease = lease.id, error = %e, "a lease granted as its worker left could not be given back")
        }
    }
}

/// Hands a checked lease request a range of tests, `None` when there is
/// no work right now.
pub async fn grant(state: &AppState, req: &LeaseRequest) -> Result<Option<Lease>, ServiceError> {
    state.workers.seen(req);
    let fleet = state.workers.fleet();
    match claiming::claim(&state.db, &state.config, &claim_of(req), fleet).await? {
        Some(claimed) => lease_of(state, req, claimed).await.map(Some),
        None => Ok(None),
    }
}

/// The store's claim of a lease request.
pub fn claim_of(req: &LeaseRequest) -> claiming::Claim<'_> {
    claiming::Claim {
        worker: &req.worker,
        threads: req.threads,
        inline: req.include_tests,
        offers: &req.offers,
        max_tests: req.max_tests,
        audits_only: req.audits_only,
    }
}

/// The lease a claim took, as the worker gets it (an adaptive campaign's,
/// or one asked for with `include_tests`, lists its tests). A lease that
/// cannot be made (its tests not listed) is given back at once, so it
/// does not hold its campaign's prefix until it expires.
pub async fn lease_of(
    state: &AppState,
    req: &LeaseRequest,
    claimed: claiming::Claimed,
) -> Result<Lease, ServiceError> {
    let fence = LeaseFence {
        worker: claimed.lease.worker.clone(),
        attempt: claimed.lease.attempt,
        key: LeaseKey(claimed.lease.key.clone()),
    };
    let id = claimed.lease.id;
    let made = make_lease(state, req, claimed).await;
    if let Err(e) = &made {
        tracing::warn!(lease = id, error = %e, "a lease taken could not be handed out; given back");
        match fence::release_as(&state.db, id, &fence, fence::Giver::Coordinator).await {
            Ok(_) => state.work.announce_one(),
            Err(e) => {
                tracing::warn!(lease = id, error = %e, "the lease could not be given back either")
            }
        }
    }
    made
}

/// [`lease_of`] before its error is handled.
async fn make_lease(
    state: &AppState,
    req: &LeaseRequest,
    claimed: claiming::Claimed,
) -> Result<Lease, ServiceError> {
    let row = claimed.lease;
    let campaign = match claimed.campaign {
        Some(campaign) => campaign,
        None => {
            let id = row.campaign_id;
            state.db.read(move |conn| campaigns::get(conn, id)).await?
        }
    };
    // An adaptive campaign's tests are planned by the coordinator stage by
    // stage: every lease names its tests' cells and weights.
    let tests = if req.include_tests || campaign.method.in_stages() {
        let tests = state.samplers.get(&state.db, &campaign).await?;
        let (from, to) = (row.resume_at as u64, row.end_index as u64);
        let list = tokio::task::spawn_blocking(move || {
            (from..to)
                .map(|index| {
                    let planned = tests.planned(index)?;
                    Some(TestCase {
                        index,
                        cell: planned.cell as u64,
                        scenario: planned.scenario,
                        weight: planned.weight,
                    })
                })
                .collect::<Option<Vec<_>>>()
        })
        .await
        .map_err(|e| ServiceError::Internal(e.into()))?
        .ok_or_else(|| {
            ServiceError::Internal(anyhow::anyhow!(
                "campaign {} has no planned tests but was leased with include_tests",
                campaign.id
            ))
        })?;
        Some(list)
    } else {
        None
    };
    let ttl = state.config.lease_ttl_seconds;
    Ok(Lease {
        id: row.id,
        attempt: row.attempt,
        key: LeaseKey(row.key),
        campaign_id: row.campaign_id,
        start: row.start_index as u64,
        end: row.end_index as u64,
        resume_at: row.resume_at as u64,
        ttl_seconds: ttl,
        heartbeat_seconds: ttl / 3.0,
        tests,
        seconds_per_test: campaign.cost_per_test,
        explore_from: campaign.explore_from(),
    })
}

/// The claim a report's `next_lease` asks for, taken in the report's own
/// transaction (`report::receive`).
pub fn next_claim(state: &AppState, next: &LeaseRequest) -> claiming::ClaimJob {
    claiming::ClaimJob::new(&state.config, &claim_of(next), state.workers.fleet())
}
