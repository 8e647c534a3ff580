//! `/healthz`: the coordinator answers and its database does.

use crate::db::DbError;
use crate::error::ServiceError;
use crate::state::AppState;
use axum::extract::State;
use axum::Json;
use tslg_api::{Health, Problem};

/// Liveness and database health.
#[utoipa::path(get, path = "/healthz", responses(
    (status = 200, body = Health), (status = 500, body = Problem)))]
pub async fn healthz(State(state): State<AppState>) -> Result<Json<Health>, ServiceError> {
    state.db.read::<_, DbError, _>(crate::db::sql::ping).await?;
    Ok(Json(Health {
        status: "ok".into(),
        version: env!("CARGO_PKG_VERSION").into(),
    }))
}
