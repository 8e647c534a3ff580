//! `GET /api/v1/queue`: the workers the running campaigns want, per
//! program (`crate::queue`), for autoscalers.

use crate::error::ServiceError;
use crate::state::AppState;
use crate::store::campaigns;
use axum::extract::State;
use axum::Json;
use tslg_api::{CampaignStatus, QueueView};

/// The demand of the running campaigns, per program, and the workers
/// that would meet it within `--queue-target-seconds` (docs/api.md,
/// "Queue"). KEDA's `metrics-api` scaler reads `workers_wanted` (or a
/// program's, by its name); the same numbers are the Prometheus gauge
/// `tslg_workers_wanted{program}`.
#[utoipa::path(get, path = "/api/v1/queue", responses((status = 200, body = QueueView)))]
pub async fn get(State(state): State<AppState>) -> Result<Json<QueueView>, ServiceError> {
    Ok(Json(queue(&state).await?))
}

/// The queue now.
async fn queue(state: &AppState) -> Result<QueueView, ServiceError> {
    let rows = state
        .db
        .read(|conn| campaigns::list(conn, Some(CampaignStatus::Running)))
        .await?;
    Ok(crate::queue::of_rows(
        &rows,
        &state.workers.fleet(),
        state.config.queue_target_seconds,
    ))
}
