//! `GET /metrics`, in the Prometheus text exposition format (version
//! 0.0.4; `crate::telemetry::metrics` gathers it).

use crate::error::ServiceError;
use crate::state::AppState;
use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};

/// `GET /metrics`.
pub async fn scrape(State(state): State<AppState>) -> Result<Response, ServiceError> {
    let body = crate::telemetry::metrics::exposition(&state).await?;
    Ok(([(header::CONTENT_TYPE, prometheus::TEXT_FORMAT)], body).into_response())
}
