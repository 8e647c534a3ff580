//! `GET /api/v1/queue`: the workers the running campaigns want, per
//! program (`crate::queue`), for autoscalers.

use crate::error::ServiceError;
use crate::routes::ApiQuery;
use crate::state::AppState;
use crate::store::campaigns;
use axum::extract::State;
use axum::Json;
use tslg_api::{CampaignStatus, Problem, QueueView};

/// `?program=` of the queue.
#[derive(Debug, serde::Deserialize, utoipa::IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct QueueQuery {
    /// Only this program: `NAME` (every case and mode of it), a whole
    /// `NAME:case:mode`, or `builtin`; its entries and their total (0, with
    /// no entries, when it has no campaign and no live worker).
    program: Option<String>,
}

/// The demand of the running campaigns, per program, and the workers
/// that would meet it within `--queue-target-seconds` (docs/api.md,
/// "Queue"). KEDA's `metrics-api` scaler reads `workers_wanted`, of all
/// programs or of one (`?program=NAME`); the same numbers are the
/// Prometheus gauges `tslg_workers_wanted{program}` and
/// `tslg_fleet_workers_wanted`.
#[utoipa::path(get, path = "/api/v1/queue", params(QueueQuery),
    responses((status = 200, body = QueueView), (status = 400, body = Problem)))]
pub async fn get(
    State(state): State<AppState>,
    ApiQuery(query): ApiQuery<QueueQuery>,
) -> Result<Json<QueueView>, ServiceError> {
    if let Some(program) = &query.program {
        if program.is_empty() || program.len() > 200 || program.chars().any(char::is_control) {
            return Err(ServiceError::BadRequest(
                "program must be 1 to 200 bytes without control characters: a program's \
                 NAME, NAME:case:mode, or builtin"
                    .into(),
            ));
        }
    }
    let rows = state
        .db
        .read(|conn| campaigns::list(conn, Some(CampaignStatus::Running)))
        .await?;
    Ok(Json(crate::queue::of_rows(
        &rows,
        &state.workers.fleet(),
        state.config.queue_target_seconds,
        query.program.as_deref(),
    )))
}
