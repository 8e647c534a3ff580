//! The `work_spans` table: when each piece of a campaign's work was leased
//! and reported, and when its history points were folded: what
//! [`crate::campaign::timeline`] reads.

use crate::db::sql;
use crate::store::error::StoreError;
use crate::store::leases::LeaseRow;
use rusqlite::{params, Connection};
use serde::Deserialize;

/// One piece of reported work.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WorkSpan {
    pub lease_id: i64,
    /// The worker, numbered in order of first appearance.
    pub worker: u32,
    pub audit: bool,
    pub from_index: i64,
    pub to_index: i64,
    /// When its lease attempt was handed out (Unix ms).
    pub leased_at: i64,
    /// When it was reported (Unix ms).
    pub reported_at: i64,
}

/// Stores a piece of work `from..to` of `lease`, reported now by its
/// holder on its current attempt (an audit run when `audit`).
pub fn insert(
    conn: &Connection,
    lease: &LeaseRow,
    audit: bool,
    (from, to): (u64, u64),
) -> Result<(), StoreError> {
    let mut statement = conn.prepare_cached(
        "INSERT INTO work_spans (campaign_id, lease_id, worker, audit, from_index, to_index, \
         leased_at, reported_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
    )?;
    statement.execute(params![
        lease.campaign_id,
        lease.id,
        lease.worker,
        audit,
        from as i64,
        to as i64,
        lease.claimed_at,
        crate::db::now_ms()
    ])?;
    Ok(())
}

#[derive(Deserialize)]
struct Row {
    lease_id: i64,
    worker: String,
    audit: i64,
    from_index: i64,
    to_index: i64,
    leased_at: i64,
    reported_at: i64,
}

/// `campaign`'s pieces of work by lease and index, each worker numbered
/// (0, 1, … in order of first appearance), and how many workers there
/// were.
pub fn of(conn: &Connection, campaign: i64) -> Result<(Vec<WorkSpan>, u32), StoreError> {
    let rows: Vec<Row> = sql::all(
        conn,
        "SELECT lease_id, worker, audit, from_index, to_index, leased_at, reported_at \
         FROM work_spans WHERE campaign_id = ? ORDER BY lease_id, leased_at, from_index",
        [campaign],
    )?;
    let mut names: std::collections::HashMap<String, u32> = Default::default();
    let spans = rows
        .into_iter()
        .map(|r| {
            let next = names.len() as u32;
            let worker = *names.entry(r.worker).or_insert(next);
            WorkSpan {
                lease_id: r.lease_id,
                worker,
                audit: r.audit != 0,
                from_index: r.from_index,
                to_index: r.to_index,
                leased_at: r.leased_at,
                reported_at: r.reported_at,
            }
        })
        .collect();
    Ok((spans, names.len() as u32))
}

/// `campaign`'s history points that say when they were folded:
/// `(indices, folded_at)` in index order.
pub fn folds(conn: &Connection, campaign: i64) -> Result<Vec<(i64, i64)>, StoreError> {
    let rows: Vec<(i64, i64)> = sql::all(
        conn,
        "SELECT indices, folded_at FROM history WHERE campaign_id = ? AND folded_at IS NOT NULL \
         ORDER BY indices",
        [campaign],
    )?;
    Ok(rows)
}
