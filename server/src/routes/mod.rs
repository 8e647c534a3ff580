//! The HTTP routes: the API under `/api/v1`, the dashboard at `/` and
//! metrics at `/metrics`. Reads, the dashboard and metrics need the read (or
//! admin) token when one is set; the lease endpoints and the files workers
//! download need the worker (or admin) token when one is set; creating and
//! cancelling need the admin token when one is set. `/healthz` and the
//! OpenAPI document are always open.

mod auth;
mod campaigns;
mod cases;
mod dashboard;
mod enrolments;
mod events;
mod extract;
mod figures;
mod health;
mod latency;
pub(crate) mod leases;
mod libraries;
mod metrics;
pub mod openapi;
mod problem;
pub(crate) mod problem_io;
mod queue;
#[cfg(test)]
mod tests;
mod workers;

pub use extract::{ApiPath, ApiQuery};

use crate::error::ServiceError;
use crate::state::AppState;
use axum::extract::{DefaultBodyLimit, State};
use axum::http::StatusCode;
use axum::middleware::from_fn_with_state;
use axum::routing::{delete, get, post};
use axum::Router;
use problem::problem;
use std::sync::Arc;

pub fn router(state: AppState) -> Router {
    let admin = Router::new()
        .route("/api/v1/cases", post(cases::create))
        .route("/api/v1/libraries", post(libraries::create))
        .route("/api/v1/campaigns", post(campaigns::create))
        .route("/api/v1/campaigns/{id}/cancel", post(campaigns::cancel))
        .route("/api/v1/campaigns/{id}", delete(campaigns::delete))
        .route("/api/v1/libraries/{id}", delete(libraries::delete))
        .route("/api/v1/workers/{name}/flag", delete(workers::unflag))
        .route("/api/v1/workers/{name}", delete(workers::revoke))
        .route("/api/v1/enrolments", post(enrolments::issue))
        .route("/api/v1/enrolments/{principal}", delete(enrolments::revoke))
        .route_layer(from_fn_with_state(state.clone(), auth::require_admin));
    let worker = Router::new()
        .route("/api/v1/workers", post(workers::register))
        .route("/api/v1/workers/{name}/leave", post(workers::leave))
        .route("/api/v1/leases", post(leases::claim))
        .route("/api/v1/leases/{id}/heartbeat", post(leases::heartbeat))
        .route("/api/v1/leases/{id}/release", post(leases::release))
        .route("/api/v1/leases/{id}/results", post(leases::results))
        .route("/api/v1/leases/{id}/library", post(leases::library))
        .route("/api/v1/campaigns/{id}/plan", get(campaigns::plan))
        .route("/api/v1/libraries/{id}/file", get(libraries::file))
        .route_layer(from_fn_with_state(state.clone(), auth::require_worker));
    let open = Router::new()
        .route("/healthz", get(health::healthz))
        .route("/api/v1/openapi.json", get(openapi::document));
    let read = Router::new()
        .route("/api/v1/cases", get(cases::list))
        .route("/api/v1/libraries", get(libraries::list))
        .route("/api/v1/libraries/{id}", get(libraries::get_one))
        .route("/api/v1/campaigns", get(campaigns::list))
        .route("/api/v1/campaigns/{id}", get(campaigns::get_one))
        .route("/api/v1/campaigns/{id}/history", get(campaigns::history))
        .route("/api/v1/campaigns/{id}/stages", get(campaigns::stages))
        .route("/api/v1/campaigns/{id}/timeline", get(campaigns::timeline))
        .route("/api/v1/campaigns/{id}/events", get(events::list))
        .route(
            "/api/v1/campaigns/{id}/tests/{index}/openscenario",
            get(events::openscenario),
        )
        .route("/api/v1/workers", get(workers::list))
        .route("/api/v1/queue", get(queue::get))
        .route(
            "/api/v1/campaigns/{id}/figures/estimate.svg",
            get(figures::estimate),
        )
        .route(
            "/api/v1/campaigns/{id}/figures/relative-half-width.svg",
            get(figures::relative_half_width),
        )
        .route(
            "/api/v1/campaigns/{id}/figures/stages.svg",
            get(figures::stages),
        )
        .route(
            "/api/v1/campaigns/{id}/figures/support.svg",
            get(figures::support),
        )
        .route(
            "/api/v1/libraries/{id}/figures/picture.svg",
            get(figures::library_picture),
        )
        .route("/metrics", get(metrics::scrape))
        .route("/", get(dashboard::index))
        .route("/campaigns/{id}", get(dashboard::campaign))
        .route("/libraries/{id}", get(dashboard::library))
        .route("/assets/dashboard.js", get(dashboard::script))
        .route("/assets/dashboard.css", get(dashboard::style))
        .route_layer(from_fn_with_state(state.clone(), auth::require_read));
    let limit = state.config.max_body_bytes;
    admin
        .merge(worker)
        .merge(read)
        .merge(open)
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(DefaultBodyLimit::max(limit))
        .layer(from_fn_with_state(state.clone(), refuse_large_bodies))
        .layer(axum::middleware::from_fn(refuse_long_uris))
        .layer(axum::middleware::from_fn(problem::log_internal_errors))
        .layer(from_fn_with_state(
            Arc::clone(&state.metrics),
            latency::observe,
        ))
        .layer(tower_http::trace::TraceLayer::new_for_http())
        .with_state(state)
}

/// Refuses a request whose declared `Content-Length` exceeds the body
/// limit before any handler runs, on every route (also those that read no
/// body); bodies without a length are cut at the limit by the extractors
/// (`DefaultBodyLimit`).
async fn refuse_large_bodies(
    State(state): State<AppState>,
    request: axum::extract::Request,
    next: axum::middleware::Next,
) -> axum::response::Response {
    let limit = state.config.max_body_bytes;
    let declared = request
        .headers()
        .get(axum::http::header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    match declared {
        Some(length) if length > limit as u64 => problem(
            StatusCode::PAYLOAD_TOO_LARGE,
            format!("request body of {length} bytes exceeds the limit of {limit} bytes"),
        ),
        _ => next.run(request).await,
    }
}

/// The longest request target (path and query) the API takes: its
/// longest URL, a history query, is under a hundred bytes.
pub const MAX_URI_BYTES: usize = 8192;

/// Refuses a request target over [`MAX_URI_BYTES`] with 414 before routing.
/// (Targets over 65,534 bytes hyper refuses itself; [`problem_io`]
/// gives that answer its problem body.)
async fn refuse_long_uris(
    request: axum::extract::Request,
    next: axum::middleware::Next,
) -> axum::response::Response {
    let length = request
        .uri()
        .path_and_query()
        .map_or(0, |p| p.as_str().len());
    if length > MAX_URI_BYTES {
        return problem(
            StatusCode::URI_TOO_LONG,
            format!("the request target has {length} bytes; at most {MAX_URI_BYTES}"),
        );
    }
    next.run(request).await
}

async fn not_found(uri: axum::http::Uri) -> ServiceError {
    let path = uri.path();
    let shown: String = path.chars().take(200).collect();
    let more = if shown.len() < path.len() { "…" } else { "" };
    ServiceError::NotFound(format!("no route for {shown}{more}"))
}

async fn method_not_allowed(
    method: axum::http::Method,
    uri: axum::http::Uri,
) -> axum::response::Response {
    problem(
        StatusCode::METHOD_NOT_ALLOWED,
        format!("{method} is not allowed on {}", uri.path()),
    )
}
