//! Who may keep, report on or give back a lease: its holder in its
//! current attempt, with the attempt's secret key, and not flagged.

use super::claim::ttl_ms;
use crate::config::Config;
use crate::db::{now_ms, Database};
use crate::error::ServiceError;
use crate::store::audits;
use crate::store::campaigns;
use crate::store::leases::{self, LeaseRow, LeaseState};
use rusqlite::Connection;
use subtle::ConstantTimeEq;
use tslg_api::{CampaignStatus, HeartbeatAck, LeaseFence};

/// Lease `id` for a request of `worker`, refused when `worker` is flagged
/// (checked first: a flagged worker learns that whatever it asks).
pub fn get_unless_flagged(
    conn: &Connection,
    id: i64,
    worker: &str,
) -> Result<LeaseRow, ServiceError> {
    audits::refuse_flagged(conn, worker)?;
    Ok(leases::get(conn, id)?)
}

/// Refuses a caller that does not hold the lease in its current attempt:
/// 409 when the attempt or worker is not the current one (the lease expired
/// and was handed out again; a stale holder stops), 403 when they are but
/// the key is wrong (somebody else's lease). Keys compare in constant time.
pub fn check_fence(
    lease: &LeaseRow,
    worker: &str,
    attempt: i64,
    key: &str,
) -> Result<(), ServiceError> {
    if lease.worker != worker || lease.attempt != attempt {
        return Err(ServiceError::Conflict(format!(
            "lease {} is held by worker `{}` in attempt {}; this request is from worker `{}` \
             for attempt {}: the lease expired and was handed out again",
            lease.id, lease.worker, lease.attempt, worker, attempt
        )));
    }
    if !bool::from(lease.key.as_bytes().ct_eq(key.as_bytes())) {
        return Err(ServiceError::Forbidden(format!(
            "the key does not match lease {}'s attempt {}: only the worker it was handed to \
             may report on it",
            lease.id, lease.attempt
        )));
    }
    Ok(())
}

/// Extends a held lease, or says the campaign no longer needs it.
pub async fn heartbeat(
    db: &Database,
    config: &Config,
    id: i64,
    fence: &LeaseFence,
) -> Result<HeartbeatAck, ServiceError> {
    let fence = fence.clone();
    let ttl_seconds = config.lease_ttl_seconds;
    let ttl = ttl_ms(config);
    db.write(move |conn| {
        let lease = get_unless_flagged(conn, id, &fence.worker)?;
        check_fence(&lease, &fence.worker, fence.attempt, fence.key.as_str())?;
        let campaign = campaigns::get(conn, lease.campaign_id)?;
        let status = campaign.status;
        if lease.state != LeaseState::Active || status != CampaignStatus::Running {
            return Ok(HeartbeatAck {
                proceed: false,
                campaign_status: status,
                ttl_seconds: 0.0,
            });
        }
        let expires_at = now_ms() + ttl;
        let extended = leases::extend(conn, id, &fence.worker, fence.attempt, expires_at)?;
        // An audit's run waiting behind the chunk under way (taken with a
        // report) lives as long as its worker does: a slow program's
        // worker does not let it expire (which counts as giving it back).
        leases::extend_audit_runs_of(conn, &fence.worker, expires_at)?;
        Ok(HeartbeatAck {
            proceed: extended,
            campaign_status: status,
            ttl_seconds,
        })
    })
    .await
}

/// A worker left (`POST /api/v1/workers/{name}/leave`), after giving back
/// the leases it knew of: any lease still its own was granted to a wait it
/// dropped as it stopped (the coordinator answered a request whose
/// worker had gone). It expires now rather than at its TTL, so a fleet
/// that a scheduler stops leaves no range idle for 30 s. How many.
pub async fn expire_left_behind(db: &Database, worker: &str) -> Result<usize, ServiceError> {
    let worker = worker.to_owned();
    Ok(db
        .write(move |conn| leases::expire_all_of(conn, &worker))
        .await?)
}

/// Gives a lease back unfinished: it expires now and is handed out again
/// from its first unreported index.
pub async fn release(db: &Database, id: i64, fence: &LeaseFence) -> Result<LeaseRow, ServiceError> {
    release_as(db, id, fence, Giver::Worker).await
}

/// Who gives a lease back: its worker, or the coordinator, which took a
/// lease it then could not hand out (not the worker's doing).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Giver {
    Worker,
    Coordinator,
}

/// [`release`], saying who gives the lease back: only a worker's giving
/// back an audit's run counts against it.
pub async fn release_as(
    db: &Database,
    id: i64,
    fence: &LeaseFence,
    giver: Giver,
) -> Result<LeaseRow, ServiceError> {
    let fence = fence.clone();
    db.write(move |conn| -> Result<_, ServiceError> {
        // A flagged worker's release is refused as its every lease request
        // is (403, saying why): its leases expired when it was flagged.
        let lease = match giver {
            Giver::Worker => get_unless_flagged(conn, id, &fence.worker)?,
            Giver::Coordinator => leases::get(conn, id)?,
        };
        check_fence(&lease, &fence.worker, fence.attempt, fence.key.as_str())?;
        let audit_run = lease.audit_id.is_some() && lease.state == leases::LeaseState::Active;
        if audit_run && giver == Giver::Coordinator {
            // Handed out again under a new lease, counted against nobody.
            leases::cancel(conn, id)?;
        } else if audit_run {
            // An audit's run given back: it goes to another worker, and it
            // costs its worker (report/dodging.rs).
            leases::cancel(conn, id)?;
            crate::leasing::dodging::gave_back(conn, &fence.worker)?;
        } else {
            leases::expire(conn, id, &fence.worker, fence.attempt)?;
        }
        Ok(leases::get(conn, id)?)
    })
    .await
}
