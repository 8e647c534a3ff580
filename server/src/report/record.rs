//! Recording results and folding the resolved prefix.
//!
//! A report covers the indices `from..to` of a lease. The part below the
//! lease's `resume_at` was reported before: it must match what is stored
//! (then it is a duplicate, acknowledged and not counted again) or it is a
//! conflict (409). The part above is recorded: its events and invalid tests
//! as rows, the rest only as the lease's new `resume_at`. Then the campaign's
//! prefix estimator folds whatever became resolved in index order, all in
//! one transaction, so an acknowledged result is always on disk.

use crate::config::Config;
use crate::db::{now_ms, Database};
use crate::error::ServiceError;
use crate::leasing::claim as claiming;
use crate::leasing::fence::{self, check_fence};
use crate::leasing::size::update_cost;
use crate::report::check::CheckedReport;
use crate::report::explored::Explored;
use crate::report::explored::ExploredRanges;
use crate::report::fold::{fold_prefix, KnownExplored};
use crate::store::audits::{self, NewAudit};
use crate::store::campaigns::{self, CampaignRow};
use crate::store::costs;
use crate::store::leases::{self, LeaseRow, LeaseState};
use crate::store::near_misses;
use crate::store::prefix::Charge;
use crate::store::reports::{self, NewReport};
use crate::store::work_spans;
use rusqlite::Connection;
use std::sync::Arc;
use tslg_api::{CampaignStatus, ResultAck, ResultReport};
use tslg_method::number::Num;
use tslg_method::prefix::SparseOutcome;
use tslg_method::registry::CampaignTests;

/// Slack for the attempt-age check: the worker's clock starts after the
/// coordinator's, but rounding of milliseconds and clocks of different
/// resolution are allowed this much.
const CLOCK_SLACK_SECONDS: f64 = 1.0;

/// Refuses a report that says it took longer than its lease's attempt has
/// existed, or ran on more threads than the attempt was sized for: such
/// figures would set the cost per test, and so the campaign's fair-sharing
/// turn, to anything.
pub(crate) fn check_effort(
    lease: &LeaseRow,
    report: &ResultReport,
    now_ms: i64,
) -> Result<(), ServiceError> {
    let age = (now_ms - lease.claimed_at).max(0) as f64 / 1000.0 + CLOCK_SLACK_SECONDS;
    if report.compute_seconds > age {
        return Err(ServiceError::Unprocessable(format!(
            "compute_seconds = {} exceeds the {age:.3} s since lease {} was handed to worker \
             `{}`",
            Num(report.compute_seconds),
            lease.id,
            lease.worker
        )));
    }
    if i64::from(report.threads) > lease.threads {
        return Err(ServiceError::Unprocessable(format!(
            "threads = {} exceeds the {} threads lease {} was asked for",
            report.threads, lease.threads, lease.id
        )));
    }
    Ok(())
}

/// The audits an external program's report asks for ([`crate::report::audit`]):
/// `audits` from the report's start (those in the part recorded now are
/// stored), or, when no other worker could run them, only counted as
/// `waived`.
#[derive(Debug, Default)]
pub struct AuditPlan {
    pub audits: Vec<NewAudit>,
    pub waived: bool,
}

/// What the coordinator found out about a report before recording it.
pub struct Findings {
    /// The campaign's tests when it is a library campaign (they say which
    /// tests explored outside the library).
    pub tests: Option<Arc<dyn CampaignTests>>,
    /// The audits the report asks for.
    pub audits: AuditPlan,
    /// The report's exploring tests, when the coordinator ran them all.
    pub explored: Option<Explored>,
    /// Where exploring tests are kept for later folds (the report's own,
    /// when it is ahead of the prefix, and earlier reports').
    pub kept: Option<Arc<ExploredRanges>>,
}

/// Records a checked report on lease `lease_id` and folds the prefix;
/// then, in the same write, claims the worker's next lease when the
/// report asks for one (`next`, [`claiming::claim_after`]).
pub async fn record(
    db: &Database,
    config: &Arc<Config>,
    lease_id: i64,
    report: &Arc<ResultReport>,
    checked: &Arc<CheckedReport>,
    found: Findings,
    next: Option<claiming::ClaimJob>,
) -> Result<(Recorded, Option<claiming::Claimed>), ServiceError> {
    let (config, report, checked) = (Arc::clone(config), Arc::clone(report), Arc::clone(checked));
    db.write(move |conn| {
        let recorded = record_in(conn, &config, lease_id, &report, &checked, found)?;
        let claimed = match next {
            Some(job) => {
                let retried = claiming::retried_on(lease_id, &recorded.ack);
                claiming::claim_after(conn, &config, &job, retried)?
            }
            None => None,
        };
        Ok((recorded, claimed))
    })
    .await
}

/// [`record`] on the writer connection, in the report's savepoint.
fn record_in(
    tx: &Connection,
    config: &Config,
    lease_id: i64,
    report: &ResultReport,
    checked: &CheckedReport,
    found: Findings,
) -> Result<Recorded, ServiceError> {
    let (lease, campaign) = held_lease(tx, lease_id, report)?;
    record_held(tx, config, &lease, &campaign, report, checked, found)
}

/// Records a checked report on `lease` of `campaign`, read in this
/// transaction by [`held_lease`], and folds the prefix.
pub(crate) fn record_held(
    tx: &Connection,
    config: &Config,
    lease: &LeaseRow,
    campaign: &CampaignRow,
    report: &ResultReport,
    checked: &CheckedReport,
    found: Findings,
) -> Result<Recorded, ServiceError> {
    let Findings {
        tests,
        audits: plan,
        explored: known,
        kept,
    } = found;
    let lease_id = lease.id;
    let span = checked.to - checked.from;
    let (start, end, resume_at) = (
        lease.start_index as u64,
        lease.end_index as u64,
        lease.resume_at as u64,
    );
    if campaign.status.is_final() || lease.state == LeaseState::Cancelled {
        return Ok(Recorded {
            ack: stopped_ack(span, resume_at, end, campaign.status),
            stopped: None,
            campaign_id: campaign.id,
            partner_stopped: None,
            opens_work: false,
        });
    }
    check_effort(lease, report, now_ms())?;
    if checked.from < start || checked.to > end {
        return Err(ServiceError::Unprocessable(format!(
            "range {}..{} is not inside lease {lease_id}'s range {start}..{end}",
            checked.from, checked.to
        )));
    }
    if checked.from > resume_at {
        return Err(ServiceError::Unprocessable(format!(
            "range {}..{} leaves a gap: lease {lease_id} has results up to {resume_at}; report from there",
            checked.from, checked.to
        )));
    }
    let overlap_end = checked.to.min(resume_at);
    if checked.from < overlap_end {
        compare_with_stored(tx, campaign, checked, overlap_end)?;
    }
    let new_from = checked.from.max(resume_at);
    let mut accepted = 0;
    let mut charge = None;
    if new_from < checked.to {
        accepted = checked.to - new_from;
        let expires_at = now_ms() + (config.lease_ttl_seconds * 1000.0) as i64;
        charge = Some(store_new_part(
            tx, campaign, lease, report, checked, new_from, expires_at,
        )?);
        store_audits(tx, campaign.id, &report.worker, &plan, new_from)?;
    }
    let known = KnownExplored {
        replayed: known.map(Arc::new),
        kept: kept.as_deref(),
    };
    let measured = charge.and_then(|c| c.cost_per_test);
    let opens_work =
        accepted > 0 && (at_lease_limit(campaign) || !(plan.waived || plan.audits.is_empty()));
    let own = fold_prefix(tx, campaign, tests, known, Some(checked), charge)?;
    // A campaign of a pair: the pair folds over what both resolved.
    let (stopped, partner_stopped) = crate::report::pair_fold::fold_after(tx, campaign, own)?;
    // Its vehicle's cost, kept for later campaigns: when first measured,
    // and when it stops.
    if let Some(cost) = measured {
        if campaign.cost_per_test.is_none() || stopped.is_some() {
            let key = costs::key(
                &campaign.case_name,
                &campaign.preset,
                &campaign.vut,
                campaign.requires.as_deref(),
            );
            costs::put(tx, &key, cost)?;
        }
    }
    let status = stopped.unwrap_or(CampaignStatus::Running);
    let resume_at = resume_at.max(checked.to);
    Ok(Recorded {
        ack: ResultAck {
            accepted,
            duplicate: span - accepted,
            ignored: 0,
            resume_at,
            lease_done: resume_at == end,
            proceed: stopped.is_none(),
            campaign_status: status,
            next_lease: None,
        },
        stopped,
        campaign_id: campaign.id,
        partner_stopped,
        opens_work,
    })
}

/// The lease a report is on, checked to be held by its sender in this
/// attempt (a sender that is not flagged), and its campaign, read in the
/// report's transaction.
pub(crate) fn held_lease(
    conn: &Connection,
    lease_id: i64,
    report: &ResultReport,
) -> Result<(LeaseRow, CampaignRow), ServiceError> {
    let lease = fence::get_unless_flagged(conn, lease_id, &report.worker)?;
    check_fence(&lease, &report.worker, report.attempt, report.key.as_str())?;
    in_lease(&lease, report)?;
    let campaign = campaigns::get(conn, lease.campaign_id)?;
    Ok((lease, campaign))
}

/// Refuses a report whose range is not inside its lease's, before any of
/// it is replayed: the replay of a range past the lease (up to 2²² tests
/// a report) cost the coordinator the CPU of tests nobody leased.
pub(crate) fn in_lease(lease: &LeaseRow, report: &ResultReport) -> Result<(), ServiceError> {
    let (start, end) = (lease.start_index as u64, lease.end_index as u64);
    if report.from < start || report.to > end {
        return Err(ServiceError::Unprocessable(format!(
            "range {}..{} is not inside lease {}'s range {start}..{end}",
            report.from, report.to, lease.id
        )));
    }
    Ok(())
}

/// Stores the part `new_from..to` of a report that was not reported
/// before and moves the lease's `resume_at` past it; returns the work's
/// charge to the campaign's cost and worker time, which the fold writes.
/// A report keeps its lease alive until `expires_at`, like a heartbeat.
fn store_new_part(
    conn: &Connection,
    campaign: &CampaignRow,
    lease: &LeaseRow,
    report: &ResultReport,
    checked: &CheckedReport,
    new_from: u64,
    expires_at: i64,
) -> Result<Charge, ServiceError> {
    let first_new = checked.events.partition_point(|&(i, _)| i < new_from);
    let invalid: Vec<(u64, &str)> = checked
        .reasons
        .iter()
        .filter(|(i, _)| *i >= new_from)
        .map(|(i, r)| (*i, r.as_str()))
        .collect();
    // Other campaigns keep the criticalities with the report, for the
    // pairing of tests; an adaptive campaign's go to its near misses.
    let near: Vec<(u64, f64)> = if crate::report::evidence::criticality_below(campaign).is_some() {
        crate::report::evidence::kept_criticalities(&report.near_misses, new_from)
    } else {
        Vec::new()
    };
    reports::insert(
        conn,
        &NewReport {
            campaign_id: campaign.id,
            lease_id: lease.id,
            worker: &report.worker,
            from: new_from,
            to: checked.to,
            events: &checked.events[first_new..],
            invalid: &invalid,
            near: &near,
            handed_again: lease.attempt > 1,
        },
    )?;
    if campaign.method.in_stages() {
        near_misses::insert(conn, campaign.id, &report.near_misses, new_from)?;
    }
    work_spans::insert(conn, lease, false, (new_from, checked.to))?;
    let done = checked.to == lease.end_index as u64;
    let state = if done {
        LeaseState::Done
    } else {
        LeaseState::Active
    };
    if !leases::advance(conn, lease, checked.to as i64, expires_at, state)? {
        return Err(ServiceError::Conflict(format!(
            "lease {} changed during this report; send it again",
            lease.id
        )));
    }
    let accepted = checked.to - new_from;
    let span = checked.to - checked.from;
    let cost = update_cost(
        campaign.cost_per_test,
        accepted,
        report.compute_seconds,
        report.threads,
    );
    Ok(Charge {
        cost_per_test: cost,
        worker_seconds: spent_thread_seconds(report, accepted, span),
        reported_s1: checked.events[first_new..].iter().map(|e| e.1).sum(),
    })
}

/// Stores the planned audits of the part from `new_from`, or counts them
/// waived.
fn store_audits(
    conn: &Connection,
    campaign: i64,
    worker: &str,
    plan: &AuditPlan,
    new_from: u64,
) -> Result<(), ServiceError> {
    let new: Vec<NewAudit> = plan
        .audits
        .iter()
        .filter(|a| a.test_index >= new_from)
        .cloned()
        .collect();
    if new.is_empty() {
        return Ok(());
    }
    if plan.waived {
        campaigns::count_waived_audits(conn, campaign, new.len() as u64)?;
        return Ok(());
    }
    Ok(audits::insert(conn, campaign, worker, &new)?)
}

/// What recording a report did.
pub struct Recorded {
    pub ack: ResultAck,
    /// The campaign's final status, when this report stopped it.
    pub stopped: Option<CampaignStatus>,
    pub campaign_id: i64,
    /// The other campaign of the pair, when this report's pair stopped both.
    pub partner_stopped: Option<i64>,
    /// Whether the report may have opened work: its campaign had leased
    /// all it could (`leasing::size::lease_limit`, an adaptive campaign's
    /// running stage) and its prefix moved, or it asked for audits. The
    /// lease requests that wait for work are woken then, not at their
    /// next recheck.
    pub opens_work: bool,
}

/// Whether `campaign` has leased all it may now: its limit (what its stop
/// can still need, or its running stage) is reached, so only results
/// open work. An estimation stage's limit is taken at the stage's start,
/// its lowest: at worst a report wakes waiting requests needlessly.
pub fn at_lease_limit(campaign: &CampaignRow) -> bool {
    campaign.status == CampaignStatus::Running
        && campaign.next_index.max(0) as u64 >= crate::leasing::size::lease_limit(campaign, None)
}

/// Thread-seconds a report cost, prorated to the tests it newly resolved:
/// `compute_seconds · threads · accepted / span` (a partly duplicate report
/// is charged only for its new tests, so nothing is counted twice).
fn spent_thread_seconds(report: &ResultReport, accepted: u64, span: u64) -> f64 {
    let seconds = report.compute_seconds;
    if span == 0 || !(seconds.is_finite() && seconds > 0.0) {
        return 0.0;
    }
    seconds * f64::from(report.threads.max(1)) * accepted as f64 / span as f64
}

pub(crate) fn stopped_ack(
    span: u64,
    resume_at: u64,
    end: u64,
    status: CampaignStatus,
) -> ResultAck {
    ResultAck {
        accepted: 0,
        duplicate: 0,
        ignored: span,
        resume_at,
        lease_done: resume_at == end,
        proceed: false,
        campaign_status: status,
        next_lease: None,
    }
}

fn describe(outcome: Option<SparseOutcome>) -> String {
    match outcome {
        None => "no_event".into(),
        Some(SparseOutcome::Invalid) => "invalid".into(),
        Some(SparseOutcome::Event(w)) => format!("event with weight {w:e}"),
    }
}

/// Compares the part `from..overlap_end` of a report with what is stored:
/// the same outcomes make it a duplicate (acknowledged, not counted
/// again); any difference is a conflict (409), logged.
fn compare_with_stored(
    conn: &Connection,
    campaign: &CampaignRow,
    checked: &CheckedReport,
    overlap_end: u64,
) -> Result<(), ServiceError> {
    let stored = reports::outcomes(conn, campaign.id, checked.from, overlap_end)?;
    let reported: Vec<(u64, SparseOutcome)> = checked
        .outcomes
        .iter()
        .copied()
        .filter(|&(i, _)| i < overlap_end)
        .collect();
    let same = |a: &SparseOutcome, b: &SparseOutcome| match (a, b) {
        (SparseOutcome::Event(x), SparseOutcome::Event(y)) => x.to_bits() == y.to_bits(),
        (SparseOutcome::Invalid, SparseOutcome::Invalid) => true,
        _ => false,
    };
    if stored.len() == reported.len()
        && stored
            .iter()
            .zip(&reported)
            .all(|(s, r)| s.0 == r.0 && same(&s.1, &r.1))
    {
        return Ok(());
    }
    // Find the first index where they differ, to say so.
    let find = |list: &[(u64, SparseOutcome)], i: u64| {
        list.binary_search_by_key(&i, |o| o.0)
            .ok()
            .map(|k| list[k].1)
    };
    let index = stored
        .iter()
        .chain(&reported)
        .map(|o| o.0)
        .filter(|&i| match (find(&stored, i), find(&reported, i)) {
            (Some(a), Some(b)) => !same(&a, &b),
            _ => true,
        })
        .min()
        .unwrap_or(checked.from);
    let detail = format!(
        "conflicting result for test {index} of campaign {}: recorded as {}, now reported as {}",
        campaign.id,
        describe(find(&stored, index)),
        describe(find(&reported, index)),
    );
    tracing::warn!(campaign = campaign.id, test = index, "{detail}");
    Err(ServiceError::Conflict(detail))
}
