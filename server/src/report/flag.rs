//! Flagging a worker: its requests refused, its results taken back.
//!
//! A worker the replay contradicts, that ends in the minority of an audit,
//! or whose program behaves unlike the others' (by its audits,
//! `report/noisy.rs`, or by its tests, `report/evidence.rs`) is flagged:
//! every result it reported to a campaign that has not been cancelled is
//! taken back and leased to others, and a campaign that had stopped on
//! such results runs again. So the answer is the one honest workers give,
//! whatever the flagged worker did.

use crate::error::ServiceError;
use crate::store::audits;
use crate::store::credentials;
use crate::store::pairs;
use crate::store::{campaigns, leases, reports};
use rusqlite::Connection;
use tslg_api::CampaignStatus;

/// Flags `worker` (caught at test `index` of `campaign`, for `reason`) and
/// takes back its results: see the module's documentation. An enrolled
/// worker's principal is flagged with it, and the results of every worker
/// of that principal are taken back: one principal, one vote, whatever the
/// names it registered. Returns the campaigns whose results changed.
pub fn flag_worker(
    conn: &Connection,
    worker: &str,
    reason: &str,
    campaign: i64,
    index: u64,
) -> Result<Vec<i64>, ServiceError> {
    audits::flag(conn, worker, reason, campaign, index)?;
    let principal = credentials::principal_of(conn, worker)?;
    let mut changed = Vec::new();
    for name in credentials::names_of(conn, &principal)? {
        for id in reports::campaigns_of_worker(conn, &name)? {
            if take_back(conn, id, &name)? && !changed.contains(&id) {
                changed.push(id);
            }
        }
        leases::expire_all_of(conn, &name)?;
        audits::void_runs_of(conn, &name)?;
    }
    tracing::warn!(
        worker,
        principal,
        campaign,
        test = index,
        reason,
        ?changed,
        "worker flagged; its results are taken back"
    );
    Ok(changed)
}

/// Takes back `worker`'s results in `campaign`: its report rows go, their
/// ranges become leases for others, and the estimate is folded again from
/// the start (a campaign that stopped on those results runs again). A
/// cancelled campaign, or one that stopped before them, is left alone.
fn take_back(conn: &Connection, id: i64, worker: &str) -> Result<bool, ServiceError> {
    let campaign = campaigns::get(conn, id)?;
    let ranges = reports::ranges_of_worker(conn, id, worker)?;
    let Some(first) = ranges.first().map(|r| r.0) else {
        return Ok(false);
    };
    let status = campaign.status;
    let stopped = status.is_final();
    // A campaign its pair stopped was decided at the pair's index.
    let decided = pairs::decided_at(conn, &campaign)?.unwrap_or(campaign.indices as u64);
    if matches!(status, CampaignStatus::Cancelled | CampaignStatus::Failed)
        || (stopped && decided <= first as u64)
    {
        return Ok(false);
    }
    for &(from, to) in &ranges {
        reports::delete_range(conn, id, from, to)?;
        leases::insert_redo(conn, id, from as u64, to as u64)?;
    }
    if campaign.method.in_stages() && campaign.indices > first {
        // Later stages were planned from those results: they cannot be
        // planned again without running the campaign again.
        let detail = format!(
            "results of worker `{worker}` from test {first} on were taken back (it was caught \
             reporting what others could not reproduce); the adaptive stages planned from them \
             cannot stand: start the campaign again"
        );
        campaigns::set_failed(conn, id, &detail)?;
        leases::cancel_active(conn, id)?;
        return Ok(true);
    }
    if campaign.indices > first {
        let detail = format!(
            "results of worker `{worker}` from test {first} on were taken back (it was caught \
             reporting what others could not reproduce) and are being run again"
        );
        campaigns::run_again(conn, id, &detail, first)?;
        if stopped {
            // The leases the stop cancelled hold ranges not yet reported.
            leases::reactivate_cancelled(conn, id)?;
            tracing::warn!(campaign = id, worker, "a stopped campaign runs again");
        }
        pairs::reopen(conn, &campaign)?;
    }
    Ok(true)
}
