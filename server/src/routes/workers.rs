//! `/api/v1/workers`: the fleet. Workers register here for a credential of
//! their own (`crate::identity`); readers list them; an operator revokes a
//! credential or clears a flag.

use crate::error::ServiceError;
use crate::identity::MAX_REQUESTED_NAME;
use crate::leasing::request::worker_name_problem;
use crate::routes::leases::admit;
use crate::routes::problem::ApiJson;
use crate::routes::ApiPath;
use crate::state::AppState;
use crate::store::discordance;
use crate::store::{audits, costs, standing};
use axum::extract::State;
use axum::http::{HeaderMap, StatusCode};
use axum::Json;
use tslg_api::{Problem, ProgramCost, WorkerCredential, WorkerList, WorkerRegistration};
use tslg_method::discordance::worker_evidence;

/// Registers a worker: a credential of its own, under the name asked for,
/// or the first free `NAME.k` when that name was issued before (to another
/// worker, or to this one before a restart). The secret is shown once.
#[utoipa::path(post, path = "/api/v1/workers", request_body = WorkerRegistration, responses(
    (status = 201, body = WorkerCredential), (status = 401, body = Problem),
    (status = 403, body = Problem, description = "An enrolment not issued, revoked or of a flagged principal, or none where enrolment is required"),
    (status = 409, body = Problem), (status = 422, body = Problem)))]
pub async fn register(
    State(state): State<AppState>,
    ApiJson(req): ApiJson<WorkerRegistration>,
) -> Result<(StatusCode, Json<WorkerCredential>), ServiceError> {
    crate::validate::check_name("name", &req.name, MAX_REQUESTED_NAME)?;
    if req.name.starts_with('@') {
        // `@PRINCIPAL` names an enrolled principal in the evidence.
        return Err(ServiceError::Unprocessable(
            "name must not begin with `@`".into(),
        ));
    }
    let required = state.config.enrolment == crate::config::Enrolment::Required;
    let enrolment = (req.enrolment.as_deref(), required);
    let issued = state
        .credentials
        .register(&state.db, &req.name, enrolment)
        .await?;
    tracing::info!(worker = %issued.name, asked = %req.name, principal = ?issued.principal,
        "worker registered");
    Ok((StatusCode::CREATED, Json(issued)))
}

/// A worker says it is leaving (stopped by SIGTERM, or a batch job ending
/// when idle), after giving its leases back: it is out of the live fleet
/// at once, not a minute after its last request, so `GET /api/v1/queue`
/// and the sizing of leases stop counting it. A lease still its own (one
/// granted to a wait it dropped as it stopped) is handed out again at
/// once. Asking for work again brings it back.
#[utoipa::path(post, path = "/api/v1/workers/{name}/leave",
    params(("name" = String, Path), ("tslg-worker-secret" = String, Header, description = "The worker's secret (POST /api/v1/workers)")),
    responses((status = 204, description = "Out of the live fleet"), (status = 400, body = Problem),
    (status = 401, body = Problem), (status = 403, body = Problem)))]
pub async fn leave(
    State(state): State<AppState>,
    headers: HeaderMap,
    ApiPath(name): ApiPath<String>,
) -> Result<StatusCode, ServiceError> {
    path_name(&name)?;
    admit(&state, &headers, &name).await?;
    // Out of the fleet first, so that a request of it still held takes
    // nothing from here on; then what it still holds goes to the others.
    state.workers.left(&name);
    let left_behind = crate::leasing::fence::expire_left_behind(&state.db, &name).await?;
    if left_behind > 0 {
        state.work.announce();
    }
    tracing::info!(worker = %name, left_behind, "worker left");
    Ok(StatusCode::NO_CONTENT)
}

/// The workers seen since the coordinator started, most recent first:
/// their threads, the external programs they offer and those they report
/// unhealthy, when their credentials were issued (and revoked), their
/// standing in audits (given back; for noisy programs, the evidence that
/// theirs behaves unlike the others'), and the measured cost of a test of
/// each program.
#[utoipa::path(get, path = "/api/v1/workers", responses((status = 200, body = WorkerList)))]
pub async fn list(State(state): State<AppState>) -> Result<Json<WorkerList>, ServiceError> {
    let (flagged, costs, standings, compared, tested) = state
        .db
        .read(|conn| {
            Ok::<_, ServiceError>((
                audits::flagged(conn)?,
                costs::programs(conn)?,
                standing::all(conn)?,
                discordance::all(conn, false)?,
                discordance::all(conn, true)?,
            ))
        })
        .await?;
    let mut workers = state.workers.list(&flagged);
    for worker in &mut workers {
        let principal;
        (worker.registered_at, worker.revoked_at, principal) =
            state.credentials.dates(&worker.name);
        // The evidence is its principal's (`credentials::principal_of`).
        let key = principal
            .as_ref()
            .map_or_else(|| worker.name.clone(), |p| format!("@{p}"));
        worker.principal = principal;
        if let Some((_, in_row, all)) = standings.iter().find(|(w, _, _)| *w == worker.name) {
            (worker.audits_given_back, worker.audits_given_back_in_row) =
                (*all as u64, *in_row as u64);
        }
        if let Some((_, pairs, compared)) = compared.iter().find(|(w, _, _)| *w == key) {
            worker.noisy_audits_compared = *compared;
            worker.noisy_own_events = pairs.iter().map(|p| p.own_event).sum();
            worker.noisy_partner_events = pairs.iter().map(|p| p.partner_event).sum();
            worker.noisy_evidence = Some(worker_evidence(pairs));
        }
        // Its tests' evidence: one e-value a campaign; the largest shown,
        // the pairs counted over all.
        for (_, pairs, compared) in tested.iter().filter(|(w, _, _)| *w == key) {
            worker.test_pairs_compared += *compared;
            worker.test_own_events += pairs.iter().map(|p| p.own_event).sum::<u64>();
            worker.test_partner_events += pairs.iter().map(|p| p.partner_event).sum::<u64>();
            let evidence = worker_evidence(pairs);
            worker.test_evidence = Some(worker.test_evidence.map_or(evidence, |e| e.max(evidence)));
        }
    }
    Ok(Json(WorkerList {
        workers,
        costs: costs
            .into_iter()
            .map(|(program, seconds_per_test)| ProgramCost {
                program,
                seconds_per_test,
            })
            .collect(),
    }))
}

/// The worker named in a path, checked (400 otherwise).
fn path_name(name: &str) -> Result<(), ServiceError> {
    worker_name_problem(name).map_or(Ok(()), |m| Err(ServiceError::BadRequest(m)))
}

/// Revokes a worker's credential: every request in its name is refused
/// from now on and its leases are handed out again. Its results stay (to
/// take them back, it is a flag's work). Its name is not issued again.
#[utoipa::path(delete, path = "/api/v1/workers/{name}", params(("name" = String, Path)),
    responses((status = 204, description = "Revoked"), (status = 400, body = Problem),
    (status = 401, body = Problem), (status = 404, body = Problem)))]
pub async fn revoke(
    State(state): State<AppState>,
    ApiPath(name): ApiPath<String>,
) -> Result<StatusCode, ServiceError> {
    path_name(&name)?;
    if !state.credentials.revoke(&state.db, &name).await? {
        return Err(ServiceError::NotFound(format!(
            "worker `{name}` has no credential in force"
        )));
    }
    state.work.announce_one();
    tracing::warn!(worker = %name, "credential revoked by an operator");
    Ok(StatusCode::NO_CONTENT)
}

/// Clears a worker's flag: it gets work again (its taken-back results stay
/// taken back).
#[utoipa::path(delete, path = "/api/v1/workers/{name}/flag", params(("name" = String, Path)),
    responses((status = 204, description = "Cleared"), (status = 400, body = Problem),
    (status = 401, body = Problem), (status = 404, body = Problem)))]
pub async fn unflag(
    State(state): State<AppState>,
    ApiPath(name): ApiPath<String>,
) -> Result<StatusCode, ServiceError> {
    path_name(&name)?;
    let worker = name.clone();
    if !state
        .db
        .write(move |conn| {
            let principal = crate::store::credentials::principal_of(conn, &worker)?;
            let cleared = audits::unflag(conn, &worker)?;
            if cleared {
                discordance::forget(conn, &principal)?;
            }
            Ok::<_, ServiceError>(cleared)
        })
        .await?
    {
        return Err(ServiceError::NotFound(format!(
            "worker `{name}` is not flagged"
        )));
    }
    tracing::warn!(worker = %name, "flag cleared by an operator");
    Ok(StatusCode::NO_CONTENT)
}
