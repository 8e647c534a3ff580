//! The `worker_audit_standing` table: audit runs a worker gave back or let
//! expire (in a row, and in all), and the audit of its own results it owes
//! since the last one (`report/dodging.rs` says what follows from them).

use crate::db::sql;
use crate::store::error::StoreError;
use crate::store::states::{AUDIT_OPEN, CAMPAIGN_RUNNING};
use const_format::formatcp;
use rusqlite::{params, Connection};
use serde::Deserialize;

/// How long an audit a worker owes blocks its ranges, at most, in
/// seconds: long enough for others to run it, and a worker whose audit
/// nobody can run (it is alone with the program) waits no longer.
pub const OWED_SECONDS: u32 = 120;

/// A worker's standing in audits.
#[derive(Debug, Clone, Copy, Default, PartialEq, Deserialize)]
pub struct Standing {
    /// Audit runs given back or let expire since it last ran one.
    pub dodged_in_row: i64,
    /// Audit runs given back or let expire in all.
    pub dodged: i64,
    /// The audit of its own results it owes, if that audit is still open
    /// and was owed less than [`OWED_SECONDS`] ago.
    pub owed_open: bool,
}

/// `worker`'s standing (all zero for a worker never counted).
pub fn get(conn: &Connection, worker: &str) -> Result<Standing, StoreError> {
    let row: Option<Standing> = sql::optional(
        conn,
        formatcp!(
            "SELECT s.dodged_in_row, s.dodged, \
               COALESCE(a.state IN {AUDIT_OPEN} AND c.status = {CAMPAIGN_RUNNING} \
                 AND s.updated_at > strftime('%Y-%m-%dT%H:%M:%fZ', 'now', '-{OWED_SECONDS} seconds'), 0) \
               AS owed_open \
             FROM worker_audit_standing s LEFT JOIN audits a ON a.id = s.owed_audit \
             LEFT JOIN campaigns c ON c.id = a.campaign_id WHERE s.worker = ?"
        ),
        [worker],
    )?;
    Ok(row.unwrap_or_default())
}

/// Every counted worker's standing, by name.
pub fn all(conn: &Connection) -> Result<Vec<(String, i64, i64)>, StoreError> {
    Ok(sql::all(
        conn,
        "SELECT worker, dodged_in_row, dodged FROM worker_audit_standing",
        [],
    )?)
}

/// Counts an audit run `worker` gave back or let expire; `owed` is the
/// audit of its own results it now owes, if one could be chosen.
pub fn dodged(conn: &Connection, worker: &str, owed: Option<i64>) -> Result<(), StoreError> {
    sql::execute(
        conn,
        "INSERT INTO worker_audit_standing (worker, dodged_in_row, dodged, owed_audit) \
         VALUES (?1, 1, 1, ?2) \
         ON CONFLICT (worker) DO UPDATE SET dodged_in_row = dodged_in_row + 1, \
           dodged = dodged + 1, owed_audit = ?2, \
           updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')",
        params![worker, owed],
    )?;
    Ok(())
}

/// `worker` ran an audit: its streak of runs given back ends.
pub fn ran_audit(conn: &Connection, worker: &str) -> Result<(), StoreError> {
    sql::execute(
        conn,
        "UPDATE worker_audit_standing SET dodged_in_row = 0, \
           updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now') WHERE worker = ? AND dodged_in_row > 0",
        [worker],
    )?;
    Ok(())
}

/// The ranges `worker` reported to running campaigns of programs that
/// their prefixes have not passed (`(campaign, from, to)`, the part past
/// the prefix), latest first, at most `limit` rows.
pub fn unfolded_ranges(
    conn: &Connection,
    worker: &str,
    limit: usize,
) -> Result<Vec<(i64, u64, u64)>, StoreError> {
    let rows: Vec<(i64, i64, i64)> = sql::all(
        conn,
        formatcp!(
            "SELECT r.campaign_id, MAX(r.from_index, c.indices), r.to_index \
             FROM reports r JOIN campaigns c ON c.id = r.campaign_id \
             WHERE r.worker = ? AND c.status = {CAMPAIGN_RUNNING} AND c.requires IS NOT NULL \
               AND r.to_index > c.indices \
             ORDER BY r.campaign_id DESC, r.from_index DESC LIMIT ?"
        ),
        params![worker, limit as i64],
    )?;
    Ok(rows
        .into_iter()
        .map(|(c, from, to)| (c, from as u64, to as u64))
        .collect())
}
