//! Totals over the tables for `/metrics`: campaigns and libraries by
//! status, the tests resolved (with what deleted campaigns had, so the
//! counters never fall) and the leases out.

use crate::db::sql;
use crate::store::error::StoreError;
use crate::store::states::LEASE_ACTIVE;
use const_format::formatcp;
use rusqlite::Connection;
use tslg_api::{CampaignStatus, LibraryStatus};

/// Campaigns by status (the statuses that have any).
pub fn campaigns_by_status(conn: &Connection) -> Result<Vec<(CampaignStatus, i64)>, StoreError> {
    Ok(sql::all(
        conn,
        "SELECT status, COUNT(*) FROM campaigns GROUP BY status",
        [],
    )?)
}

/// Libraries by status (the statuses that have any).
pub fn libraries_by_status(conn: &Connection) -> Result<Vec<(LibraryStatus, i64)>, StoreError> {
    Ok(sql::all(
        conn,
        "SELECT status, COUNT(*) FROM libraries GROUP BY status",
        [],
    )?)
}

/// Test indices resolved over all campaigns, with their events and
/// invalid tests.
#[derive(Debug, Clone, Copy, Default)]
pub struct ResultTotals {
    pub resolved: i64,
    pub events: i64,
    pub invalid: i64,
}

/// [`ResultTotals`], with what deleted campaigns had: the counters never
/// fall.
pub fn results(conn: &Connection) -> Result<ResultTotals, StoreError> {
    let (resolved, events, invalid): (i64, i64, i64) = sql::one(
        conn,
        "SELECT d.indices + COALESCE(SUM(c.indices), 0), d.events + COALESCE(SUM(c.events), 0), \
         d.invalid + COALESCE(SUM(c.invalid), 0) FROM deleted_totals AS d LEFT JOIN campaigns AS c",
        [],
    )?;
    Ok(ResultTotals {
        resolved,
        events,
        invalid,
    })
}

/// Leases held and not expired, expired and not handed out again, and the
/// attempts after the first of every lease (handed out again).
#[derive(Debug, Clone, Copy, Default)]
pub struct LeaseTotals {
    pub outstanding: i64,
    pub expired: i64,
    pub reclaimed: i64,
}

/// [`LeaseTotals`] at `now` (unix ms).
pub fn leases(conn: &Connection, now: i64) -> Result<LeaseTotals, StoreError> {
    let (outstanding, expired, reclaimed): (i64, i64, i64) = sql::one(
        conn,
        formatcp!(
            "SELECT COALESCE(SUM(state = {LEASE_ACTIVE} AND expires_at >= ?1), 0), \
                COALESCE(SUM(state = {LEASE_ACTIVE} AND expires_at < ?1), 0), \
                COALESCE(SUM(attempt - 1), 0) FROM leases"
        ),
        [now],
    )?;
    Ok(LeaseTotals {
        outstanding,
        expired,
        reclaimed,
    })
}
