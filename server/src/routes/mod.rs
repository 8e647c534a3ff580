//! The HTTP routes: the API under `/api/v1`, the dashboard at `/` and
//! metrics at `/metrics`. Reads are public; the lease endpoints and the files
//! workers download need the worker (or admin) token when one is set;
//! creating and cancelling need the admin token when one is set.

mod auth;
mod campaigns;
mod dashboard;
mod extract;
mod figures;
mod health;
mod leases;
mod libraries;
pub mod openapi;

pub use extract::{ApiPath, ApiQuery};
pub use figures::PictureCache;

use crate::error::{problem, ApiError};
use crate::state::AppState;
use axum::extract::DefaultBodyLimit;
use axum::http::StatusCode;
use axum::middleware::from_fn_with_state;
use axum::routing::{get, post};
use axum::Router;

pub fn router(state: AppState) -> Router {
    let admin = Router::new()
        .route("/api/v1/libraries", post(libraries::create))
        .route("/api/v1/campaigns", post(campaigns::create))
        .route("/api/v1/campaigns/{id}/cancel", post(campaigns::cancel))
        .route_layer(from_fn_with_state(state.clone(), auth::require_admin));
    let worker = Router::new()
        .route("/api/v1/leases", post(leases::claim))
        .route("/api/v1/leases/{id}/heartbeat", post(leases::heartbeat))
        .route("/api/v1/leases/{id}/release", post(leases::release))
        .route("/api/v1/leases/{id}/results", post(leases::results))
        .route("/api/v1/campaigns/{id}/plan", get(campaigns::plan))
        .route("/api/v1/libraries/{id}/file", get(libraries::file))
        .route_layer(from_fn_with_state(state.clone(), auth::require_worker));
    let public = Router::new()
        .route("/healthz", get(health::healthz))
        .route("/api/v1/openapi.json", get(openapi::document))
        .route("/api/v1/libraries", get(libraries::list))
        .route("/api/v1/libraries/{id}", get(libraries::get_one))
        .route("/api/v1/campaigns", get(campaigns::list))
        .route("/api/v1/campaigns/{id}", get(campaigns::get_one))
        .route("/api/v1/campaigns/{id}/history", get(campaigns::history))
        .route("/api/v1/workers", get(leases::workers))
        .route(
            "/api/v1/campaigns/{id}/figures/estimate.svg",
            get(figures::estimate),
        )
        .route(
            "/api/v1/campaigns/{id}/figures/relative-half-width.svg",
            get(figures::relative_half_width),
        )
        .route(
            "/api/v1/libraries/{id}/figures/picture.svg",
            get(figures::library_picture),
        )
        .route("/metrics", get(crate::metrics::scrape))
        .route("/", get(dashboard::index))
        .route("/campaigns/{id}", get(dashboard::campaign))
        .route("/libraries/{id}", get(dashboard::library))
        .route("/assets/dashboard.js", get(dashboard::script))
        .route("/assets/dashboard.css", get(dashboard::style));
    let limit = state.config.max_body_bytes;
    admin
        .merge(worker)
        .merge(public)
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(DefaultBodyLimit::max(limit))
        .layer(from_fn_with_state(state.clone(), crate::metrics::observe))
        .layer(tower_http::trace::TraceLayer::new_for_http())
        .with_state(state)
}

async fn not_found(uri: axum::http::Uri) -> ApiError {
    ApiError::NotFound(format!("no route for {}", uri.path()))
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
