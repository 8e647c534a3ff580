//! `/api/v1/leases`: workers take ranges of tests and report outcomes.

use crate::error::ServiceError;
use crate::leasing::fence;
use crate::leasing::grant::{give_back, grant, lease_of, next_claim, Ended};
use crate::leasing::request::{check_lease_request, check_worker};
use crate::report::check::check_report;
use crate::report::receive;
use crate::routes::latency::HoldClock;
use crate::routes::problem::ApiJson;
use crate::routes::ApiPath;
use crate::state::AppState;
use crate::work_signal::FIRST_RECHECK;
use axum::extract::State;
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use std::time::Duration;
use tslg_api::{
    HeartbeatAck, Lease, LeaseFence, LeaseRelease, LeaseRequest, LibraryUpload, Problem, ResultAck,
    ResultReport, MAX_INVALID_REASON, WORKER_SECRET_HEADER,
};

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
        .map(|next| next_claim(&state, next));
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
