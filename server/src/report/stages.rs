//! Adaptive campaigns' stages on the coordinator ([`tslg_method::adaptive`]).
//!
//! A lease never reaches past the running stage (`campaigns.stage_end`).
//! When every test of the stage has its result (the prefix's frontier, as
//! for any campaign, passes its end), or an estimation stage's rule stops
//! the campaign before the frontier, the stage is resolved in the report's
//! transaction: its events and invalid tests as stored, each test's
//! criticality run again here for a built-in vehicle or as the program's
//! worker reported it (`near_misses`), give the estimate's step and the
//! next stage's plan. What is persisted (the estimate, the running stage,
//! the counts, a history point) follows from the results alone, so the
//! coordinator's copy rebuilt after a restart resolves the same stages
//! again ([`catch_up`]) and the campaign is the in-process one.

use crate::campaign::history;
use crate::error::ServiceError;
use crate::store::campaigns::CampaignRow;
use crate::store::prefix::{self, close_stopped, frontier};
use crate::store::{adaptive_stages, near_misses, reports};
use rusqlite::Connection;
use std::sync::Arc;
use tslg_api::CampaignStatus;
use tslg_method::adaptive::{StageRecord, TestResult};
use tslg_method::estimator::Decision;
use tslg_method::outside::OutsideTally;
use tslg_method::prefix::{PrefixFold, SparseOutcome};
use tslg_method::registry::{AdaptiveStages, CampaignTests};

/// The results of the running stage's tests `from..to`, in index order.
fn stage_results(
    conn: &Connection,
    campaign: i64,
    tests: &Arc<dyn CampaignTests>,
    from: u64,
    to: u64,
) -> Result<Vec<TestResult>, ServiceError> {
    let stages = tests.adaptive().expect("an adaptive campaign's tests");
    let outcomes = reports::outcomes(conn, campaign, from, to)?;
    let replayed = stages.replay_stage(from, to);
    let near_misses = if replayed.is_some() {
        Vec::new()
    } else {
        near_misses::of_range(conn, campaign, from, to)?
    };
    // A test that did not come within `near_miss` is "far": only whether a
    // criticality is within it matters to the plan.
    let far = 1.0f64.max(stages.settings().near_miss);
    let mut results: Vec<TestResult> = (from..to)
        .map(|i| TestResult::Done {
            event: false,
            criticality: replayed.as_ref().map_or(far, |r| r[(i - from) as usize].1),
        })
        .collect();
    for (i, c) in near_misses {
        if let TestResult::Done { criticality, .. } = &mut results[(i as u64 - from) as usize] {
            *criticality = c;
        }
    }
    with_outcomes(&mut results, from, outcomes);
    Ok(results)
}

/// Sets the stored `outcomes` (events and invalid tests) of a stage's
/// tests from `from` into `results`.
fn with_outcomes(results: &mut [TestResult], from: u64, outcomes: Vec<(u64, SparseOutcome)>) {
    for (i, outcome) in outcomes {
        results[(i - from) as usize] = match outcome {
            SparseOutcome::Invalid => TestResult::Invalid,
            SparseOutcome::Event(_) => TestResult::Done {
                event: true,
                criticality: 0.0,
            },
        };
    }
}

/// The running stage `from..to`'s results when its rule stops the
/// campaign within the tests before `frontier` (an estimation stage, its
/// results in index order up to there): those tests' results, the others
/// without an event, never folded ([`AdaptiveStages::stops_within`]). The
/// campaign stops where the whole stage would stop it, and its workers do
/// not run the stage's last tests, which its estimate would not use (half
/// a stage on average, measured: 70 tests run for 333 used).
fn stopped_within(
    conn: &Connection,
    campaign: i64,
    stages: &dyn AdaptiveStages,
    (from, to): (u64, u64),
    frontier: u64,
) -> Result<Option<Vec<TestResult>>, ServiceError> {
    if frontier <= from || frontier >= to {
        return Ok(None);
    }
    let none = TestResult::Done {
        event: false,
        criticality: 1.0f64.max(stages.settings().near_miss),
    };
    let mut results = vec![none; (frontier - from) as usize];
    with_outcomes(
        &mut results,
        from,
        reports::outcomes(conn, campaign, from, frontier)?,
    );
    if !stages.stops_within(&results) {
        return Ok(None);
    }
    results.resize((to - from) as usize, none);
    Ok(Some(results))
}

/// Resolves the stages of `tests` that `campaign`'s stored state has
/// already passed: the coordinator's copy, rebuilt, catches up with it.
/// `Some(reason)` when the copy cannot: its plan, made again from the seed
/// and the stored results, does not run the stored stage (its start, end
/// and kind; a campaign planned by another version of tslg, or whose
/// stored state was changed), so no report could ever resolve it.
pub fn catch_up(
    conn: &Connection,
    campaign: &CampaignRow,
    tests: &Arc<dyn CampaignTests>,
) -> Result<Option<String>, ServiceError> {
    let Some(stages) = tests.adaptive() else {
        return Ok(None);
    };
    let resolved_to = match campaign.stage_start {
        Some(start) => start as u64,
        // Stopped: every stage that ran was resolved.
        None => campaign.indices as u64,
    };
    // On a reader: the stages' records were stored when they were
    // resolved the first time.
    while let Some((from, to)) = stages.running() {
        if to > resolved_to {
            break;
        }
        let results = stage_results(conn, campaign.id, tests, from, to)?;
        stages.resolve(&results);
    }
    let (Some(start), false) = (campaign.stage_start, campaign.status.is_final()) else {
        return Ok(None);
    };
    // Leases run to the stored stage's end and the lease size follows its
    // kind: the plan must agree on all three, as it would store them.
    let stored = (
        start as u64,
        campaign.stage_end.map(|end| end as u64),
        campaign.stage_kind.as_deref(),
    );
    let planned = stages
        .progress()
        .running
        .map(|(from, to, kind)| (from, Some(to), Some(kind)));
    if planned == Some(stored) {
        return Ok(None);
    }
    let describe = |(from, to, kind): (u64, Option<u64>, Option<&str>)| {
        format!(
            "{} stage {from}..{}",
            kind.unwrap_or("a"),
            to.map_or("?".to_string(), |to| to.to_string())
        )
    };
    let planned = planned.map_or("no stage".to_string(), describe);
    Ok(Some(format!(
        "adaptive campaign {}'s stages, planned again from its seed and stored results, do \
         not reach its stored {} (they run {planned}): it was planned by another version of \
         tslg or its stored state was changed, so it cannot go on; start it again",
        campaign.id,
        describe(stored)
    )))
}

/// Resolves every stage of `campaign` whose tests all have results, and
/// persists where it stands; the final status when it stopped.
pub fn resolve_stages(
    conn: &Connection,
    campaign: &CampaignRow,
    tests: &Arc<dyn CampaignTests>,
) -> Result<Option<CampaignStatus>, ServiceError> {
    let stages: &dyn AdaptiveStages = tests
        .adaptive()
        .ok_or_else(|| anyhow::anyhow!("campaign {} has no adaptive stages", campaign.id))?;
    let in_step = match (stages.running(), campaign.stage_start) {
        (Some((from, _)), Some(start)) => from == start as u64,
        _ => false,
    };
    if !in_step {
        return Err(ServiceError::Internal(anyhow::anyhow!(
            "the coordinator's copy of adaptive campaign {} is not at its stored stage",
            campaign.id
        )));
    }
    let frontier = frontier(conn, campaign)?;
    let mut records = Vec::new();
    while let Some((from, to)) = stages.running() {
        let results = if frontier >= to {
            stage_results(conn, campaign.id, tests, from, to)?
        } else if let Some(results) =
            stopped_within(conn, campaign.id, stages, (from, to), frontier)?
        {
            results
        } else {
            break;
        };
        records.push(stages.resolve(&results));
    }
    if records.is_empty() {
        return Ok(None);
    }
    write(conn, campaign, stages, &records)
}

/// Stores the estimate's course over the estimation stages of `records`
/// (from the last restart of a guarded campaign's estimate on) as history
/// points at the campaign's test indices, thinned as every
/// campaign's history is ([`history::worth_storing`], on estimation tests)
/// and keeping each stage's last point, so the estimate and its interval
/// are drawn over the estimation tests (one point a stage drew nothing:
/// a campaign that stopped in its first estimation stage had one point).
fn store_courses(
    conn: &Connection,
    campaign: i64,
    records: &[StageRecord],
) -> Result<(), ServiceError> {
    let mut last = prefix::last_history_tests(conn, campaign)?;
    let mut kept = Vec::new();
    for record in records {
        if record.restarts_estimate {
            // A guarded campaign's estimate starts again after this stage:
            // its history is the new estimate's.
            prefix::delete_history(conn, campaign)?;
            kept.clear();
            last = None;
            continue;
        }
        for (k, point) in record.course.iter().enumerate() {
            let tests = point.estimator.tests();
            let stage_end = k + 1 == record.course.len();
            if tests > 0 && (stage_end || history::worth_storing(last, tests)) {
                last = Some(tests);
                kept.push((
                    PrefixFold {
                        outside: OutsideTally::default(),
                        ..*point
                    },
                    None,
                ));
            }
        }
    }
    prefix::store_history(conn, campaign, &kept)?;
    Ok(())
}

/// Persists the campaign's state after resolving stages.
fn write(
    conn: &Connection,
    campaign: &CampaignRow,
    stages: &dyn AdaptiveStages,
    records: &[StageRecord],
) -> Result<Option<CampaignStatus>, ServiceError> {
    let p = stages.progress();
    let fold = p.fold;
    let (status, detail, indices) = match &p.finished {
        None => (CampaignStatus::Running, None, p.running.map_or(0, |r| r.0)),
        Some(done) => {
            let (status, detail) = match done.result.status {
                Decision::Converged => (
                    CampaignStatus::Converged,
                    format!(
                        "relative half-width ≤ β = {} after {} tests ({} estimation \
                         tests; {} library and {} search tests found where the vehicle \
                         fails){}",
                        campaign.beta,
                        done.result.indices,
                        fold.indices,
                        done.library_tests,
                        done.search_tests,
                        if campaign.guard_outside {
                            ", with the failure mass outside its support bounded"
                        } else {
                            ""
                        }
                    ),
                ),
                _ => (
                    CampaignStatus::Exhausted,
                    format!(
                        "max_tests = {} used up before the relative half-width reached β = {}{}",
                        campaign.max_tests,
                        campaign.beta,
                        if campaign.guard_outside {
                            " with the outside bound within β × the estimate"
                        } else {
                            ""
                        }
                    ),
                ),
            };
            (status, Some(detail), done.result.indices)
        }
    };
    prefix::store_stages(
        conn,
        campaign.id,
        &prefix::StagesState {
            indices,
            progress: &p,
            status,
            detail: detail.as_deref(),
            confidence: campaign.confidence,
        },
    )?;
    adaptive_stages::store(conn, campaign.id, records)?;
    store_courses(conn, campaign.id, records)?;
    if p.finished.is_none() {
        return Ok(None);
    }
    close_stopped(conn, campaign.id, indices)?;
    tracing::info!(
        campaign = campaign.id,
        status = status.as_str(),
        tests = indices,
        "adaptive campaign stopped"
    );
    Ok(Some(status))
}
