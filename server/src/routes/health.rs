use crate::error::ServiceError;
use crate::state::AppState;
use axum::extract::State;
use axum::Json;
use tslg_api::{Health, Problem};

/// Liveness and database health.
#[utoipa::path(get, path = "/healthz", responses(
    (status = 200, body = Health), (status = 500, body = Problem)))]
pub async fn healthz(State(state): State<AppState>) -> Result<Json<Health>, ServiceError> {
    state
        .db
        .read(|conn| -> Result<_, ServiceError> {
            conn.query_row("SELECT 1", [], |_| Ok(()))?;
            Ok(())
        })
        .await?;
    Ok(Json(Health {
        status: "ok".into(),
        version: env!("CARGO_PKG_VERSION").into(),
    }))
}
