use crate::error::ApiError;
use crate::state::AppState;
use axum::extract::State;
use axum::Json;
use tslg_api::{Health, Problem};

/// Liveness and database health.
#[utoipa::path(get, path = "/healthz", responses(
    (status = 200, body = Health), (status = 500, body = Problem)))]
pub async fn healthz(State(state): State<AppState>) -> Result<Json<Health>, ApiError> {
    sqlx::query("SELECT 1").execute(&state.db.read).await?;
    Ok(Json(Health {
        status: "ok".into(),
        version: env!("CARGO_PKG_VERSION").into(),
    }))
}
