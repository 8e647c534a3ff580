//! `/api/v1/cases`: the cases this coordinator runs, each described by its
//! descriptor (presets, defaults, accepted tables, grid or sequential).

use crate::error::ServiceError;
use crate::routes::problem::ApiJson;
use crate::state::AppState;
use crate::store::user_cases;
use axum::extract::State;
use axum::http::StatusCode;
use axum::response::IntoResponse;
use axum::Json;
use tslg_api::{CaseView, CreateCase, Problem};
use tslg_client::wire::case_view;
use tslg_method::cases::user::file::CaseFile;
use tslg_method::cases::user::registry::{self, UserCaseDefinition};
use tslg_method::registry::CaseError;

/// The longest `table_name`, in bytes (docs/api.md, limits).
const MAX_TABLE_NAME: usize = 255;

/// Every case, in the order the help texts list them.
#[utoipa::path(get, path = "/api/v1/cases", responses((status = 200, body = Vec<CaseView>)))]
pub async fn list() -> Json<Vec<CaseView>> {
    Json(
        tslg_method::cases::descriptors()
            .iter()
            .map(tslg_client::wire::case_view)
            .collect(),
    )
}

/// Defines a user-defined grid case from its case file and exposure table
/// (docs/bring-your-own.md); libraries and campaigns then name it like a
/// built-in case. The same definition again is a 200; another under a
/// name in use a 409.
#[utoipa::path(post, path = "/api/v1/cases", request_body = CreateCase, responses(
    (status = 201, body = CaseView), (status = 200, body = CaseView),
    (status = 401, body = Problem), (status = 409, body = Problem), (status = 422, body = Problem)))]
pub async fn create(
    State(state): State<AppState>,
    ApiJson(req): ApiJson<CreateCase>,
) -> Result<impl IntoResponse, ServiceError> {
    if let Some(name) = &req.table_name {
        crate::validate::check_name("table_name", name, MAX_TABLE_NAME)?;
    }
    let file = CaseFile::parse(&req.file)
        .map_err(|e| ServiceError::Unprocessable(format!("case file: {e}")))?;
    let definition = UserCaseDefinition {
        table_name: req
            .table_name
            .clone()
            .unwrap_or_else(|| file.exposure.clone()),
        file: req.file,
        table: req.table,
    };
    let existed = registry::get(&file.name).is_some();
    let checked = definition.clone();
    let name = tokio::task::spawn_blocking(move || registry::register(checked))
        .await
        .map_err(|e| ServiceError::Internal(e.into()))?
        .map_err(|e| match e {
            CaseError::AlreadyDefined(_) => ServiceError::Conflict(e.to_string()),
            e => ServiceError::Unprocessable(e.to_string()),
        })?;
    let stored = name.clone();
    state
        .db
        .write(move |conn| user_cases::insert(conn, &stored, &definition))
        .await?;
    let view = case_view(
        &tslg_method::cases::descriptor(&name)
            .map_err(|e| ServiceError::Internal(anyhow::anyhow!("a case just registered: {e}")))?,
    );
    let status = if existed {
        StatusCode::OK
    } else {
        StatusCode::CREATED
    };
    Ok((status, Json(view)))
}
