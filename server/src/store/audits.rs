//! The `audits` and `flagged_workers` tables: tests run again by other
//! workers, and the workers caught disagreeing with two others.

use crate::error::ApiError;
use sqlx::{SqliteConnection, SqlitePool};
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
}

/// Where an audit stands (see [`crate::audit`] and the `audits` table).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, sqlx::Type)]
#[sqlx(rename_all = "lowercase")]
pub enum AuditState {
    /// Waits for a second run.
    Replica,
    /// Two runs disagree; a third decides.
    Tiebreak,
    Agreed,
    /// The third run decided and the minority was flagged.
    Settled,
    /// The first run was taken back with its worker.
    Void,
    /// Three runs, three outcomes.
    Undecided,
    /// Still open when its campaign stopped before its test.
    Past,
}

#[derive(Debug, Clone, sqlx::FromRow)]
pub struct AuditRow {
    pub id: i64,
    pub campaign_id: i64,
    pub test_index: i64,
    pub state: AuditState,
    pub first_worker: String,
    pub first_outcome: String,
    pub replica_worker: Option<String>,
    pub replica_outcome: Option<String>,
    pub lease_id: Option<i64>,
}

const COLUMNS: &str = "id, campaign_id, test_index, state, first_worker, first_outcome, \
    replica_worker, replica_outcome, lease_id";

/// States in which an audit waits for a run and holds the campaign's
/// prefix at its test.
pub const OPEN: &str = "('replica', 'tiebreak')";

/// Stores the audits of a report of `worker` on `campaign`. A test whose
/// earlier audit was voided (its first run taken back) is audited afresh.
pub async fn insert(
    conn: &mut SqliteConnection,
    campaign: i64,
    worker: &str,
    audits: &[NewAudit],
) -> Result<(), ApiError> {
    for audit in audits {
        sqlx::query(
            "INSERT INTO audits (campaign_id, test_index, reason, state, first_worker, first_outcome) \
             VALUES (?, ?, ?, 'replica', ?, ?) \
             ON CONFLICT (campaign_id, test_index) DO UPDATE SET reason = excluded.reason, \
               state = 'replica', first_worker = excluded.first_worker, \
               first_outcome = excluded.first_outcome, replica_worker = NULL, \
               replica_outcome = NULL, third_worker = NULL, third_outcome = NULL, lease_id = NULL \
             WHERE audits.state IN ('void', 'past')",
        )
        .bind(campaign)
        .bind(audit.test_index as i64)
        .bind(audit.reason)
        .bind(worker)
        .bind(&audit.first_outcome)
        .execute(&mut *conn)
        .await?;
    }
    Ok(())
}

pub async fn get(conn: &mut SqliteConnection, id: i64) -> Result<AuditRow, ApiError> {
    sqlx::query_as(&format!("SELECT {COLUMNS} FROM audits WHERE id = ?"))
        .bind(id)
        .fetch_optional(&mut *conn)
        .await?
        .ok_or_else(|| ApiError::Internal(anyhow::anyhow!("audit {id} is missing")))
}

/// An open audit that `worker` may run: of a running campaign whose program
/// it offers, not run by it before, and without a live lease.
pub async fn runnable(
    conn: &mut SqliteConnection,
    worker: &str,
    offered: &str,
    now_ms: i64,
) -> Result<Option<AuditRow>, ApiError> {
    let columns: Vec<String> = COLUMNS.split(", ").map(|c| format!("a.{c}")).collect();
    let sql = format!(
        "SELECT {} FROM audits a JOIN campaigns c ON c.id = a.campaign_id \
         LEFT JOIN leases l ON l.id = a.lease_id \
         WHERE a.state IN {OPEN} AND c.status = 'running' \
           AND c.requires IN (SELECT value FROM json_each(?)) \
           AND a.first_worker <> ? AND COALESCE(a.replica_worker, '') <> ? \
           AND (a.lease_id IS NULL OR l.state <> 'active' OR l.expires_at < ?) \
         ORDER BY a.campaign_id, a.test_index LIMIT 1",
        columns.join(", ")
    );
    Ok(sqlx::query_as(&sql)
        .bind(offered)
        .bind(worker)
        .bind(worker)
        .bind(now_ms)
        .fetch_optional(&mut *conn)
        .await?)
}

/// Counts of a campaign's audits by state, for its view.
pub async fn counts(pool: &SqlitePool, campaign: i64) -> Result<Vec<(AuditState, i64)>, ApiError> {
    Ok(
        sqlx::query_as("SELECT state, COUNT(*) FROM audits WHERE campaign_id = ? GROUP BY state")
            .bind(campaign)
            .fetch_all(pool)
            .await?,
    )
}

/// Why `worker` is flagged, if it is.
pub async fn flag_of<'e, E>(executor: E, worker: &str) -> Result<Option<String>, ApiError>
where
    E: sqlx::Executor<'e, Database = sqlx::Sqlite>,
{
    let row: Option<(String,)> =
        sqlx::query_as("SELECT reason FROM flagged_workers WHERE name = ?")
            .bind(worker)
            .fetch_optional(executor)
            .await?;
    Ok(row.map(|(reason,)| reason))
}

/// Refuses a flagged worker (403), inside the transaction that would give
/// it work or take its results, so a flag set meanwhile cannot be missed.
pub async fn refuse_flagged(conn: &mut SqliteConnection, worker: &str) -> Result<(), ApiError> {
    match flag_of(&mut *conn, worker).await? {
        None => Ok(()),
        Some(reason) => Err(flagged_problem(worker, &reason)),
    }
}

/// The 403 a flagged worker gets.
pub fn flagged_problem(worker: &str, reason: &str) -> ApiError {
    ApiError::Forbidden(format!(
        "worker `{worker}` is flagged and gets no work: {reason}; an operator clears the flag \
         with DELETE /api/v1/workers/{worker}/flag"
    ))
}

/// Every flagged worker with why.
pub async fn flagged(pool: &SqlitePool) -> Result<Vec<(String, String)>, ApiError> {
    Ok(
        sqlx::query_as("SELECT name, reason FROM flagged_workers ORDER BY flagged_at")
            .fetch_all(pool)
            .await?,
    )
}

/// Clears a flag; false when the worker was not flagged.
pub async fn unflag(pool: &SqlitePool, worker: &str) -> Result<bool, ApiError> {
    let done = sqlx::query("DELETE FROM flagged_workers WHERE name = ?")
        .bind(worker)
        .execute(pool)
        .await?;
    Ok(done.rows_affected() == 1)
}
