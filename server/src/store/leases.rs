//! The `leases` table: ranges of a campaign's tests handed to a worker,
//! each attempt fenced on (lease id, worker, attempt) and the attempt's
//! secret key. Which lease a request gets, and how large, is decided in
//! `leasing/`; here are its rows.

use crate::db::sql;
use crate::store::audits;
use crate::store::campaign_row::methods_where;
use crate::store::campaign_row::CampaignRow;
use crate::store::error::StoreError;
pub use crate::store::states::LeaseState;
use crate::store::states::{CAMPAIGN_RUNNING, LEASE_ACTIVE, LEASE_CANCELLED, LEASE_DONE};
use const_format::formatcp;
use rusqlite::{params, Connection};
use std::sync::LazyLock;

#[derive(Debug, Clone, serde::Deserialize)]
pub struct LeaseRow {
    pub id: i64,
    pub campaign_id: i64,
    pub start_index: i64,
    pub end_index: i64,
    pub resume_at: i64,
    pub attempt: i64,
    pub worker: String,
    pub state: LeaseState,
    pub key: String,
    /// Unix ms when the current attempt was handed out.
    pub claimed_at: i64,
    /// The threads the current attempt was asked for.
    pub threads: i64,
    /// The audit whose run this one-test lease is.
    pub audit_id: Option<i64>,
}

pub const COLUMNS: &str = "id, campaign_id, start_index, end_index, resume_at, attempt, worker, \
    state, key, claimed_at, threads, audit_id";

/// Open audits past which a campaign gets no new range.
const MAX_OPEN_AUDITS: i64 = 256;

/// A fresh lease key: 128 bits from the operating system's generator, as
/// 32 hex digits.
fn new_key() -> String {
    format!("{:032x}", rand::random::<u128>())
}

/// Which campaigns a worker may be leased: those whose program it offers
/// and, when its lease lists its tests, none whose scenarios are drawn
/// while a test runs and no whole library build (method `build`).
#[derive(Debug, Clone)]
pub struct Eligible {
    /// The cases whose scenarios are drawn while a test runs, as a JSON
    /// array, when the lease lists its tests.
    pub sequential: Option<&'static str>,
    /// The programs offered (`NAME:case:mode`), as a JSON array.
    pub offered: String,
}

impl Eligible {
    /// The SQL that keeps campaigns (`c`) this worker cannot take; binds
    /// the sequential cases (when listed) and the offered programs, in
    /// order ([`Self::values`]).
    /// A whole build is the one test such a worker cannot list.
    fn filters(&self) -> &'static str {
        static LISTED: LazyLock<String> = LazyLock::new(|| {
            format!(
                "AND c.case_name NOT IN (SELECT value FROM json_each(?)) AND c.method NOT IN {} \
                 {PROGRAMS}",
                methods_where(|m| m.builds == Some(tslg_api::BuildWork::Whole))
            )
        });
        const PROGRAMS: &str =
            "AND (c.requires IS NULL OR c.requires IN (SELECT value FROM json_each(?)))";
        if self.sequential.is_some() {
            LISTED.as_str()
        } else {
            PROGRAMS
        }
    }

    /// The filters' bound values.
    fn values(&self) -> Vec<&str> {
        self.sequential
            .into_iter()
            .chain([self.offered.as_str()])
            .collect()
    }
}

/// Who takes a lease now: the worker, its threads, when (unix ms) and until
/// when the attempt is its.
#[derive(Debug, Clone, Copy)]
pub struct Taker<'a> {
    pub worker: &'a str,
    pub threads: u32,
    pub now: i64,
    pub expires: i64,
}

/// The expired lease (its holder presumed lost: the range blocks the
/// prefix) of a running campaign `eligible` allows, with at most
/// `span_limit` tests left, the first by campaign and index.
///
/// Found first, then taken: usually no lease has expired, and a read that
/// finds nothing costs less than an update that changes nothing. Through
/// the index of active leases by expiry, which holds only the leases out
/// now: without statistics the planner would rather walk every lease, done
/// or not, of each running campaign.
pub fn find_expired(
    conn: &Connection,
    eligible: &Eligible,
    now: i64,
    span_limit: i64,
) -> Result<Option<i64>, StoreError> {
    let filters = eligible.filters();
    let sql = format!(
        "SELECT l.id FROM leases l INDEXED BY leases_active \
         JOIN campaigns c ON c.id = l.campaign_id \
         WHERE l.state = {LEASE_ACTIVE} AND l.expires_at < ? AND c.status = {CAMPAIGN_RUNNING} \
           AND l.audit_id IS NULL AND l.end_index - l.resume_at <= ? {filters} \
         ORDER BY l.campaign_id, l.resume_at LIMIT 1"
    );
    let filter_values = eligible.values();
    let mut values: Vec<&dyn rusqlite::ToSql> = vec![&now, &span_limit];
    values.extend(filter_values.iter().map(|v| v as &dyn rusqlite::ToSql));
    let expired: Option<(i64,)> = sql::optional(conn, &sql, values.as_slice())?;
    Ok(expired.map(|(id,)| id))
}

/// Hands lease `id` out again, to `taker`, in a new attempt with a new key.
pub fn take_again(conn: &Connection, id: i64, taker: &Taker<'_>) -> Result<LeaseRow, StoreError> {
    sql::execute(
        conn,
        "UPDATE leases SET attempt = attempt + 1, worker = ?, expires_at = ?, key = ?, \
         claimed_at = ?, threads = ? WHERE id = ?",
        params![
            taker.worker,
            taker.expires,
            new_key(),
            taker.now,
            taker.threads,
            id
        ],
    )?;
    get(conn, id)
}

/// The ids of the running campaigns `eligible` allows with tests left to
/// lease, at most `most`, whose turn comes first (the claim reads them in
/// that order and takes the first that may lease more, `leasing/size.rs`:
/// usually the first, so only its row is read whole). A campaign with
/// many tests waiting for their
/// audits gets no new range until workers have run them: audits come
/// first, and the work behind them cannot count before they are done. A
/// campaign of a pair gets a new range only when it is not ahead of the
/// other campaign's: the pair uses only the tests both resolved, so one
/// running ahead (the other's program slow, or offered by no worker) would
/// waste its tests; it is at most a lease ahead.
pub fn in_turn(
    conn: &Connection,
    eligible: &Eligible,
    most: usize,
) -> Result<Vec<i64>, StoreError> {
    let filters = eligible.filters();
    let sql = format!(
        "SELECT c.id FROM campaigns c WHERE status = {CAMPAIGN_RUNNING} \
         AND next_index < max_tests {filters} \
         AND (stage_end IS NULL OR next_index < stage_end) \
         AND (paired_with IS NULL OR next_index <= \
              (SELECT p.next_index FROM campaigns p WHERE p.id = c.paired_with)) \
         AND (SELECT COUNT(*) FROM audits a WHERE a.campaign_id = c.id \
              AND a.state IN {open}) < {MAX_OPEN_AUDITS} \
         ORDER BY next_turn_at, id LIMIT {most}",
        open = crate::store::states::AUDIT_OPEN
    );
    let filter_values = eligible.values();
    let values: Vec<&dyn rusqlite::ToSql> = filter_values
        .iter()
        .map(|v| v as &dyn rusqlite::ToSql)
        .collect();
    let ids: Vec<(i64,)> = sql::all(conn, &sql, values.as_slice())?;
    Ok(ids.into_iter().map(|(id,)| id).collect())
}

/// Leases `campaign`'s tests `start..end` to `taker` and moves its turn to
/// `turn_at` (unix ms); `None` when another claim moved its `next_index`
/// first.
pub fn insert_range(
    conn: &Connection,
    campaign: &CampaignRow,
    end: i64,
    turn_at: i64,
    taker: &Taker<'_>,
) -> Result<Option<LeaseRow>, StoreError> {
    let start = campaign.next_index;
    let moved = sql::execute(
        conn,
        formatcp!(
            "UPDATE campaigns SET next_index = ?, next_turn_at = ? \
         WHERE id = ? AND next_index = ? AND status = {CAMPAIGN_RUNNING}"
        ),
        params![end, turn_at, campaign.id, start],
    )?;
    if moved != 1 {
        return Ok(None);
    }
    // Without `RETURNING` (SQLite buffers its rows in a table of their
    // own): every value of the row is known here but its id.
    let key = new_key();
    sql::execute(
        conn,
        formatcp!(
            "INSERT INTO leases (campaign_id, start_index, end_index, resume_at, attempt, worker, \
         expires_at, state, key, claimed_at, threads) \
         VALUES (?, ?, ?, ?, 1, ?, ?, {LEASE_ACTIVE}, ?, ?, ?)"
        ),
        params![
            campaign.id,
            start,
            end,
            start,
            taker.worker,
            taker.expires,
            key,
            taker.now,
            taker.threads
        ],
    )?;
    Ok(Some(LeaseRow {
        id: conn.last_insert_rowid(),
        campaign_id: campaign.id,
        start_index: start,
        end_index: end,
        resume_at: start,
        attempt: 1,
        worker: taker.worker.to_owned(),
        state: LeaseState::Active,
        key,
        claimed_at: taker.now,
        threads: i64::from(taker.threads),
        audit_id: None,
    }))
}

/// A one-test lease of `audit` for `taker`; the audit's earlier lease, if
/// any (expired, or its holder gone), is cancelled.
pub fn insert_audit_run(
    conn: &Connection,
    audit: &audits::AuditRow,
    taker: &Taker<'_>,
) -> Result<LeaseRow, StoreError> {
    if let Some(old) = audit.lease_id {
        sql::execute(
            conn,
            formatcp!(
                "UPDATE leases SET state = {LEASE_CANCELLED} WHERE id = ? \
                 AND state = {LEASE_ACTIVE}"
            ),
            [old],
        )?;
    }
    let sql = format!(
        "INSERT INTO leases (campaign_id, start_index, end_index, resume_at, attempt, worker, \
         expires_at, state, key, claimed_at, threads, audit_id) \
         VALUES (?, ?, ?, ?, 1, ?, ?, {LEASE_ACTIVE}, ?, ?, ?, ?) RETURNING {COLUMNS}"
    );
    let lease: LeaseRow = sql::one(
        conn,
        &sql,
        params![
            audit.campaign_id,
            audit.test_index,
            audit.test_index + 1,
            audit.test_index,
            taker.worker,
            taker.expires,
            new_key(),
            taker.now,
            taker.threads,
            audit.id
        ],
    )?;
    sql::execute(
        conn,
        "UPDATE audits SET lease_id = ? WHERE id = ?",
        [lease.id, audit.id],
    )?;
    Ok(lease)
}

/// Which leases a request may be handed (see [`unstarted`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Runs {
    /// Ranges only: the worker runs no audits.
    Ranges,
    /// Ranges and audits' runs.
    Both,
    /// Audits' runs only.
    Audits,
}

/// A live lease of `worker` other than `besides` with nothing reported
/// yet, the newest, that `eligible` allows, of at most `span_limit` tests,
/// of the kind `runs` says (see `leasing::claim_after`).
pub fn unstarted(
    conn: &Connection,
    worker: &str,
    besides: i64,
    eligible: &Eligible,
    (now, span_limit): (i64, i64),
    runs: Runs,
) -> Result<Option<LeaseRow>, StoreError> {
    let filters = eligible.filters();
    // An audit's run goes only to a request that may run audits.
    let audits = match runs {
        Runs::Ranges => "AND l.audit_id IS NULL",
        Runs::Both => "",
        Runs::Audits => "AND l.audit_id IS NOT NULL",
    };
    let sql = format!(
        "SELECT {COLUMNS} FROM leases WHERE id = (SELECT l.id FROM leases l \
         JOIN campaigns c ON c.id = l.campaign_id \
         WHERE l.state = {LEASE_ACTIVE} AND l.expires_at > ? AND l.worker = ? AND l.id != ? \
           AND l.resume_at = l.start_index AND l.end_index - l.resume_at <= ? {audits} \
           {filters} \
         ORDER BY l.id DESC LIMIT 1)"
    );
    let filter_values = eligible.values();
    let mut values: Vec<&dyn rusqlite::ToSql> = vec![&now, &worker, &besides, &span_limit];
    values.extend(filter_values.iter().map(|v| v as &dyn rusqlite::ToSql));
    Ok(sql::optional(conn, &sql, values.as_slice())?)
}

/// A lease of `from..to` for any worker, expired at once so the next
/// claim takes it: the range of results taken back from a flagged worker.
pub fn insert_redo(conn: &Connection, campaign: i64, from: u64, to: u64) -> Result<(), StoreError> {
    sql::execute(
        conn,
        formatcp!(
            "INSERT INTO leases (campaign_id, start_index, end_index, resume_at, attempt, worker, \
         expires_at, state, key, claimed_at, threads) \
         VALUES (?, ?, ?, ?, 0, '', 0, {LEASE_ACTIVE}, ?, 0, 1)"
        ),
        params![campaign, from as i64, to as i64, from as i64, new_key()],
    )?;
    Ok(())
}

/// Cancels the active leases of `campaign` (it stopped): their workers
/// are told to stop at their next heartbeat or report.
pub fn cancel_active(conn: &Connection, campaign: i64) -> Result<(), StoreError> {
    sql::execute(
        conn,
        formatcp!("UPDATE leases SET state = {LEASE_CANCELLED} WHERE campaign_id = ? AND state = {LEASE_ACTIVE}"),
        [campaign],
    )?;
    Ok(())
}

/// The leases a stop cancelled with ranges not yet reported, active again
/// and expired, so that they are leased again first (a stopped campaign
/// that runs again).
pub fn reactivate_cancelled(conn: &Connection, campaign: i64) -> Result<(), StoreError> {
    sql::execute(
        conn,
        formatcp!(
            "UPDATE leases SET state = {LEASE_ACTIVE}, expires_at = 0 WHERE campaign_id = ? \
         AND state = {LEASE_CANCELLED} AND resume_at < end_index AND audit_id IS NULL"
        ),
        [campaign],
    )?;
    Ok(())
}

/// Moves `lease`'s `resume_at` to `to` past a report of its holder in its
/// attempt, keeps it until `expires_at` (a report is a heartbeat) and sets
/// its `state`; `false` when the lease changed since it was read (another
/// report of it came first).
pub fn advance(
    conn: &Connection,
    lease: &LeaseRow,
    to: i64,
    expires_at: i64,
    state: LeaseState,
) -> Result<bool, StoreError> {
    let moved = sql::execute(
        conn,
        formatcp!(
            "UPDATE leases SET resume_at = ?, expires_at = ?, state = ? \
         WHERE id = ? AND worker = ? AND attempt = ? AND resume_at = ? AND state = {LEASE_ACTIVE}"
        ),
        params![
            to,
            expires_at,
            state.as_str(),
            lease.id,
            lease.worker,
            lease.attempt,
            lease.resume_at
        ],
    )?;
    Ok(moved == 1)
}

/// Expires every active lease of `worker` (it was flagged, or it left):
/// each is handed out again to another. How many there were.
pub fn expire_all_of(conn: &Connection, worker: &str) -> Result<usize, StoreError> {
    Ok(sql::execute(
        conn,
        formatcp!("UPDATE leases SET expires_at = 0 WHERE worker = ? AND state = {LEASE_ACTIVE}"),
        [worker],
    )?)
}

/// Keeps `worker`'s active audit runs until `expires_at` (its heartbeat
/// says it is alive).
pub fn extend_audit_runs_of(
    conn: &Connection,
    worker: &str,
    expires_at: i64,
) -> Result<(), StoreError> {
    sql::execute(
        conn,
        formatcp!(
            "UPDATE leases SET expires_at = MAX(expires_at, ?) WHERE worker = ? \
             AND audit_id IS NOT NULL AND state = {LEASE_ACTIVE} AND expires_at > 0"
        ),
        params![expires_at, worker],
    )?;
    Ok(())
}

/// Cancels lease `id` (an audit's run given back: the audit is run by
/// another worker under a new lease).
pub fn cancel(conn: &Connection, id: i64) -> Result<(), StoreError> {
    sql::execute(
        conn,
        formatcp!(
            "UPDATE leases SET state = {LEASE_CANCELLED} WHERE id = ? AND state = {LEASE_ACTIVE}"
        ),
        [id],
    )?;
    Ok(())
}

/// A one-test lease (an audit's run, a whole build), reported: done.
pub fn finish(conn: &Connection, id: i64) -> Result<(), StoreError> {
    sql::execute(
        conn,
        formatcp!("UPDATE leases SET resume_at = end_index, state = {LEASE_DONE} WHERE id = ?"),
        [id],
    )?;
    Ok(())
}

/// Keeps lease `id`'s active attempt `attempt` of `worker` until
/// `expires_at`; whether it was still that attempt.
pub fn extend(
    conn: &Connection,
    id: i64,
    worker: &str,
    attempt: i64,
    expires_at: i64,
) -> Result<bool, StoreError> {
    let updated = sql::execute(
        conn,
        formatcp!(
            "UPDATE leases SET expires_at = ? WHERE id = ? AND worker = ? AND attempt = ? \
         AND state = {LEASE_ACTIVE}"
        ),
        params![expires_at, id, worker, attempt],
    )?;
    Ok(updated == 1)
}

/// Expires lease `id`'s active attempt `attempt` of `worker` now: it is
/// handed out again from its first unreported index.
pub fn expire(conn: &Connection, id: i64, worker: &str, attempt: i64) -> Result<(), StoreError> {
    sql::execute(
        conn,
        formatcp!(
            "UPDATE leases SET expires_at = 0 WHERE id = ? AND worker = ? AND attempt = ? \
         AND state = {LEASE_ACTIVE}"
        ),
        params![id, worker, attempt],
    )?;
    Ok(())
}

pub fn get(conn: &Connection, id: i64) -> Result<LeaseRow, StoreError> {
    sql::optional(
        conn,
        &format!("SELECT {COLUMNS} FROM leases WHERE id = ?"),
        [id],
    )?
    .ok_or_else(|| StoreError::NotFound(format!("lease {id} does not exist")))
}
