//! The `audits` and `flagged_workers` tables: tests run again by other
//! workers, and the workers caught disagreeing with two others.

use crate::db::sql;
use crate::store::credentials;
use crate::store::error::StoreError;
pub use crate::store::states::AuditState;
use crate::store::states::{
    AUDIT_AGREED, AUDIT_OPEN, AUDIT_PAST, AUDIT_REPLICA, AUDIT_TIEBREAK, AUDIT_UNDECIDED,
    AUDIT_VOID, CAMPAIGN_RUNNING, LEASE_ACTIVE,
};
use const_format::formatcp;
use rusqlite::{params, Connection};
use tslg_method::prefix::SparseOutcome;

/// A test's outcome as the audits compare and store it: `none`,
/// `invalid`, or `event:` with the weight's bits (weights compare bit for
/// bit, as duplicate reports do).
pub fn encode(outcome: Option<SparseOutcome>) -> String {
    match outcome {
        None => "none".into(),
        Some(SparseOutcome::Invalid) => "invalid".into(),
        Some(SparseOutcome::Event(w)) => format!("event:{:016x}", w.to_bits()),
    }
}

/// A test chosen for an audit, with why.
#[derive(Debug, Clone, PartialEq)]
pub struct NewAudit {
    pub test_index: u64,
    pub reason: &'static str,
    pub first_outcome: String,
    /// Owed by a worker that gave back an audit run (`report/dodging.rs`).
    pub owed: bool,
}

#[derive(Debug, Clone, serde::Deserialize)]
pub struct AuditRow {
    pub id: i64,
    pub campaign_id: i64,
    pub test_index: i64,
    /// `sample` (chosen by the secret generator, whatever the outcome) or
    /// `weight` (an event heavy in the estimate).
    pub reason: String,
    /// Owed by a worker that gave back an audit run: not chosen by the
    /// secret sample alone.
    pub owed: bool,
    pub state: AuditState,
    pub first_worker: String,
    pub first_outcome: String,
    pub replica_worker: Option<String>,
    pub replica_outcome: Option<String>,
    pub lease_id: Option<i64>,
}

const COLUMNS: &str =
    "id, campaign_id, test_index, reason, owed, state, first_worker, first_outcome, \
    replica_worker, replica_outcome, lease_id";

/// Stores the audits of a report of `worker` on `campaign`. A test whose
/// earlier audit was voided (its first run taken back) is audited afresh.
pub fn insert(
    conn: &Connection,
    campaign: i64,
    worker: &str,
    audits: &[NewAudit],
) -> Result<(), StoreError> {
    for audit in audits {
        sql::execute(
            conn,
            formatcp!("INSERT INTO audits (campaign_id, test_index, reason, owed, state, first_worker, first_outcome) \
             VALUES (?, ?, ?, ?, {AUDIT_REPLICA}, ?, ?) \
             ON CONFLICT (campaign_id, test_index) DO UPDATE SET reason = excluded.reason, \
               owed = excluded.owed, \
               state = {AUDIT_REPLICA}, first_worker = excluded.first_worker, \
               first_outcome = excluded.first_outcome, replica_worker = NULL, \
               replica_outcome = NULL, third_worker = NULL, third_outcome = NULL, lease_id = NULL \
             WHERE audits.state IN ({AUDIT_VOID}, {AUDIT_PAST})"),
            params![
                campaign,
                audit.test_index as i64,
                audit.reason,
                audit.owed,
                worker,
                audit.first_outcome
            ],
        )?;
    }
    Ok(())
}

/// The id of `campaign`'s audit of test `index`, if there is one open.
pub fn open_id_at(conn: &Connection, campaign: i64, index: u64) -> Result<Option<i64>, StoreError> {
    let id: Option<(i64,)> = sql::optional(
        conn,
        formatcp!(
            "SELECT id FROM audits WHERE campaign_id = ? AND test_index = ? \
             AND state IN {AUDIT_OPEN}"
        ),
        params![campaign, index as i64],
    )?;
    Ok(id.map(|(id,)| id))
}

/// The id of an open audit of `worker`'s tests `from..to` of `campaign`,
/// if there is one.
pub fn open_of_in(
    conn: &Connection,
    campaign: i64,
    worker: &str,
    from: u64,
    to: u64,
) -> Result<Option<i64>, StoreError> {
    let id: Option<(i64,)> = sql::optional(
        conn,
        formatcp!(
            "SELECT id FROM audits WHERE campaign_id = ? AND test_index >= ? AND test_index < ? \
             AND first_worker = ? AND state IN {AUDIT_OPEN} LIMIT 1"
        ),
        params![campaign, from as i64, to as i64, worker],
    )?;
    Ok(id.map(|(id,)| id))
}

pub fn get(conn: &Connection, id: i64) -> Result<AuditRow, StoreError> {
    sql::optional(
        conn,
        &format!("SELECT {COLUMNS} FROM audits WHERE id = ?"),
        [id],
    )?
    .ok_or_else(|| StoreError::Database(crate::db::DbError::new(format!("audit {id} is missing"))))
}

/// An open audit that `worker` may run: of a running campaign whose program
/// it offers, not run by its principal before (one vote per principal:
/// `credentials::principal_of`), and without a live lease; first those
/// whose last run was not handed to it (a run it gave back goes to others
/// first, and to it again only when nobody else takes it: with two
/// workers, nobody else may).
pub fn runnable(
    conn: &Connection,
    worker: &str,
    offered: &str,
    now_ms: i64,
) -> Result<Option<AuditRow>, StoreError> {
    let columns: Vec<String> = COLUMNS.split(", ").map(|c| format!("a.{c}")).collect();
    let sql = format!(
        "SELECT {} FROM audits a JOIN campaigns c ON c.id = a.campaign_id \
         LEFT JOIN leases l ON l.id = a.lease_id \
         WHERE a.state IN {AUDIT_OPEN} AND c.status = {CAMPAIGN_RUNNING} \
           AND c.requires IN (SELECT value FROM json_each(?)) \
           AND {first} <> ? AND COALESCE({replica}, '') <> ? \
           AND (a.lease_id IS NULL OR l.state <> {LEASE_ACTIVE} OR l.expires_at < ?) \
         ORDER BY COALESCE(l.worker = ?, 0), a.campaign_id, a.test_index LIMIT 1",
        columns.join(", "),
        first = credentials::principal_sql("a.first_worker"),
        replica = credentials::principal_sql("a.replica_worker"),
    );
    let principal = credentials::principal_of(conn, worker)?;
    Ok(sql::optional(
        conn,
        &sql,
        params![offered, principal, principal, now_ms, worker],
    )?)
}

/// Counts of a campaign's audits by state, for its view.
pub fn counts(conn: &Connection, campaign: i64) -> Result<Vec<(AuditState, i64)>, StoreError> {
    Ok(sql::all(
        conn,
        "SELECT state, COUNT(*) FROM audits WHERE campaign_id = ? GROUP BY state",
        [campaign],
    )?)
}

/// Why `worker` is flagged, if it is.
pub fn flag_of(conn: &Connection, worker: &str) -> Result<Option<String>, StoreError> {
    let row: Option<(String,)> = sql::optional(
        conn,
        &format!("SELECT reason FROM ({FLAGGED}) WHERE name = ?"),
        [worker],
    )?;
    Ok(row.map(|(reason,)| reason))
}

/// Every flagged worker with why and when: those flagged themselves, and
/// the other workers of a principal flagged with one of its own (a flag
/// sticks to the principal, so a new name does not shed it).
const FLAGGED: &str = "\
    SELECT name, reason, flagged_at FROM flagged_workers \
    UNION ALL SELECT c.name, 'its principal `' || p.principal || '` is flagged: ' || p.reason, \
      p.flagged_at FROM worker_credentials c JOIN flagged_principals p ON p.principal = c.principal \
      WHERE c.name NOT IN (SELECT name FROM flagged_workers)";

/// SQL for the flagged principals, as `credentials::principal_of` names
/// them (`@` and the enrolled principal, or a worker's own name).
pub const FLAGGED_PRINCIPALS: &str = "\
    SELECT name FROM flagged_workers UNION SELECT '@' || principal FROM flagged_principals";

/// Refuses a flagged worker (403), inside the transaction that would give
/// it work or take its results, so a flag set meanwhile cannot be missed.
pub fn refuse_flagged(conn: &Connection, worker: &str) -> Result<(), StoreError> {
    match flag_of(conn, worker)? {
        None => Ok(()),
        Some(reason) => Err(flagged_problem(worker, &reason)),
    }
}

/// The 403 a flagged worker gets.
pub fn flagged_problem(worker: &str, reason: &str) -> StoreError {
    StoreError::NotYours(format!(
        "worker `{worker}` is flagged and gets no work: {reason}; an operator clears the flag \
         with DELETE /api/v1/workers/{worker}/flag"
    ))
}

/// Every flagged worker with why.
pub fn flagged(conn: &Connection) -> Result<Vec<(String, String)>, StoreError> {
    Ok(sql::all(
        conn,
        &format!("SELECT name, reason FROM ({FLAGGED}) ORDER BY flagged_at, name"),
        [],
    )?)
}

/// Clears a flag (a write), with its principal's and those of the
/// principal's other workers; false when the worker was not flagged.
pub fn unflag(conn: &Connection, worker: &str) -> Result<bool, StoreError> {
    let own = sql::execute(
        conn,
        "DELETE FROM flagged_workers WHERE name = ?1 OR name IN (SELECT name FROM \
         worker_credentials WHERE principal = (SELECT principal FROM worker_credentials \
         WHERE name = ?1))",
        [worker],
    )? > 0;
    let principal = sql::execute(
        conn,
        "DELETE FROM flagged_principals WHERE principal = \
         (SELECT principal FROM worker_credentials WHERE name = ?)",
        [worker],
    )? == 1;
    Ok(own || principal)
}

/// Records a run of audit `id`: the audit moves to `state`, its `column`
/// run (`replica` or `third`) is `worker`'s with `outcome`, and its lease
/// is done with.
pub fn record_run(
    conn: &Connection,
    id: i64,
    state: AuditState,
    column: RunColumn,
    worker: &str,
    outcome: &str,
) -> Result<(), StoreError> {
    let sql = match column {
        RunColumn::Replica => {
            "UPDATE audits SET state = ?, replica_worker = ?, replica_outcome = ?, \
             lease_id = NULL WHERE id = ?"
        }
        RunColumn::Third => {
            "UPDATE audits SET state = ?, third_worker = ?, third_outcome = ?, \
             lease_id = NULL WHERE id = ?"
        }
    };
    sql::execute(conn, sql, params![state.as_str(), worker, outcome, id])?;
    Ok(())
}

/// Which run of an audit a result is: the second (`replica`) or the one
/// that breaks a tie (`third`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunColumn {
    Replica,
    Third,
}

/// Flags `worker`, caught at test `index` of `campaign` for `reason` (a
/// worker flagged before keeps its first reason).
pub fn flag(
    conn: &Connection,
    worker: &str,
    reason: &str,
    campaign: i64,
    index: u64,
) -> Result<(), StoreError> {
    sql::execute(
        conn,
        "INSERT OR IGNORE INTO flagged_workers (name, reason, campaign_id, test_index) \
         VALUES (?, ?, ?, ?)",
        params![worker, reason, campaign, index as i64],
    )?;
    // An enrolled worker's principal is flagged with it.
    sql::execute(
        conn,
        "INSERT OR IGNORE INTO flagged_principals (principal, reason) \
         SELECT principal, ? FROM worker_credentials WHERE name = ? AND principal IS NOT NULL",
        params![
            format!("its worker `{worker}` was flagged: {reason}"),
            worker
        ],
    )?;
    Ok(())
}

/// Takes a flagged worker's runs out of the audits: the audits of its
/// first runs are void (its results are taken back, and the tests run
/// again may be audited afresh), and a tie it made waits for another
/// second run.
pub fn void_runs_of(conn: &Connection, worker: &str) -> Result<(), StoreError> {
    sql::execute(
        conn,
        formatcp!(
            "UPDATE audits SET state = {AUDIT_VOID}, lease_id = NULL \
         WHERE first_worker = ? AND state IN ({AUDIT_REPLICA}, {AUDIT_TIEBREAK}, {AUDIT_AGREED}, \
           {AUDIT_UNDECIDED})"
        ),
        [worker],
    )?;
    sql::execute(
        conn,
        formatcp!("UPDATE audits SET state = {AUDIT_REPLICA}, replica_worker = NULL, replica_outcome = NULL, \
         lease_id = NULL WHERE replica_worker = ? AND state = {AUDIT_TIEBREAK}"),
        [worker],
    )?;
    Ok(())
}
