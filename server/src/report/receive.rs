//! Receiving a worker's report: who may report, what is checked before it
//! is stored ([`crate::report::audit`]: the coordinator's replay of built-in
//! vehicles, the weights and the audits of external programs), recording
//! it, and the bookkeeping that follows. The route only parses.

use crate::config::Config;
use crate::error::ServiceError;
use crate::leasing::claim as claiming;
use crate::leasing::fence;
use crate::report::audit;
use crate::report::check::CheckedReport;
use crate::report::record::{self, AuditPlan, Findings, Recorded};
use crate::report::replay;
use crate::report::replay_counts::{Place, ReplayCounts};
use crate::report::tests_cache::SamplerCache;
use crate::state::AppState;
use crate::store::{audits, campaigns, leases};
use std::sync::Arc;
use tslg_api::{ResultAck, ResultReport};
use tslg_method::registry::CampaignTests;

/// Replays a report may take on the async runtime, in expectation (the
/// sample is drawn with the check): about 30 ns each on a grid case (the
/// choice, a draw and a look-up), so under ten microseconds; more go to
/// the blocking pool.
const INLINE_REPLAYS: f64 = 256.0;

/// Replays a report may take on the writer itself (see [`at_once`]), in
/// expectation: the sample's size is not known before it is drawn.
const WRITER_REPLAYS: f64 = 64.0;

/// The replays a report's check takes in expectation when `tests` of its
/// tests are new: its listed outcomes and the share of the tests sampled.
fn expected_replays(share: f64, tests: u64, checked: &CheckedReport) -> f64 {
    share * tests as f64 + checked.outcomes.len() as f64
}

/// The replays checking the tests `new..checked.to` of a report on
/// `tests` takes in expectation: every test where the check runs every
/// test (a library campaign whose exploring tests the fold counts), else
/// [`expected_replays`].
fn expected_check(tests: &dyn CampaignTests, share: f64, new: u64, checked: &CheckedReport) -> f64 {
    if tests.outside_mass().is_some() {
        (checked.to - new) as f64
    } else {
        expected_replays(share, checked.to - new, checked)
    }
}

/// Checks, records and accounts a report on lease `lease_id`; then runs
/// `next`, the claim of the worker's next lease that the report carries
/// (in the same trip to the writer where the report takes one), and
/// returns what it took.
pub async fn receive(
    state: &AppState,
    lease_id: i64,
    report: &Arc<ResultReport>,
    checked: &Arc<CheckedReport>,
    next: Option<claiming::ClaimJob>,
) -> Result<(ResultAck, Option<claiming::Claimed>), ServiceError> {
    // A report whose sampled replay exceeds what the writer takes (a real
    // worker's chunk of half a second holds millions of tests, a tenth of
    // them replayed) goes the general way at once, without a trip to the
    // writer that could only decline it: by the writer's own rule, on the
    // whole report (a resumed lease's new part is smaller).
    let replays = expected_replays(
        state.config.replay_share,
        checked.to - checked.from,
        checked,
    );
    if replays > WRITER_REPLAYS {
        return in_parts_then_claim(state, lease_id, report, checked, next).await;
    }
    let next = match at_once(state, lease_id, report, checked, next).await {
        Ok(AtOnce::Recorded(recorded, claimed)) => {
            account(state, report, &recorded);
            return Ok((recorded.ack, claimed.map(|c| *c)));
        }
        Ok(AtOnce::Contradicted(mismatch)) => {
            // Its leases expired and its results taken back: work for the
            // others.
            state.work.announce();
            return Err(contradicted(&mismatch, &report.worker));
        }
        Ok(AtOnce::Declined(next)) => next,
        Err(e) => {
            // The writer may have resolved adaptive stages it did not
            // persist; the copy is rebuilt from what is stored.
            forget_adaptive(state, lease_id);
            return Err(e);
        }
    };
    in_parts_then_claim(state, lease_id, report, checked, next).await
}

/// [`receive_in_parts`], then the claim of the next lease in a write of its
/// own when the report's write could not take it (an audit run's).
async fn in_parts_then_claim(
    state: &AppState,
    lease_id: i64,
    report: &Arc<ResultReport>,
    checked: &Arc<CheckedReport>,
    mut next: Option<claiming::ClaimJob>,
) -> Result<(ResultAck, Option<claiming::Claimed>), ServiceError> {
    let (ack, mut claimed) = receive_in_parts(state, lease_id, report, checked, &mut next).await?;
    if let Some(job) = next {
        claimed = {
            let config = Arc::clone(&state.config);
            let retried = claiming::retried_on(lease_id, &ack);
            // The report is recorded: a claim that fails now must not turn
            // its acknowledgement into an error (the worker would send it
            // again); the worker asks for work as usual.
            state
                .db
                .write(move |conn| claiming::claim_after(conn, &config, &job, retried))
                .await
                .unwrap_or_else(|e| {
                    tracing::warn!(worker = %report.worker, error = %e, "no next lease with a report");
                    None
                })
        };
    }
    Ok((ack, claimed))
}

/// [`receive`] for a report the writer declined to take at once: read,
/// checked, then recorded, with the next lease claimed in the same write
/// (`next` taken) unless the report is an audit run's.
async fn receive_in_parts(
    state: &AppState,
    lease_id: i64,
    report: &Arc<ResultReport>,
    checked: &Arc<CheckedReport>,
    next: &mut Option<claiming::ClaimJob>,
) -> Result<(ResultAck, Option<claiming::Claimed>), ServiceError> {
    // One read for what decides the checks. Only the lease's holder may
    // report on it, and only what it reports is checked: a report in
    // another worker's name must not get that worker flagged. (The
    // transaction that records the report checks flag and fence again.)
    let (lease, campaign) = {
        let report = Arc::clone(report);
        state
            .db
            .read(move |conn| -> Result<_, ServiceError> {
                let lease = fence::get_unless_flagged(conn, lease_id, &report.worker)?;
                fence::check_fence(&lease, &report.worker, report.attempt, report.key.as_str())?;
                super::record::in_lease(&lease, &report)?;
                let campaign = campaigns::get(conn, lease.campaign_id)?;
                Ok((lease, campaign))
            })
            .await?
    };
    if campaign.method.runs_whole() {
        return Err(ServiceError::Conflict(format!(
            "lease {lease_id} is a library build: its worker uploads the library to POST \
             /api/v1/leases/{lease_id}/library"
        )));
    }
    let tests = if campaign.status.is_final() {
        None
    } else {
        Some(state.samplers.get(&state.db, &campaign).await?)
    };
    let library_tests = || tests.clone().filter(|_| campaign.method.uses_library());
    let recorded = if lease.audit_id.is_some() {
        let kept = Some(state.samplers.explored());
        audit::record_audit_run(&state.db, library_tests(), kept, lease_id, report, checked)
            .await
            .map(|recorded| (recorded, None))
    } else {
        let mut plan = AuditPlan::default();
        let mut explored = None;
        if let Some(tests) = &tests {
            if tests.external().is_none() {
                // Only what the report adds is checked: a part reported
                // before is compared with what is stored (a conflict, 409).
                let new = checked.from.max(lease.resume_at as u64);
                explored =
                    verify_builtin(state, tests, campaign.id, &report.worker, checked, new).await?;
            } else {
                check_weights(tests, checked).await?;
                plan = audit_plan(state, &campaign, &report.worker, checked).await?;
            }
        }
        let found = Findings {
            tests: library_tests(),
            audits: plan,
            explored,
            kept: Some(state.samplers.explored()),
        };
        let config = &state.config;
        record::record(
            &state.db,
            config,
            lease_id,
            report,
            checked,
            found,
            next.take(),
        )
        .await
    };
    // An adaptive campaign's stages live in memory with its tests: a
    // report that failed may have resolved a stage it did not persist, so
    // the copy is rebuilt from what is stored.
    let (recorded, claimed) = recorded.inspect_err(|_| {
        if campaign.method.in_stages() {
            state.samplers.forget(campaign.id);
        }
    })?;
    account(state, report, &recorded);
    Ok((recorded.ack, claimed))
}

/// What the writer made of a report it was asked to check and record in
/// one go.
enum AtOnce {
    /// Recorded, with the next lease when the report asked for one and
    /// one was taken.
    Recorded(Box<Recorded>, Option<Box<claiming::Claimed>>),
    /// The coordinator's own run contradicts it: the worker is flagged.
    Contradicted(crate::report::mismatch::Mismatch),
    /// It needs more than the writer should do: the general path, which
    /// also runs the claim of the next lease, handed back.
    Declined(Option<claiming::ClaimJob>),
}

/// [`AtOnce`] before the next lease is claimed.
enum Decided {
    Recorded(Box<Recorded>),
    Contradicted(crate::report::mismatch::Mismatch),
    Declined,
}

/// The common report in one trip to the writer, without a read before it:
/// a report of a built-in vehicle whose campaign's tests the coordinator
/// holds, with at most [`WRITER_REPLAYS`] tests to run again in
/// expectation (a draw and a look-up each on a grid case, microseconds in
/// all). The writer reads the
/// lease and its campaign (the holder checked, as always), runs the
/// checks, and flags the worker or records the report, then claims the
/// worker's next lease when the report asks for one. Anything else (an
/// external program's audits, a campaign whose tests are not built yet,
/// a large replay, an audit run, a build) is declined and goes the general
/// way.
async fn at_once(
    state: &AppState,
    lease_id: i64,
    report: &Arc<ResultReport>,
    checked: &Arc<CheckedReport>,
    next: Option<claiming::ClaimJob>,
) -> Result<AtOnce, ServiceError> {
    let (samplers, sampler, replays, config) = (
        Arc::clone(&state.samplers),
        Arc::clone(&state.sampler),
        Arc::clone(&state.replays),
        Arc::clone(&state.config),
    );
    let (report, checked) = (Arc::clone(report), Arc::clone(checked));
    state
        .db
        .write(move |conn| {
            let shared = Shared {
                samplers: &samplers,
                sampler: &sampler,
                replays: &replays,
                config: &config,
            };
            Ok(match decide(conn, &shared, lease_id, &report, &checked)? {
                Decided::Recorded(recorded) => {
                    let retried = claiming::retried_on(lease_id, &recorded.ack);
                    let claimed = match next {
                        Some(job) => claiming::claim_after(conn, &config, &job, retried)?,
                        None => None,
                    };
                    AtOnce::Recorded(recorded, claimed.map(Box::new))
                }
                Decided::Contradicted(mismatch) => AtOnce::Contradicted(mismatch),
                Decided::Declined => AtOnce::Declined(next),
            })
        })
        .await
}

/// What [`decide`] needs of the coordinator's state.
struct Shared<'a> {
    samplers: &'a SamplerCache,
    sampler: &'a crate::report::secret_sample::Sampler,
    replays: &'a ReplayCounts,
    config: &'a Config,
}

/// [`at_once`]'s decision on the writer: declined, contradicted (the
/// worker flagged) or recorded.
fn decide(
    conn: &rusqlite::Connection,
    shared: &Shared<'_>,
    lease_id: i64,
    report: &ResultReport,
    checked: &CheckedReport,
) -> Result<Decided, ServiceError> {
    let Shared {
        samplers,
        sampler,
        replays,
        config,
    } = *shared;
    let (lease, campaign) = record::held_lease(conn, lease_id, report)?;
    let tests = samplers
        .cached(campaign.id)
        .map(|tests| crate::report::tests_cache::switched(tests, &campaign));
    let Some(tests) = tests.filter(|t| t.external().is_none()) else {
        return Ok(Decided::Declined);
    };
    if lease.audit_id.is_some() || campaign.method.runs_whole() || campaign.status.is_final() {
        return Ok(Decided::Declined);
    }
    let new = checked.from.max(lease.resume_at as u64);
    let mut explored = None;
    if new < checked.to {
        if tests.planned(new).is_none() {
            return Ok(Decided::Declined);
        }
        // Whether the writer takes the report is decided before the sample
        // is drawn, on its expected size: a sample declined for being
        // large, then drawn again on the general path, would check each
        // test with less than the share.
        let work = expected_check(tests.as_ref(), config.replay_share, new, checked);
        if work > WRITER_REPLAYS {
            return Ok(Decided::Declined);
        }
        let verified = replay::verify_counted(
            tests.as_ref(),
            checked,
            new,
            |from, to| sampler.pick(config.replay_share, from, to),
            (replays, Place::Writer),
        );
        if let Some(mismatch) = verified.mismatch {
            let reason = format!("campaign {}: {mismatch}", campaign.id);
            crate::report::flag::flag_worker(
                conn,
                &report.worker,
                &reason,
                campaign.id,
                mismatch.index,
            )?;
            return Ok(Decided::Contradicted(mismatch));
        }
        explored = verified.explored;
    }
    let found = Findings {
        tests: Some(tests).filter(|_| campaign.method.uses_library()),
        audits: AuditPlan::default(),
        explored,
        kept: Some(samplers.explored()),
    };
    let recorded = record::record_held(conn, config, &lease, &campaign, report, checked, found)?;
    Ok(Decided::Recorded(Box::new(recorded)))
}

/// Drops the coordinator's copy of lease `lease_id`'s campaign when it is
/// adaptive (its stages are rebuilt from what is stored).
fn forget_adaptive(state: &AppState, lease_id: i64) {
    let (state, samplers) = (state.clone(), Arc::clone(&state.samplers));
    tokio::spawn(async move {
        let campaign = state
            .db
            .read(move |conn| {
                let lease = leases::get(conn, lease_id)?;
                campaigns::get(conn, lease.campaign_id)
            })
            .await;
        if let Ok(campaign) = campaign {
            if campaign.method.in_stages() {
                samplers.forget(campaign.id);
            }
        }
    });
}

/// The 422 of a report the coordinator's own run contradicts.
fn contradicted(mismatch: &crate::report::mismatch::Mismatch, worker: &str) -> ServiceError {
    ServiceError::Unprocessable(format!(
        "{mismatch}: the report is refused and worker `{worker}` is flagged; its results are \
         taken back"
    ))
}

/// The workers' counts, the rates and the caches after a report.
fn account(state: &AppState, report: &ResultReport, recorded: &Recorded) {
    let accepted = recorded.ack.accepted;
    // The accepted tests are the range's tail (the rest were duplicates).
    let invalid = report
        .invalid
        .iter()
        .filter(|i| i.index >= report.to - accepted)
        .count() as u64;
    state.workers.reported(&report.worker, accepted, invalid);
    if recorded.opens_work {
        state.work.announce();
    }
    if accepted > 0 && recorded.ack.proceed {
        state.throughput.accepted(recorded.campaign_id, accepted);
    }
    if let Some(partner) = recorded.partner_stopped {
        state.samplers.forget(partner);
        state.throughput.forget(partner);
    }
    if recorded.stopped.is_some() {
        state.samplers.forget(recorded.campaign_id);
        state.throughput.forget(recorded.campaign_id);
        // A library build's enumeration: the library from its events.
        let (state, id) = (state.clone(), recorded.campaign_id);
        tokio::spawn(async move {
            if let Err(e) = crate::builds::on_workers::finish(&state, id).await {
                tracing::error!(campaign = id, error = %e, "a library built on workers could not be recorded");
            }
        });
    }
}

/// Runs a built-in vehicle's reported tests again on the coordinator (see
/// [`replay::verify_builtin`]); a contradiction refuses the report and flags
/// the worker. The exploring tests it found, when it ran every test.
async fn verify_builtin(
    state: &AppState,
    tests: &Arc<dyn CampaignTests>,
    campaign: i64,
    worker: &str,
    checked: &Arc<CheckedReport>,
    new_from: u64,
) -> Result<Option<crate::report::explored::Explored>, ServiceError> {
    if new_from >= checked.to {
        return Ok(None);
    }
    let (tests, report) = (Arc::clone(tests), Arc::clone(checked));
    let share = state.config.replay_share;
    let work = expected_check(tests.as_ref(), share, new_from, checked);
    // Grid cases replay with a draw and a look-up (their tests are planned);
    // a car-following replay simulates the whole test. The sample is drawn
    // with the check, off the async runtime when the check is: for a
    // report of 2²² tests it takes milliseconds.
    let cheap = tests.planned(new_from).is_some();
    let (sampler, replays) = (Arc::clone(&state.sampler), Arc::clone(&state.replays));
    let check = move |place: Place| {
        replay::verify_counted(
            tests.as_ref(),
            &report,
            new_from,
            |from, to| sampler.pick(share, from, to),
            (&replays, place),
        )
    };
    let verified = if cheap && work <= INLINE_REPLAYS {
        // A few microseconds: not worth a trip to the blocking pool.
        check(Place::Request)
    } else {
        tokio::task::spawn_blocking(move || check(Place::Pool))
            .await
            .map_err(|e| ServiceError::Internal(e.into()))?
    };
    let Some(mismatch) = verified.mismatch else {
        return Ok(verified.explored);
    };
    audit::flag_for_mismatch(&state.db, worker, campaign, &mismatch).await?;
    // Its leases expired and its results taken back: work for the others.
    state.work.announce();
    Err(contradicted(&mismatch, worker))
}

/// An external program's events: the weight must be the campaign's draw
/// (grid cases) or finite and positive (car-following): another weight
/// means a worker that samples differently, and its results must not enter
/// the estimate.
async fn check_weights(
    tests: &Arc<dyn CampaignTests>,
    report: &CheckedReport,
) -> Result<(), ServiceError> {
    if report.events.is_empty() {
        return Ok(());
    }
    let tests = Arc::clone(tests);
    let events = report.events.clone();
    let checked = tokio::task::spawn_blocking(move || {
        events
            .iter()
            .try_for_each(|&(index, weight)| tests.check_event(index, weight))
    })
    .await
    .map_err(|e| ServiceError::Internal(e.into()))?;
    checked.map_err(|reason| {
        ServiceError::Unprocessable(format!(
            "{reason}: the worker draws different scenarios (another version of tslg?)"
        ))
    })
}

/// The audits of an external program's report, waived when no live worker
/// of another principal that is not flagged offers the program.
async fn audit_plan(
    state: &AppState,
    campaign: &campaigns::CampaignRow,
    worker: &str,
    checked: &CheckedReport,
) -> Result<AuditPlan, ServiceError> {
    let config = &state.config;
    // A worker that gave audit runs back has more of its tests audited
    // (report/dodging.rs).
    let name = worker.to_owned();
    let standing = state
        .db
        .read(move |conn| crate::store::standing::get(conn, &name))
        .await?;
    let share = crate::leasing::dodging::audit_share(config.audit_share, &standing);
    let chosen = state.sampler.pick(share, checked.from, checked.to);
    let planned = audit::choose_audits(
        checked,
        checked.from,
        campaign.reported_s1,
        config.audit_weight_share,
        &chosen,
    );
    if planned.is_empty() {
        return Ok(AuditPlan::default());
    }
    // Another principal's worker runs the replica (one vote per principal:
    // `audits::runnable`), so a live one must offer the program.
    let requirement = campaign.requires.as_deref().unwrap_or_default();
    let own = worker.to_owned();
    let own_principal = state
        .db
        .read(move |conn| crate::store::credentials::principal_of(conn, &own))
        .await?;
    let mut others = false;
    for name in state.workers.live_offering(requirement) {
        if name == worker {
            continue;
        }
        let (flag, principal) = state
            .db
            .read(move |conn| {
                let flag = audits::flag_of(conn, &name)?;
                Ok::<_, ServiceError>((flag, crate::store::credentials::principal_of(conn, &name)?))
            })
            .await?;
        if flag.is_none() && principal != own_principal {
            others = true;
            break;
        }
    }
    Ok(AuditPlan {
        audits: planned,
        waived: !others,
    })
}
