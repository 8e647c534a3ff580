//! `/healthz`: the coordinator answers, its database reads, and it
//! writes: a probe row set and committed through the writer, as every
//! lease and report is (a coordinator that reads but cannot write takes no
//! report: it is not healthy).

use crate::db::DbError;
use crate::error::ServiceError;
use crate::state::AppState;
use axum::extract::State;
use axum::Json;
use tslg_api::{Health, Problem};

/// Liveness and database health: 503 when the database cannot be read or
/// written, saying why.
#[utoipa::path(get, path = "/healthz", responses(
    (status = 200, body = Health), (status = 503, body = Problem)))]
pub async fn healthz(State(state): State<AppState>) -> Result<Json<Health>, ServiceError> {
    let unavailable = |what: &'static str| {
        move |e: DbError| {
            ServiceError::Unavailable(format!("the database cannot be {what}: {:#}", e.0))
        }
    };
    let db = &state.db;
    db.read(crate::db::sql::ping)
        .await
        .map_err(unavailable("read"))?;
    db.write(crate::db::sql::probe_write)
        .await
        .map_err(unavailable("written"))?;
    Ok(Json(Health {
        status: "ok".into(),
        version: env!("CARGO_PKG_VERSION").into(),
    }))
}
