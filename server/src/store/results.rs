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
use crate::error::ApiError;
use crate::history;
use crate::lease_size::update_cost;
use crate::sampler_cache::SamplerCache;
use crate::store::campaigns::{self, CampaignRow};
use crate::store::leases::{self, check_fence};
use sqlx::{QueryBuilder, Sqlite, SqliteConnection};
use std::sync::Arc;
use tslg_api::{CampaignStatus, Method, ResultAck, ResultReport};
use tslg_method::estimator::Decision;
use tslg_method::prefix::{outside_tally, Exploration, SparseOutcome};
use tslg_method::registry::CampaignTests;

/// Longest accepted reason of an invalid test.
const MAX_REASON: usize = 2000;

/// A report checked for shape: sorted, disjoint, inside its range.
pub struct CheckedReport {
    pub from: u64,
    pub to: u64,
    /// Events and invalid tests, sorted by index.
    pub outcomes: Vec<(u64, SparseOutcome)>,
    pub reasons: Vec<(u64, String)>,
}

pub fn check_report(report: &ResultReport) -> Result<CheckedReport, ApiError> {
    let bad = |m: String| Err(ApiError::Unprocessable(m));
    if report.from >= report.to {
        return bad(format!(
            "empty range: from {} must be < to {}",
            report.from, report.to
        ));
    }
    if report.to > i64::MAX as u64 {
        return bad(format!("to {} is out of range", report.to));
    }
    let mut outcomes = Vec::with_capacity(report.events.len() + report.invalid.len());
    for e in &report.events {
        if !(e.weight.is_finite() && e.weight >= 0.0) {
            return bad(format!(
                "event at test {} has weight {}; weights are finite and ≥ 0",
                e.index, e.weight
            ));
        }
        outcomes.push((e.index, SparseOutcome::Event(e.weight)));
    }
    let mut reasons = Vec::with_capacity(report.invalid.len());
    for i in &report.invalid {
        if i.reason.len() > MAX_REASON {
            return bad(format!(
                "the reason for invalid test {} exceeds {MAX_REASON} bytes",
                i.index
            ));
        }
        outcomes.push((i.index, SparseOutcome::Invalid));
        reasons.push((i.index, i.reason.clone()));
    }
    outcomes.sort_by_key(|&(i, _)| i);
    for pair in outcomes.windows(2) {
        if pair[0].0 == pair[1].0 {
            return bad(format!(
                "test {} is reported more than once in this report",
                pair[0].0
            ));
        }
    }
    if let Some(&(i, _)) = outcomes
        .iter()
        .find(|&&(i, _)| i < report.from || i >= report.to)
    {
        return bad(format!(
            "test {i} lies outside the reported range {}..{}",
            report.from, report.to
        ));
    }
    reasons.sort_by_key(|(i, _)| *i);
    Ok(CheckedReport {
        from: report.from,
        to: report.to,
        outcomes,
        reasons,
    })
}

/// Records a checked report on lease `lease_id` and folds the prefix;
/// `samplers` gives a library campaign's tests, to tell which explored.
pub async fn record(
    db: &Database,
    config: &Config,
    samplers: &SamplerCache,
    lease_id: i64,
    report: &ResultReport,
    checked: &CheckedReport,
) -> Result<Recorded, ApiError> {
    let mut tx = db.write.begin().await?;
    let lease = leases::get(&mut tx, lease_id).await?;
    check_fence(&lease, &report.worker, report.attempt, report.key.as_str())?;
    let campaign = campaigns::get(&mut *tx, lease.campaign_id).await?;
    let tests = if campaign.method() == Method::Library && !campaign.status().is_final() {
        Some(samplers.get(db, &campaign).await?)
    } else {
        None
    };
    let span = checked.to - checked.from;
    let (start, end, resume_at) = (
        lease.start_index as u64,
        lease.end_index as u64,
        lease.resume_at as u64,
    );
    if campaign.status().is_final() || lease.state == "cancelled" {
        return Ok(Recorded {
            ack: stopped_ack(span, resume_at, end, campaign.status()),
            stopped: None,
            campaign_id: campaign.id,
        });
    }
    if checked.from < start || checked.to > end {
        return Err(ApiError::Unprocessable(format!(
            "range {}..{} is not inside lease {lease_id}'s range {start}..{end}",
            checked.from, checked.to
        )));
    }
    if checked.from > resume_at {
        return Err(ApiError::Unprocessable(format!(
            "range {}..{} leaves a gap: lease {lease_id} has results up to {resume_at}; report from there",
            checked.from, checked.to
        )));
    }
    let overlap_end = checked.to.min(resume_at);
    if checked.from < overlap_end {
        compare_with_stored(&mut tx, &campaign, checked, overlap_end).await?;
    }
    let new_from = checked.from.max(resume_at);
    let mut accepted = 0;
    if new_from < checked.to {
        accepted = checked.to - new_from;
        insert_outcomes(&mut tx, campaign.id, checked, new_from).await?;
        let done = checked.to == end;
        let moved = sqlx::query(
            "UPDATE leases SET resume_at = ?, expires_at = ?, state = ? \
             WHERE id = ? AND worker = ? AND attempt = ? AND resume_at = ? AND state = 'active'",
        )
        .bind(checked.to as i64)
        .bind(now_ms() + (config.lease_ttl_seconds * 1000.0) as i64)
        .bind(if done { "done" } else { "active" })
        .bind(lease_id)
        .bind(&report.worker)
        .bind(report.attempt)
        .bind(resume_at as i64)
        .execute(&mut *tx)
        .await?;
        if moved.rows_affected() != 1 {
            return Err(ApiError::Conflict(format!(
                "lease {lease_id} changed during this report; send it again"
            )));
        }
        let cost = update_cost(
            campaign.cost_per_test,
            accepted,
            report.compute_seconds,
            report.threads,
        );
        let worker_seconds = spent_thread_seconds(report, accepted, span);
        sqlx::query(
            "UPDATE campaigns SET cost_per_test = ?, worker_seconds = worker_seconds + ? \
             WHERE id = ?",
        )
        .bind(cost)
        .bind(worker_seconds)
        .bind(campaign.id)
        .execute(&mut *tx)
        .await?;
    }
    let stopped = fold_prefix(&mut tx, &campaign, tests).await?;
    tx.commit().await?;
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
        },
        stopped,
        campaign_id: campaign.id,
    })
}

/// What recording a report did.
pub struct Recorded {
    pub ack: ResultAck,
    /// The campaign's final status, when this report stopped it.
    pub stopped: Option<CampaignStatus>,
    pub campaign_id: i64,
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

fn stopped_ack(span: u64, resume_at: u64, end: u64, status: CampaignStatus) -> ResultAck {
    ResultAck {
        accepted: 0,
        duplicate: 0,
        ignored: span,
        resume_at,
        lease_done: resume_at == end,
        proceed: false,
        campaign_status: status,
    }
}

/// The tests of `from..to` that draw outside the library, replayed off the
/// async runtime (one random number each); empty without a library.
async fn explored_tests(
    tests: Option<&Arc<dyn CampaignTests>>,
    from: u64,
    to: u64,
) -> Result<Vec<u64>, ApiError> {
    let Some(tests) = tests.filter(|t| t.outside_mass().is_some()) else {
        return Ok(Vec::new());
    };
    let tests = Arc::clone(tests);
    tokio::task::spawn_blocking(move || (from..to).filter(|&i| tests.explores(i)).collect())
        .await
        .map_err(|e| ApiError::Internal(e.into()))
}

/// Stored outcomes of `campaign` in `from..to`, sorted by index.
async fn stored_outcomes(
    conn: &mut SqliteConnection,
    campaign: i64,
    from: u64,
    to: u64,
) -> Result<Vec<(u64, SparseOutcome)>, ApiError> {
    let events: Vec<(i64, f64)> = sqlx::query_as(
        "SELECT test_index, weight FROM events WHERE campaign_id = ? AND test_index >= ? AND test_index < ?",
    )
    .bind(campaign)
    .bind(from as i64)
    .bind(to as i64)
    .fetch_all(&mut *conn)
    .await?;
    let invalid: Vec<(i64,)> = sqlx::query_as(
        "SELECT test_index FROM invalid_tests WHERE campaign_id = ? AND test_index >= ? AND test_index < ?",
    )
    .bind(campaign)
    .bind(from as i64)
    .bind(to as i64)
    .fetch_all(&mut *conn)
    .await?;
    let mut outcomes: Vec<(u64, SparseOutcome)> = events
        .into_iter()
        .map(|(i, w)| (i as u64, SparseOutcome::Event(w)))
        .chain(
            invalid
                .into_iter()
                .map(|(i,)| (i as u64, SparseOutcome::Invalid)),
        )
        .collect();
    outcomes.sort_by_key(|&(i, _)| i);
    Ok(outcomes)
}

fn describe(outcome: Option<SparseOutcome>) -> String {
    match outcome {
        None => "no_event".into(),
        Some(SparseOutcome::Invalid) => "invalid".into(),
        Some(SparseOutcome::Event(w)) => format!("event with weight {w:e}"),
    }
}

async fn compare_with_stored(
    conn: &mut SqliteConnection,
    campaign: &CampaignRow,
    checked: &CheckedReport,
    overlap_end: u64,
) -> Result<(), ApiError> {
    let stored = stored_outcomes(conn, campaign.id, checked.from, overlap_end).await?;
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
    let find = |list: &[(u64, SparseOutcome)], i: u64| list.iter().find(|o| o.0 == i).map(|o| o.1);
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
    Err(ApiError::Conflict(detail))
}

/// Rows per multi-row `INSERT`: 3 bound values each, far below SQLite's
/// limit of 32 766 variables, and large enough that a report with thousands
/// of events costs a handful of statements rather than one per event.
const INSERT_BATCH: usize = 1000;

async fn insert_outcomes(
    conn: &mut SqliteConnection,
    campaign: i64,
    checked: &CheckedReport,
    from: u64,
) -> Result<(), ApiError> {
    let new = || checked.outcomes.iter().filter(move |o| o.0 >= from);
    let events: Vec<(u64, f64)> = new()
        .filter_map(|&(i, o)| match o {
            SparseOutcome::Event(w) => Some((i, w)),
            SparseOutcome::Invalid => None,
        })
        .collect();
    for batch in events.chunks(INSERT_BATCH) {
        QueryBuilder::<Sqlite>::new("INSERT INTO events (campaign_id, test_index, weight) ")
            .push_values(batch, |mut row, &(index, weight)| {
                row.push_bind(campaign)
                    .push_bind(index as i64)
                    .push_bind(weight);
            })
            .build()
            .execute(&mut *conn)
            .await?;
    }
    let invalid: Vec<(u64, &str)> = new()
        .filter(|o| matches!(o.1, SparseOutcome::Invalid))
        .map(|&(index, _)| {
            let reason = checked
                .reasons
                .binary_search_by_key(&index, |(i, _)| *i)
                .map(|k| checked.reasons[k].1.as_str())
                .unwrap_or("");
            (index, reason)
        })
        .collect();
    for batch in invalid.chunks(INSERT_BATCH) {
        QueryBuilder::<Sqlite>::new("INSERT INTO invalid_tests (campaign_id, test_index, reason) ")
            .push_values(batch, |mut row, &(index, reason)| {
                row.push_bind(campaign)
                    .push_bind(index as i64)
                    .push_bind(reason);
            })
            .build()
            .execute(&mut *conn)
            .await?;
    }
    Ok(())
}

/// Folds the newly resolved prefix of `campaign` and persists the estimate,
/// a history point and, when the rule stops the campaign, its final status.
async fn fold_prefix(
    conn: &mut SqliteConnection,
    campaign: &CampaignRow,
    tests: Option<Arc<dyn CampaignTests>>,
) -> Result<Option<CampaignStatus>, ApiError> {
    let (open,): (Option<i64>,) = sqlx::query_as(
        "SELECT MIN(resume_at) FROM leases WHERE campaign_id = ? AND state = 'active'",
    )
    .bind(campaign.id)
    .fetch_one(&mut *conn)
    .await?;
    let frontier = open.map_or(campaign.next_index, |r| r.min(campaign.next_index)) as u64;
    let mut fold = campaign.fold();
    if frontier <= fold.indices {
        return Ok(None);
    }
    let outcomes = stored_outcomes(conn, campaign.id, fold.indices, frontier).await?;
    let mass = tests.as_ref().and_then(|t| t.outside_mass());
    let from = fold.indices;
    if mass.is_some() && campaign.outside_upper.is_none() && from > 0 {
        // Started before the outside bound existed: count its exploring
        // tests from the start, as the fold would have.
        let earlier = stored_outcomes(conn, campaign.id, 0, from).await?;
        let explored = explored_tests(tests.as_ref(), 0, from).await?;
        let tests = tests
            .as_ref()
            .expect("a mass comes from the campaign's tests");
        fold.outside = outside_tally(&explored, &earlier, &|i| tests.surrogate_misses(i));
    }
    let explored = explored_tests(tests.as_ref(), from, frontier).await?;
    let misses = |i| tests.as_ref().is_some_and(|t| t.surrogate_misses(i));
    let exploration = mass.map(|mass| Exploration {
        explored: &explored,
        mass,
        surrogate_misses: &misses,
    });
    let rule = campaign.rule();
    let (last_stored,): (Option<i64>,) =
        sqlx::query_as("SELECT MAX(indices) FROM history WHERE campaign_id = ?")
            .bind(campaign.id)
            .fetch_one(&mut *conn)
            .await?;
    // History points inside this fold, at most one per 1 % of growth.
    let mut last_stored = last_stored.map(|i| i as u64);
    let mut course = Vec::new();
    let decision = fold
        .advance_observed(
            &rule,
            rule.z(),
            frontier,
            &outcomes,
            exploration,
            &mut |state| {
                if history::worth_storing(last_stored, state.indices) {
                    last_stored = Some(state.indices);
                    course.push(*state);
                }
            },
        )
        .map_err(|e| {
            anyhow::anyhow!("stored outcomes of campaign {} rejected: {e}", campaign.id)
        })?;
    let (status, detail) = match decision {
        None => (CampaignStatus::Running, None),
        Some(Decision::Converged) => (
            CampaignStatus::Converged,
            Some(format!(
                "relative half-width ≤ β = {} after test index {}{}",
                rule.beta,
                fold.indices - 1,
                if rule.guard_outside {
                    ", with the failure mass outside the library bounded"
                } else {
                    ""
                }
            )),
        ),
        Some(Decision::Exhausted) | Some(Decision::Continue) => (
            CampaignStatus::Exhausted,
            Some(format!(
                "max_tests = {} used up before the relative half-width reached β = {}",
                rule.max_tests, rule.beta
            )),
        ),
    };
    let (s1, s2) = fold.estimator.sums();
    let upper = mass.map(|m| m.upper(fold.outside.tests, fold.outside.events, campaign.confidence));
    sqlx::query(
        "UPDATE campaigns SET indices = ?, tests = ?, events = ?, invalid = ?, s1 = ?, s2 = ?, \
         largest = ?, outside_tests = ?, outside_events = ?, outside_s1 = ?, outside_upper = ?, \
         outside_mismatches = ?, \
         status = ?, status_detail = COALESCE(?, status_detail), \
         updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now') WHERE id = ?",
    )
    .bind(fold.indices as i64)
    .bind(fold.estimator.tests() as i64)
    .bind(fold.estimator.events() as i64)
    .bind(fold.invalid as i64)
    .bind(s1)
    .bind(s2)
    .bind(fold.estimator.largest_term())
    .bind(fold.outside.tests as i64)
    .bind(fold.outside.events as i64)
    .bind(fold.outside.s1)
    .bind(upper)
    .bind(fold.outside.mismatches as i64)
    .bind(status.as_str())
    .bind(detail)
    .bind(campaign.id)
    .execute(&mut *conn)
    .await?;
    if decision.is_some() || history::worth_storing(last_stored, fold.indices) {
        course.push(fold);
    }
    for batch in course.chunks(INSERT_BATCH) {
        QueryBuilder::<Sqlite>::new(
            "INSERT OR REPLACE INTO history (campaign_id, indices, tests, events, s1, s2) ",
        )
        .push_values(batch, |mut row, state| {
            let (s1, s2) = state.estimator.sums();
            row.push_bind(campaign.id)
                .push_bind(state.indices as i64)
                .push_bind(state.estimator.tests() as i64)
                .push_bind(state.estimator.events() as i64)
                .push_bind(s1)
                .push_bind(s2);
        })
        .build()
        .execute(&mut *conn)
        .await?;
    }
    if decision.is_some() {
        sqlx::query(
            "UPDATE leases SET state = 'cancelled' WHERE campaign_id = ? AND state = 'active'",
        )
        .bind(campaign.id)
        .execute(&mut *conn)
        .await?;
        tracing::info!(
            campaign = campaign.id,
            status = status.as_str(),
            stop_index = fold.indices,
            "campaign stopped"
        );
        return Ok(Some(status));
    }
    Ok(None)
}
