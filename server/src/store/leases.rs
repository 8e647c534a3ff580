//! The `leases` table: claiming work, heartbeats and releases, each fenced
//! on (lease id, worker, attempt) and the attempt's secret key.

use crate::config::Config;
use crate::db::sql;
use crate::db::{now_ms, Database};
use crate::lease_size::{
    lease_size, predicted_unleased, SizingInput, LIBRARY_MAX_LEASE, MAX_INLINE_LEASE, MAX_LEASE,
};
use crate::store::campaigns::{self, CampaignRow, COLUMNS as CAMPAIGN_COLUMNS};
use crate::store::error::StoreError;
use crate::store::{audits, campaign_row};
use rusqlite::{params, Connection};
use std::sync::{Arc, LazyLock};
use subtle::ConstantTimeEq;
use tslg_api::{CampaignStatus, HeartbeatAck, LeaseFence};

/// Where a lease stands: being worked on (or expired, waiting for another
/// worker), fully reported, or cancelled with its campaign.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LeaseState {
    Active,
    Done,
    Cancelled,
}

impl LeaseState {
    /// The state as the `leases` table stores it.
    pub fn as_str(self) -> &'static str {
        match self {
            LeaseState::Active => "active",
            LeaseState::Done => "done",
            LeaseState::Cancelled => "cancelled",
        }
    }
}

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

pub use tslg_api::MAX_THREADS;
/// The longest a lease's work is expected to take for fair sharing, in
/// milliseconds (a day): a campaign's turn never moves further ahead.
const MAX_EXPECTED_MS: i64 = 86_400_000;

/// A fresh lease key: 128 bits from the operating system's generator, as
/// 32 hex digits.
fn new_key() -> String {
    format!("{:032x}", rand::random::<u128>())
}

fn ttl_ms(config: &Config) -> i64 {
    (config.lease_ttl_seconds * 1000.0) as i64
}

/// A lease handed out, with its campaign when the claim read it (a new
/// range; not a lease handed out again or an audit run).
pub struct Claimed {
    pub lease: LeaseRow,
    pub campaign: Option<CampaignRow>,
}

/// Who asks for work and what it takes.
#[derive(Debug, Clone, Copy)]
pub struct Claim<'a> {
    pub worker: &'a str,
    pub threads: u32,
    /// The lease lists its tests (grid cases only; capped in size).
    pub inline: bool,
    /// The external programs the worker runs, `NAME:case:mode`.
    pub offers: &'a [String],
    /// The most tests the worker takes in one lease.
    pub max_tests: Option<u64>,
}

/// Hands out work: first a lease that expired (its holder is presumed
/// lost; the range blocks the prefix), otherwise a new range of the running
/// campaign whose turn comes first. A lease moves its campaign's turn to
/// when the lease's work is expected to be done,
/// `now + size · cost_per_test / threads`, so campaigns get comparable
/// worker time even while their lease sizes differ (a campaign's first
/// leases, before its cost is known, are small). Campaigns of an external
/// vehicle go only to workers that `offers` it (`NAME:case:mode`). `None`
/// when there is nothing to do.
pub async fn claim(
    db: &Database,
    config: &Arc<Config>,
    ask: &Claim<'_>,
) -> Result<Option<Claimed>, StoreError> {
    let job = ClaimJob::new(config, ask);
    let config = Arc::clone(config);
    db.write(move |conn| {
        // In the transaction: a flag set since the route's check still counts.
        audits::refuse_flagged(conn, &job.worker)?;
        claim_in(conn, &config, &job)
    })
    .await
}

/// The cases whose scenarios are drawn while a test runs, as the JSON
/// array bound to a claim's query when its lease lists its tests.
static SEQUENTIAL: LazyLock<String> = LazyLock::new(|| {
    let sequential: Vec<&str> = tslg_method::cases::descriptors()
        .iter()
        .filter(|d| !d.is_grid())
        .map(|d| d.name)
        .collect();
    serde_json::to_string(&sequential).expect("strings serialise")
});

impl ClaimJob {
    /// The claim `ask` as the writer runs it, timed now.
    pub fn new(config: &Config, ask: &Claim<'_>) -> Self {
        let Claim {
            inline,
            offers,
            max_tests,
            ..
        } = *ask;
        let now = now_ms();
        let expires = now + ttl_ms(config);
        let mut span_limit = if inline { MAX_INLINE_LEASE } else { u64::MAX };
        if let Some(most) = max_tests {
            span_limit = span_limit.min(most);
        }
        let span_limit = span_limit.min(i64::MAX as u64) as i64;
        ClaimJob {
            worker: ask.worker.to_string(),
            threads: ask.threads,
            audits: !(inline || offers.is_empty()),
            sequential: inline.then(|| SEQUENTIAL.as_str()),
            offered: serde_json::to_string(offers).expect("strings serialise"),
            span_limit,
            now,
            expires,
        }
    }
}

/// Runs `job` after another write of the same request (a report that asks
/// for the next lease), timed now. A flagged worker gets no lease with the
/// write, and no error: the report stands. `retried_on` is the lease of a
/// report that was all duplicate, a report sent again because its answer
/// was lost: the unstarted lease the first sending took is handed out
/// again rather than a second one (which nobody would hold, blocking its
/// campaign's prefix until it expired).
///
/// No savepoint of its own: every refusal comes before the claim's first
/// write, so what can fail after it is the database itself, and then the
/// whole request's write is rolled back with it (a report goes unrecorded
/// and its worker sends it again). A nested savepoint copied each page the
/// claim touched into the statement journal a second time, about a tenth
/// of the writer's time under load (docs/benchmarks.md).
pub fn claim_after(
    conn: &Connection,
    config: &Config,
    job: &ClaimJob,
    retried_on: Option<i64>,
) -> Result<Option<Claimed>, StoreError> {
    let now = now_ms();
    let job = ClaimJob {
        now,
        expires: now + ttl_ms(config),
        ..job.clone()
    };
    if let Some(reason) = audits::flag_of(conn, &job.worker)? {
        tracing::warn!(worker = %job.worker, %reason, "no next lease with a report: the worker is flagged");
        return Ok(None);
    }
    if let Some(reported) = retried_on {
        if let Some(lease) = unstarted(conn, &job, reported)? {
            return Ok(Some(Claimed {
                lease,
                campaign: None,
            }));
        }
    }
    claim_in(conn, config, &job)
}

/// `lease_id` when its report's acknowledgement `ack` is all duplicate:
/// the report was sent again (see [`claim_after`]).
pub fn retried_on(lease_id: i64, ack: &tslg_api::ResultAck) -> Option<i64> {
    (ack.accepted == 0 && ack.duplicate > 0).then_some(lease_id)
}

/// A live lease of `job`'s worker other than `besides` with nothing
/// reported yet, the newest, if the request `job` could have been given it:
/// a request sent again may ask for less than the first sending did (fewer
/// tests; the tests listed, which caps the lease and keeps the cases whose
/// scenarios are drawn while a test runs, and audits; programs no longer
/// offered), and then gets a new lease as any claim would (the unstarted
/// one expires unused).
fn unstarted(
    conn: &Connection,
    job: &ClaimJob,
    besides: i64,
) -> Result<Option<LeaseRow>, StoreError> {
    let filters = job.filters();
    // An audit's run goes only to a request that may run audits.
    let audits = if job.audits {
        ""
    } else {
        "AND l.audit_id IS NULL"
    };
    let sql = format!(
        "SELECT {COLUMNS} FROM leases WHERE id = (SELECT l.id FROM leases l \
         JOIN campaigns c ON c.id = l.campaign_id \
         WHERE l.state = 'active' AND l.expires_at > ? AND l.worker = ? AND l.id != ? \
           AND l.resume_at = l.start_index AND l.end_index - l.resume_at <= ? {audits} \
           {filters} \
         ORDER BY l.id DESC LIMIT 1)"
    );
    let filter_values = job.filter_values();
    let mut values: Vec<&dyn rusqlite::ToSql> =
        vec![&job.now, &job.worker, &besides, &job.span_limit];
    values.extend(filter_values.iter().map(|v| v as &dyn rusqlite::ToSql));
    Ok(sql::optional(conn, &sql, values.as_slice())?)
}

/// A claim as the writer runs it.
#[derive(Clone)]
pub struct ClaimJob {
    worker: String,
    threads: u32,
    /// Whether the worker may run audits (it offers programs and takes
    /// leases without their tests listed).
    audits: bool,
    /// The cases whose scenarios are drawn while a test runs, as a JSON
    /// array, when the lease lists its tests: a client that needs each
    /// test's scenario in the lease can only take campaigns whose
    /// scenarios are fixed before the test runs, and no whole library
    /// build (`enumerate = 2`).
    sequential: Option<&'static str>,
    /// The programs offered, as a JSON array.
    offered: String,
    span_limit: i64,
    now: i64,
    expires: i64,
}

impl ClaimJob {
    /// The SQL that keeps campaigns a lease that lists its tests cannot
    /// take, and those whose program the worker does not offer; binds the
    /// sequential cases (when listed) and the offered programs, in order.
    fn filters(&self) -> &'static str {
        if self.sequential.is_some() {
            "AND c.case_name NOT IN (SELECT value FROM json_each(?)) AND c.enumerate != 2 \
             AND (c.requires IS NULL OR c.requires IN (SELECT value FROM json_each(?)))"
        } else {
            "AND (c.requires IS NULL OR c.requires IN (SELECT value FROM json_each(?)))"
        }
    }

    /// The filters' bound values.
    fn filter_values(&self) -> Vec<&str> {
        self.sequential
            .into_iter()
            .chain([self.offered.as_str()])
            .collect()
    }
}

/// [`claim`] on the writer connection, for a worker that is not flagged.
fn claim_in(
    conn: &Connection,
    config: &Config,
    job: &ClaimJob,
) -> Result<Option<Claimed>, StoreError> {
    let worker = job.worker.as_str();
    let filters = job.filters();
    let filter_values = job.filter_values();
    // Found first, then taken: usually no lease has expired, and a read
    // that finds nothing costs less than an update that changes nothing.
    // Through the index of active leases by expiry, which holds only the
    // leases out now: without statistics the planner would rather walk
    // every lease, done or not, of each running campaign.
    let sql = format!(
        "SELECT l.id FROM leases l INDEXED BY leases_active \
         JOIN campaigns c ON c.id = l.campaign_id \
         WHERE l.state = 'active' AND l.expires_at < ? AND c.status = 'running' \
           AND l.audit_id IS NULL AND l.end_index - l.resume_at <= ? {filters} \
         ORDER BY l.campaign_id, l.resume_at LIMIT 1"
    );
    let mut values: Vec<&dyn rusqlite::ToSql> = vec![&job.now, &job.span_limit];
    values.extend(filter_values.iter().map(|v| v as &dyn rusqlite::ToSql));
    let expired: Option<(i64,)> = sql::optional(conn, &sql, values.as_slice())?;
    if let Some((id,)) = expired {
        sql::execute(
            conn,
            "UPDATE leases SET attempt = attempt + 1, worker = ?, expires_at = ?, key = ?, \
             claimed_at = ?, threads = ? WHERE id = ?",
            params![worker, job.expires, new_key(), job.now, job.threads, id],
        )?;
        let lease = get(conn, id)?;
        tracing::info!(
            lease = lease.id,
            attempt = lease.attempt,
            worker,
            "expired lease handed out again"
        );
        return Ok(Some(Claimed {
            lease,
            campaign: None,
        }));
    }
    if job.audits {
        if let Some(lease) = claim_audit(conn, job)? {
            return Ok(Some(Claimed {
                lease,
                campaign: None,
            }));
        }
    }
    // A campaign with many tests waiting for their audits gets no new
    // range until workers have run them: audits come first, and the work
    // behind them cannot count before they are done. A campaign of a pair
    // gets a new range only when it is not ahead of the other campaign's:
    // the pair uses only the tests both resolved, so one running ahead
    // (the other's program slow, or offered by no worker) would waste
    // its tests; it is at most a lease ahead.
    let sql = format!(
        "SELECT {CAMPAIGN_COLUMNS} FROM campaigns c WHERE status = 'running' \
         AND next_index < max_tests {filters} \
         AND (stage_end IS NULL OR next_index < stage_end) \
         AND (paired_with IS NULL OR next_index <= \
              (SELECT p.next_index FROM campaigns p WHERE p.id = c.paired_with)) \
         AND (SELECT COUNT(*) FROM audits a WHERE a.campaign_id = c.id \
              AND a.state IN {open}) < {MAX_OPEN_AUDITS} \
         ORDER BY next_turn_at, id LIMIT 1",
        open = audits::OPEN
    );
    let values: Vec<&dyn rusqlite::ToSql> = filter_values
        .iter()
        .map(|v| v as &dyn rusqlite::ToSql)
        .collect();
    let Some(campaign) = campaign_row::first(conn, &sql, values.as_slice())? else {
        return Ok(None);
    };
    let size = new_lease_size(config, &campaign, job.threads).min(job.span_limit as u64);
    let start = campaign.next_index;
    let end = start + size as i64;
    let moved = sql::execute(
        conn,
        "UPDATE campaigns SET next_index = ?, next_turn_at = ? \
         WHERE id = ? AND next_index = ? AND status = 'running'",
        params![
            end,
            job.now
                .saturating_add(expected_ms(&campaign, size, job.threads)),
            campaign.id,
            start
        ],
    )?;
    if moved != 1 {
        return Ok(None);
    }
    // Without `RETURNING` (SQLite buffers its rows in a table of their
    // own): every value of the row is known here but its id.
    let key = new_key();
    sql::execute(
        conn,
        "INSERT INTO leases (campaign_id, start_index, end_index, resume_at, attempt, worker, \
         expires_at, state, key, claimed_at, threads) \
         VALUES (?, ?, ?, ?, 1, ?, ?, 'active', ?, ?, ?)",
        params![
            campaign.id,
            start,
            end,
            start,
            worker,
            job.expires,
            key,
            job.now,
            job.threads
        ],
    )?;
    let lease = LeaseRow {
        id: conn.last_insert_rowid(),
        campaign_id: campaign.id,
        start_index: start,
        end_index: end,
        resume_at: start,
        attempt: 1,
        worker: worker.to_owned(),
        state: LeaseState::Active,
        key,
        claimed_at: job.now,
        threads: i64::from(job.threads),
        audit_id: None,
    };
    Ok(Some(Claimed {
        lease,
        campaign: Some(campaign),
    }))
}

/// A one-test lease for an open audit `job`'s worker may run (see
/// [`crate::report::audit`]): a new lease, or the audit's expired one taken over.
fn claim_audit(conn: &Connection, job: &ClaimJob) -> Result<Option<LeaseRow>, StoreError> {
    let Some(audit) = audits::runnable(conn, &job.worker, &job.offered, job.now)? else {
        return Ok(None);
    };
    if let Some(old) = audit.lease_id {
        sql::execute(
            conn,
            "UPDATE leases SET state = 'cancelled' WHERE id = ? AND state = 'active'",
            [old],
        )?;
    }
    let sql = format!(
        "INSERT INTO leases (campaign_id, start_index, end_index, resume_at, attempt, worker, \
         expires_at, state, key, claimed_at, threads, audit_id) \
         VALUES (?, ?, ?, ?, 1, ?, ?, 'active', ?, ?, ?, ?) RETURNING {COLUMNS}"
    );
    let lease: LeaseRow = sql::one(
        conn,
        &sql,
        params![
            audit.campaign_id,
            audit.test_index,
            audit.test_index + 1,
            audit.test_index,
            job.worker,
            job.expires,
            new_key(),
            job.now,
            job.threads,
            audit.id
        ],
    )?;
    sql::execute(
        conn,
        "UPDATE audits SET lease_id = ? WHERE id = ?",
        [lease.id, audit.id],
    )?;
    tracing::info!(
        audit = audit.id,
        campaign = audit.campaign_id,
        test = audit.test_index,
        worker = job.worker,
        "audit run leased"
    );
    Ok(Some(lease))
}

/// A lease of `from..to` for any worker, expired at once so the next
/// claim takes it: the range of results taken back from a flagged worker.
pub fn insert_redo(conn: &Connection, campaign: i64, from: u64, to: u64) -> Result<(), StoreError> {
    sql::execute(
        conn,
        "INSERT INTO leases (campaign_id, start_index, end_index, resume_at, attempt, worker, \
         expires_at, state, key, claimed_at, threads) \
         VALUES (?, ?, ?, ?, 0, '', 0, 'active', ?, 0, 1)",
        params![campaign, from as i64, to as i64, from as i64, new_key()],
    )?;
    Ok(())
}

/// Cancels the active leases of `campaign` (it stopped): their workers
/// are told to stop at their next heartbeat or report.
pub fn cancel_active(conn: &Connection, campaign: i64) -> Result<(), StoreError> {
    sql::execute(
        conn,
        "UPDATE leases SET state = 'cancelled' WHERE campaign_id = ? AND state = 'active'",
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
        "UPDATE leases SET state = 'active', expires_at = 0 WHERE campaign_id = ? \
         AND state = 'cancelled' AND resume_at < end_index AND audit_id IS NULL",
        [campaign],
    )?;
    Ok(())
}

/// Milliseconds of work a lease of `size` tests is expected to take on
/// `threads` threads, `size · cost / threads`, at most a day; 0 while the
/// campaign's cost is unknown (or not a finite positive number, which the
/// report checks rule out, but the turn must never wrap whatever is stored).
fn expected_ms(campaign: &CampaignRow, size: u64, threads: u32) -> i64 {
    let cost = campaign
        .cost_per_test
        .filter(|c| c.is_finite() && *c > 0.0)
        .unwrap_or(0.0);
    let ms = size as f64 * cost / f64::from(threads.max(1)) * 1000.0;
    ms.round().clamp(0.0, MAX_EXPECTED_MS as f64) as i64
}

/// An adaptive campaign's leases end with its running stage: the next is
/// planned from this one's results.
fn new_lease_size(config: &Config, campaign: &CampaignRow, threads: u32) -> u64 {
    let end = campaign
        .stage_end
        .map_or(campaign.max_tests, |e| e.min(campaign.max_tests));
    let mut budget_left = (end - campaign.next_index).max(0) as u64;
    if campaign.stage_end.is_some() {
        // Its leases list their tests.
        budget_left = budget_left.min(MAX_INLINE_LEASE);
    }
    if let Some(fixed) = config.lease_size {
        return fixed.min(budget_left);
    }
    // A campaign of a pair has no stop of its own to aim at (its fold's
    // rule never converges): its leases grow with its prefix, as before a
    // prediction.
    let rule = campaign.fold_rule();
    let fold = campaign.fold();
    let r = fold.estimator.relative_half_width(rule.z());
    lease_size(&SizingInput {
        threads,
        cost_per_test: campaign.cost_per_test,
        target_seconds: config.lease_target_seconds,
        budget_left,
        predicted_unleased: predicted_unleased(
            fold.estimator.tests(),
            fold.estimator.events(),
            rule.min_events,
            r,
            rule.beta,
            campaign.next_index as u64,
        ),
        resolved: fold.indices,
        max_lease: match campaign.method {
            tslg_api::Method::Library => LIBRARY_MAX_LEASE,
            _ => MAX_LEASE,
        },
    })
}

pub fn get(conn: &Connection, id: i64) -> Result<LeaseRow, StoreError> {
    sql::optional(
        conn,
        &format!("SELECT {COLUMNS} FROM leases WHERE id = ?"),
        [id],
    )?
    .ok_or_else(|| StoreError::NotFound(format!("lease {id} does not exist")))
}

/// Lease `id` for a request of `worker`, refused when `worker` is flagged
/// (checked first: a flagged worker learns that whatever it asks).
pub fn get_unless_flagged(
    conn: &Connection,
    id: i64,
    worker: &str,
) -> Result<LeaseRow, StoreError> {
    audits::refuse_flagged(conn, worker)?;
    get(conn, id)
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
) -> Result<(), StoreError> {
    if lease.worker != worker || lease.attempt != attempt {
        return Err(StoreError::Conflict(format!(
            "lease {} is held by worker `{}` in attempt {}; this request is from worker `{}` \
             for attempt {}: the lease expired and was handed out again",
            lease.id, lease.worker, lease.attempt, worker, attempt
        )));
    }
    if !bool::from(lease.key.as_bytes().ct_eq(key.as_bytes())) {
        return Err(StoreError::NotYours(format!(
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
) -> Result<HeartbeatAck, StoreError> {
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
        let updated = sql::execute(
            conn,
            "UPDATE leases SET expires_at = ? WHERE id = ? AND worker = ? AND attempt = ? \
             AND state = 'active'",
            params![now_ms() + ttl, id, fence.worker, fence.attempt],
        )?;
        Ok(HeartbeatAck {
            proceed: updated == 1,
            campaign_status: status,
            ttl_seconds,
        })
    })
    .await
}

/// Gives a lease back unfinished: it expires now and is handed out again
/// from its first unreported index.
pub async fn release(db: &Database, id: i64, fence: &LeaseFence) -> Result<LeaseRow, StoreError> {
    let fence = fence.clone();
    db.write(move |conn| {
        let lease = get(conn, id)?;
        check_fence(&lease, &fence.worker, fence.attempt, fence.key.as_str())?;
        sql::execute(
            conn,
            "UPDATE leases SET expires_at = 0 WHERE id = ? AND worker = ? AND attempt = ? \
             AND state = 'active'",
            params![id, fence.worker, fence.attempt],
        )?;
        get(conn, id)
    })
    .await
}
