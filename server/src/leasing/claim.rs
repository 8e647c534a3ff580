//! Which lease a worker's request gets: first a lease that expired (its
//! holder is presumed lost; the range blocks the prefix), then an open
//! audit's run for a worker that may run audits, otherwise a new range of
//! the running campaign whose turn comes first.

use super::size::{
    lease_limit, lease_size, SizingInput, LIBRARY_MAX_LEASE, MAX_INLINE_LEASE, MAX_LEASE,
};
use crate::config::Config;
use crate::db::{now_ms, Database};
use crate::error::ServiceError;
use crate::leasing::dodging;
use crate::store::campaigns::{self, CampaignRow};
use crate::store::leases::{self, Eligible, LeaseRow, Runs, Taker};
use crate::store::prefix;
use crate::store::{audits, standing};
use crate::workers::Fleet;
use rusqlite::Connection;
use std::sync::{Arc, LazyLock};

pub use tslg_api::MAX_THREADS;

/// Running campaigns a claim considers, in turn order: it takes the first
/// that may lease more (those at their limit wait for results).
const CANDIDATES: usize = 32;

/// The longest a lease's work is expected to take for fair sharing, in
/// milliseconds (a day): a campaign's turn never moves further ahead.
const MAX_EXPECTED_MS: i64 = 86_400_000;

/// A lease's time to live, in milliseconds.
pub fn ttl_ms(config: &Config) -> i64 {
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
    /// Only an audit's run, or nothing.
    pub audits_only: bool,
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
    fleet: Arc<Fleet>,
) -> Result<Option<Claimed>, ServiceError> {
    let job = ClaimJob::new(config, ask, fleet);
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
    pub fn new(config: &Config, ask: &Claim<'_>, fleet: Arc<Fleet>) -> Self {
        let Claim {
            inline,
            offers,
            max_tests,
            audits_only,
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
            eligible: Eligible {
                sequential: inline.then(|| SEQUENTIAL.as_str()),
                offered: serde_json::to_string(offers).expect("strings serialise"),
            },
            span_limit,
            now,
            expires,
            audits_only,
            fleet,
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
) -> Result<Option<Claimed>, ServiceError> {
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
        let runs = match (job.audits, job.audits_only) {
            (false, _) => Runs::Ranges,
            (true, false) => Runs::Both,
            (true, true) => Runs::Audits,
        };
        if let Some(lease) = leases::unstarted(
            conn,
            &job.worker,
            reported,
            &job.eligible,
            (job.now, job.span_limit),
            runs,
        )? {
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

/// A claim as the writer runs it.
#[derive(Clone)]
pub struct ClaimJob {
    worker: String,
    threads: u32,
    /// Whether the worker may run audits (it offers programs and takes
    /// leases without their tests listed).
    audits: bool,
    /// The campaigns the worker may take: those whose program it offers,
    /// and, when the lease lists its tests, only those whose scenarios are
    /// fixed before a test runs and no whole library build.
    eligible: Eligible,
    span_limit: i64,
    now: i64,
    expires: i64,
    /// Only an audit's run, or nothing (a slow program's worker asking
    /// with a report while its lease runs).
    audits_only: bool,
    /// The threads of the live workers, which a campaign's leases are
    /// shared among.
    fleet: Arc<Fleet>,
}

impl ClaimJob {
    /// Who takes the lease, as the store records it.
    fn taker(&self) -> Taker<'_> {
        Taker {
            worker: &self.worker,
            threads: self.threads,
            now: self.now,
            expires: self.expires,
        }
    }
}

/// [`claim`] on the writer connection, for a worker that is not flagged:
/// an expired lease, else an audit's run (for a worker that may run
/// audits), else a new range; only the audit's run when the job asks for
/// audits only.
fn claim_in(
    conn: &Connection,
    config: &Config,
    job: &ClaimJob,
) -> Result<Option<Claimed>, ServiceError> {
    if job.audits_only {
        let lease = if job.audits {
            claim_audit(conn, job)?
        } else {
            None
        };
        return Ok(lease.map(|lease| Claimed {
            lease,
            campaign: None,
        }));
    }
    // A worker that owes an audit of its own results takes no range (of
    // any campaign, whether or not its lease lists its tests) until other
    // workers have decided it; it may run audits (report/dodging.rs).
    if dodging::owes(&standing::get(conn, &job.worker)?) {
        return Ok(match job.audits {
            true => claim_audit(conn, job)?.map(|lease| Claimed {
                lease,
                campaign: None,
            }),
            false => None,
        });
    }
    if let Some(id) = leases::find_expired(conn, &job.eligible, job.now, job.span_limit)? {
        let lease = leases::take_again(conn, id, &job.taker())?;
        tracing::info!(
            lease = lease.id,
            attempt = lease.attempt,
            worker = job.worker,
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
    new_range(conn, config, job)
}

/// A new range of the first campaign in turn that may lease more, sized
/// for the worker ([`new_lease_size`]); its turn moves to when the range's
/// work is expected to be done.
fn new_range(
    conn: &Connection,
    config: &Config,
    job: &ClaimJob,
) -> Result<Option<Claimed>, ServiceError> {
    for id in leases::in_turn(conn, &job.eligible, CANDIDATES)? {
        let campaign = campaigns::get(conn, id)?;
        let serving = job.fleet.serving(campaign.requires.as_deref());
        // An estimation stage's leases follow its recorded results.
        let frontier = match campaign.stage_kind.as_deref() {
            Some("estimate") => Some(prefix::frontier(conn, &campaign)?),
            _ => None,
        };
        let size = new_lease_size(config, &campaign, job.threads, serving, frontier)
            .min(job.span_limit.max(0) as u64);
        if size == 0 {
            continue;
        }
        let end = campaign.next_index + size as i64;
        let turn_at = job
            .now
            .saturating_add(expected_ms(&campaign, size, job.threads));
        let lease = leases::insert_range(conn, &campaign, end, turn_at, &job.taker())?;
        return Ok(lease.map(|lease| Claimed {
            lease,
            campaign: Some(campaign),
        }));
    }
    Ok(None)
}

/// A one-test lease for an open audit `job`'s worker may run (see
/// `report/audit.rs`): a new lease, or the audit's expired one taken over.
fn claim_audit(conn: &Connection, job: &ClaimJob) -> Result<Option<LeaseRow>, ServiceError> {
    let Some(audit) = audits::runnable(conn, &job.worker, &job.eligible.offered, job.now)? else {
        return Ok(None);
    };
    // A run still active here was let expire by its holder (a live worker's
    // heartbeats keep its audit runs: fence.rs).
    if let Some(old) = audit.lease_id {
        dodging::replaced_run(conn, &leases::get(conn, old)?)?;
    }
    let lease = leases::insert_audit_run(conn, &audit, &job.taker())?;
    tracing::info!(
        audit = audit.id,
        campaign = audit.campaign_id,
        test = audit.test_index,
        worker = job.worker,
        "audit run leased"
    );
    Ok(Some(lease))
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

/// The size of a new lease of `campaign` for a worker of `threads`
/// threads, `serving` threads of live workers able to run it
/// ([`lease_size`], up to [`lease_limit`]); 0 when it has leased all it
/// may. `--lease-size` fixes the size (experiments, tests), within the
/// budget and the running stage.
fn new_lease_size(
    config: &Config,
    campaign: &CampaignRow,
    threads: u32,
    serving: u32,
    frontier: Option<u64>,
) -> u64 {
    let next_index = campaign.next_index.max(0) as u64;
    let mut budget_end = campaign
        .stage_end
        .map_or(campaign.max_tests, |e| e.min(campaign.max_tests))
        .max(0) as u64;
    if campaign.stage_end.is_some() {
        // Its leases list their tests.
        budget_end = budget_end.min(next_index + MAX_INLINE_LEASE);
    }
    if let Some(fixed) = config.lease_size {
        return fixed.min(budget_end.saturating_sub(next_index));
    }
    let size = lease_size(&SizingInput {
        threads,
        serving_threads: serving,
        cost_per_test: campaign.cost_per_test,
        target_seconds: config.lease_target_seconds,
        next_index,
        resolved: campaign.indices.max(0) as u64,
        limit: lease_limit(campaign, frontier),
        max_lease: if campaign.method.folds_by_redrawing() {
            LIBRARY_MAX_LEASE
        } else {
            MAX_LEASE
        },
    });
    size.min(budget_end.saturating_sub(next_index))
}
