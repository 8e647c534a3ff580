//! `/api/v1/leases`: workers take ranges of tests and report outcomes.

use crate::error::ServiceError;
use crate::leasing::claim as claiming;
use crate::leasing::fence;
use crate::report::check::check_report;
use crate::report::receive;
use crate::routes::latency::HoldClock;
use crate::routes::problem::ApiJson;
use crate::routes::ApiPath;
use crate::state::AppState;
use crate::store::campaigns;
use crate::work_signal::FIRST_RECHECK;
use axum::extract::State;
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use std::time::Duration;
use tslg_api::{
    HeartbeatAck, Lease, LeaseFence, LeaseKey, LeaseRelease, LeaseRequest, LibraryUpload, Method,
    Problem, ResultAck, ResultReport, TestCase, MAX_CLAIM_WAIT_SECONDS, MAX_INVALID_REASON,
    WORKER_SECRET_HEADER,
};
use tslg_method::external::{check_program_name, ExternalMode};

/// Most programs' offers and unhealthy reports one request may carry.
const MAX_OFFERS: usize = 256;
const MAX_UNHEALTHY: usize = 16;
const MAX_UNHEALTHY_REASON: usize = 4000;

/// A worker's name: 1 to 128 bytes, no control characters; the problem
/// otherwise (a body's name answers 422, a path's 400).
pub(crate) fn worker_name_problem(worker: &str) -> Option<String> {
    (worker.is_empty() || worker.len() > 128 || worker.chars().any(char::is_control))
        .then(|| "worker must be 1 to 128 printable characters".to_string())
}

fn check_worker(worker: &str) -> Result<(), ServiceError> {
    worker_name_problem(worker).map_or(Ok(()), |m| Err(ServiceError::Unprocessable(m)))
}

/// Admits a request naming `worker` when it carries that worker's secret
/// (`crate::identity`; 403 otherwise).
pub(crate) async fn admit(
    state: &AppState,
    headers: &HeaderMap,
    worker: &str,
) -> Result<(), ServiceError> {
    let secret = headers
        .get(WORKER_SECRET_HEADER)
        .and_then(|v| v.to_str().ok());
    state.credentials.verify(&state.db, worker, secret).await
}

/// Takes a range of tests of a running campaign; 204 when there is none.
#[utoipa::path(post, path = "/api/v1/leases", request_body = LeaseRequest, params(("tslg-worker-secret" = String, Header, description = "The worker's secret (POST /api/v1/workers)")), responses(
    (status = 200, body = Lease), (status = 204, description = "No work right now (when the wait asked for ends)"),
    (status = 401, body = Problem), (status = 403, body = Problem),
    (status = 422, body = Problem)))]
pub async fn claim(
    State(state): State<AppState>,
    headers: HeaderMap,
    ApiJson(req): ApiJson<LeaseRequest>,
) -> Result<Response, ServiceError> {
    check_lease_request(&req)?;
    admit(&state, &headers, &req.worker).await?;
    // A request that asks to wait is held until work may be there (its
    // campaign announced, or at every recheck): docs/api.md, long polling.
    let wait = req
        .wait_seconds
        .unwrap_or(0.0)
        .min(state.config.max_claim_wait_seconds);
    // A worker whose last wait found nothing rechecks at the long ceiling
    // from the start: its rechecks do not begin anew at every request.
    let recheck = Duration::from_secs_f64(state.config.claim_recheck_seconds);
    let first = if state.workers.idle(&req.worker) {
        recheck
    } else {
        FIRST_RECHECK
    };
    // The time spent asking the store is latency; the rest is held time.
    let clock = HoldClock::start();
    // A worker that leaves while this request is held dropped it (the
    // coordinator does not see its connection close): the request ends
    // at its next ask, taking nothing.
    let leavings = state.workers.leavings(&req.worker);
    let granted = state
        .work
        .ask_until(
            Duration::from_secs_f64(wait),
            (first, recheck),
            || rand::random_range(0.5..=1.0),
            || {
                let left = state.workers.leavings(&req.worker) != leavings;
                let asked = clock.ask(grant(&state, &req));
                async move {
                    if left {
                        return Err(Ended::Left);
                    }
                    asked.await.map_err(Ended::Failed)
                }
            },
        )
        .await;
    let granted = match granted {
        // Granted as its worker left: nobody would work it. (The grant
        // counted the worker as seen again: it is out of the fleet anew.)
        Ok(Some(lease)) if state.workers.leavings(&req.worker) != leavings => {
            give_back(&state, &req.worker, &lease).await;
            state.workers.left(&req.worker);
            Err(Ended::Left)
        }
        other => other,
    };
    if let Ok(granted) = &granted {
        state
            .workers
            .set_idle(&req.worker, wait > 0.0 && granted.is_none());
    }
    // A store error can end a held request too: its wait is held time all
    // the same.
    let mut response = match granted {
        Ok(Some(lease)) => Json(lease).into_response(),
        Ok(None) => StatusCode::NO_CONTENT.into_response(),
        Err(Ended::Left) => {
            // A wake-up this request took goes on to a live one.
            state.work.announce_one();
            StatusCode::NO_CONTENT.into_response()
        }
        Err(Ended::Failed(e)) => e.into_response(),
    };
    if wait > 0.0 {
        clock.mark(&mut response);
    }
    Ok(response)
}

/// Why a held lease request ended without a lease.
enum Ended {
    /// The store failed.
    Failed(ServiceError),
    /// Its worker left while it was held.
    Left,
}

/// Gives back a lease granted to a worker that has left.
async fn give_back(state: &AppState, worker: &str, lease: &Lease) {
    let fence = LeaseFence {
        worker: worker.to_owned(),
        attempt: lease.attempt,
        key: lease.key.clone(),
    };
    match fence::release_as(&state.db, lease.id, &fence, fence::Giver::Coordinator).await {
        Ok(_) => tracing::info!(
            lease = lease.id,
            worker,
            "a lease granted as its worker left; given back"
        ),
        Err(e) => {
            tracing::warn!(lease = lease.id, error = %e, "a lease granted as its worker left could not be given back")
        }
    }
}

/// What a lease request must be before anything is taken (422 otherwise).
fn check_lease_request(req: &LeaseRequest) -> Result<(), ServiceError> {
    check_worker(&req.worker)?;
    if !(1..=claiming::MAX_THREADS).contains(&req.threads) {
        return Err(ServiceError::Unprocessable(format!(
            "threads = {} must be in 1..={}",
            req.threads,
            claiming::MAX_THREADS
        )));
    }
    if let Some(wait) = req.wait_seconds {
        if !(0.0..=MAX_CLAIM_WAIT_SECONDS).contains(&wait) {
            // A huge number in exponent form, not in hundreds of digits.
            let shown = if wait.abs() < 1e6 {
                format!("{wait}")
            } else {
                format!("{wait:e}")
            };
            return Err(ServiceError::Unprocessable(format!(
                "wait_seconds = {shown} must be in [0, {MAX_CLAIM_WAIT_SECONDS}]"
            )));
        }
    }
    if req.max_tests == Some(0) {
        return Err(ServiceError::Unprocessable(
            "max_tests = 0: a lease holds at least one test".into(),
        ));
    }
    check_programs(req)
}

/// Hands a checked lease request a range of tests, `None` when there is
/// no work right now.
async fn grant(state: &AppState, req: &LeaseRequest) -> Result<Option<Lease>, ServiceError> {
    state.workers.seen(req);
    let fleet = state.workers.fleet();
    match claiming::claim(&state.db, &state.config, &claim_of(req), fleet).await? {
        Some(claimed) => lease_of(state, req, claimed).await.map(Some),
        None => Ok(None),
    }
}

/// The store's claim of a lease request.
fn claim_of(req: &LeaseRequest) -> claiming::Claim<'_> {
    claiming::Claim {
        worker: &req.worker,
        threads: req.threads,
        inline: req.include_tests,
        offers: &req.offers,
        max_tests: req.max_tests,
        audits_only: req.audits_only,
    }
}

/// The lease a claim took, as the worker gets it (an adaptive campaign's,
/// or one asked for with `include_tests`, lists its tests). A lease that
/// cannot be made (its tests not listed) is given back at once, so it
/// does not hold its campaign's prefix until it expires.
async fn lease_of(
    state: &AppState,
    req: &LeaseRequest,
    claimed: claiming::Claimed,
) -> Result<Lease, ServiceError> {
    let fence = LeaseFence {
        worker: claimed.lease.worker.clone(),
        attempt: claimed.lease.attempt,
        key: LeaseKey(claimed.lease.key.clone()),
    };
    let id = claimed.lease.id;
    let made = make_lease(state, req, claimed).await;
    if let Err(e) = &made {
        tracing::warn!(lease = id, error = %e, "a lease taken could not be handed out; given back");
        match fence::release_as(&state.db, id, &fence, fence::Giver::Coordinator).await {
            Ok(_) => state.work.announce_one(),
            Err(e) => {
                tracing::warn!(lease = id, error = %e, "the lease could not be given back either")
            }
        }
    }
    made
}

/// [`lease_of`] before its error is handled.
async fn make_lease(
    state: &AppState,
    req: &LeaseRequest,
    claimed: claiming::Claimed,
) -> Result<Lease, ServiceError> {
    let row = claimed.lease;
    let campaign = match claimed.campaign {
        Some(campaign) => campaign,
        None => {
            let id = row.campaign_id;
            state.db.read(move |conn| campaigns::get(conn, id)).await?
        }
    };
    // An adaptive campaign's tests are planned by the coordinator stage by
    // stage: every lease names its tests' cells and weights.
    let tests = if req.include_tests || campaign.method == Method::Adaptive {
        let tests = state.samplers.get(&state.db, &campaign).await?;
        let (from, to) = (row.resume_at as u64, row.end_index as u64);
        let list = tokio::task::spawn_blocking(move || {
            (from..to)
                .map(|index| {
                    let planned = tests.planned(index)?;
                    Some(TestCase {
                        index,
                        cell: planned.cell as u64,
                        scenario: planned.scenario,
                        weight: planned.weight,
                    })
                })
                .collect::<Option<Vec<_>>>()
        })
        .await
        .map_err(|e| ServiceError::Internal(e.into()))?
        .ok_or_else(|| {
            ServiceError::Internal(anyhow::anyhow!(
                "campaign {} has no planned tests but was leased with include_tests",
                campaign.id
            ))
        })?;
        Some(list)
    } else {
        None
    };
    let ttl = state.config.lease_ttl_seconds;
    Ok(Lease {
        id: row.id,
        attempt: row.attempt,
        key: LeaseKey(row.key),
        campaign_id: row.campaign_id,
        start: row.start_index as u64,
        end: row.end_index as u64,
        resume_at: row.resume_at as u64,
        ttl_seconds: ttl,
        heartbeat_seconds: ttl / 3.0,
        tests,
        seconds_per_test: campaign.cost_per_test,
        explore_from: campaign.explore_from(),
    })
}

/// Checks the external programs a lease request offers (`NAME:case:mode`)
/// and reports unhealthy.
fn check_programs(req: &LeaseRequest) -> Result<(), ServiceError> {
    let bad = |m: String| Err(ServiceError::Unprocessable(m));
    if req.offers.len() > MAX_OFFERS {
        return bad(format!(
            "offers lists {} entries; at most {MAX_OFFERS}",
            req.offers.len()
        ));
    }
    for offer in &req.offers {
        let parts: Vec<&str> = offer.split(':').collect();
        let [name, case, mode] = parts[..] else {
            return bad(format!("offer `{offer}` must be NAME:case:mode"));
        };
        check_program_name(name).map_err(ServiceError::Unprocessable)?;
        if case.is_empty() || case.len() > 64 {
            return bad(format!(
                "offer `{offer}`: the case must be 1 to 64 characters"
            ));
        }
        if serde_json::from_value::<ExternalMode>(mode.into()).is_err() {
            return bad(format!("offer `{offer}`: the mode must be step or episode"));
        }
    }
    if req.noisy.len() > req.offers.len() {
        return bad(format!(
            "noisy lists {} entries, more than offers ({})",
            req.noisy.len(),
            req.offers.len()
        ));
    }
    if let Some(stray) = req.noisy.iter().find(|n| !req.offers.contains(n)) {
        return bad(format!(
            "noisy lists `{stray}`, which offers does not: list the offers whose program said \
             \"deterministic\": false"
        ));
    }
    if req.unhealthy.len() > MAX_UNHEALTHY {
        return bad(format!(
            "unhealthy lists {} programs; at most {MAX_UNHEALTHY}",
            req.unhealthy.len()
        ));
    }
    for u in &req.unhealthy {
        check_program_name(&u.name).map_err(ServiceError::Unprocessable)?;
        if u.reason.len() > MAX_UNHEALTHY_REASON {
            return bad(format!(
                "the reason program `{}` is unhealthy exceeds {MAX_UNHEALTHY_REASON} bytes",
                u.name
            ));
        }
    }
    Ok(())
}

/// Keeps a lease alive; `continue: false` means drop it.
#[utoipa::path(post, path = "/api/v1/leases/{id}/heartbeat", params(("id" = i64, Path), ("tslg-worker-secret" = String, Header, description = "The worker's secret (POST /api/v1/workers)")),
    request_body = LeaseFence, responses(
    (status = 200, body = HeartbeatAck), (status = 403, body = Problem), (status = 404, body = Problem),
    (status = 409, body = Problem), (status = 422, body = Problem)))]
pub async fn heartbeat(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
    headers: HeaderMap,
    ApiJson(fence): ApiJson<LeaseFence>,
) -> Result<Json<HeartbeatAck>, ServiceError> {
    check_worker(&fence.worker)?;
    admit(&state, &headers, &fence.worker).await?;
    state.workers.heard(&fence.worker);
    Ok(Json(
        fence::heartbeat(&state.db, &state.config, id, &fence).await?,
    ))
}

/// Gives an unfinished lease back, to be handed out again at once, saying
/// why.
#[utoipa::path(post, path = "/api/v1/leases/{id}/release", params(("id" = i64, Path), ("tslg-worker-secret" = String, Header, description = "The worker's secret (POST /api/v1/workers)")),
    request_body = LeaseRelease, responses(
    (status = 204, description = "Released"), (status = 403, body = Problem),
    (status = 404, body = Problem), (status = 409, body = Problem),
    (status = 422, body = Problem)))]
pub async fn release(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
    headers: HeaderMap,
    ApiJson(release): ApiJson<LeaseRelease>,
) -> Result<StatusCode, ServiceError> {
    check_worker(&release.worker)?;
    let reason = release.reason.as_deref().unwrap_or("no reason given");
    if reason.len() > MAX_INVALID_REASON || reason.chars().any(|c| c.is_control() && c != '\n') {
        return Err(ServiceError::Unprocessable(format!(
            "the reason must be at most {MAX_INVALID_REASON} bytes without control characters"
        )));
    }
    admit(&state, &headers, &release.worker).await?;
    let lease = fence::release(&state.db, id, &release.fence()).await?;
    // Its tests are another worker's now (or when the lease's rest is due).
    state.work.announce_one();
    state.workers.released(&release.worker, reason);
    tracing::info!(
        lease = id,
        worker = %release.worker,
        resume_at = lease.resume_at,
        reason,
        "lease released"
    );
    Ok(StatusCode::NO_CONTENT)
}

/// Uploads the library a worker built whole for a campaign of method
/// `build` (or why the build failed): the library is ready (or failed)
/// and the campaign done. A file that is not the library asked for is a
/// 422 and changes nothing.
#[utoipa::path(post, path = "/api/v1/leases/{id}/library", params(("id" = i64, Path), ("tslg-worker-secret" = String, Header, description = "The worker's secret (POST /api/v1/workers)")),
    request_body = LibraryUpload, responses(
    (status = 204, description = "Recorded"), (status = 403, body = Problem),
    (status = 404, body = Problem),
    (status = 409, description = "Not the lease's holder, or the build is no longer wanted", body = Problem),
    (status = 422, body = Problem)))]
pub async fn library(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
    headers: HeaderMap,
    ApiJson(upload): ApiJson<LibraryUpload>,
) -> Result<StatusCode, ServiceError> {
    check_worker(&upload.worker)?;
    admit(&state, &headers, &upload.worker).await?;
    crate::builds::whole::upload(&state, id, &upload).await?;
    Ok(StatusCode::NO_CONTENT)
}

/// Reports the outcomes of a range of the lease's tests.
#[utoipa::path(post, path = "/api/v1/leases/{id}/results", params(("id" = i64, Path), ("tslg-worker-secret" = String, Header, description = "The worker's secret (POST /api/v1/workers)")),
    request_body = ResultReport, responses(
    (status = 200, body = ResultAck), (status = 403, body = Problem), (status = 404, body = Problem),
    (status = 409, description = "Not the lease's holder, or a conflicting result", body = Problem),
    (status = 422, body = Problem)))]
pub async fn results(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
    headers: HeaderMap,
    ApiJson(report): ApiJson<ResultReport>,
) -> Result<Json<ResultAck>, ServiceError> {
    check_worker(&report.worker)?;
    if let Some(next) = &report.next_lease {
        if next.worker != report.worker {
            return Err(ServiceError::Unprocessable(format!(
                "next_lease.worker `{}` is not the reporting worker `{}`",
                next.worker, report.worker
            )));
        }
        check_lease_request(next).map_err(|e| match e {
            ServiceError::Unprocessable(m) => {
                ServiceError::Unprocessable(format!("next_lease: {m}"))
            }
            other => other,
        })?;
        if next.wait_seconds.is_some_and(|w| w != 0.0) {
            return Err(ServiceError::Unprocessable(
                "next_lease.wait_seconds: a report's next lease is answered with the report, \
                 without waiting; wait in POST /api/v1/leases"
                    .into(),
            ));
        }
    }
    let checked = std::sync::Arc::new(check_report(&report)?);
    // A malformed body is a 422 whoever sends it; a well-formed one in
    // another worker's name a 403.
    admit(&state, &headers, &report.worker).await?;
    let report = std::sync::Arc::new(report);
    let next = report
        .next_lease
        .as_ref()
        .map(|next| claiming::ClaimJob::new(&state.config, &claim_of(next), state.workers.fleet()));
    let (mut ack, claimed) = receive::receive(&state, id, &report, &checked, next).await?;
    if let Some(next) = &report.next_lease {
        state.workers.seen(next);
        if let Some(claimed) = claimed {
            // The report is recorded: a lease that cannot be finished now
            // must not turn its acknowledgement into an error (the worker
            // would report again); it is given back, and the worker asks
            // for work as usual.
            ack.next_lease = lease_of(&state, next, claimed).await.ok();
        }
    }
    Ok(Json(ack))
}
