//! `/api/v1/libraries`: build requests, state and files.

use crate::error::ServiceError;
use crate::routes::problem::ApiJson;
use crate::routes::{ApiPath, ApiQuery};
use crate::state::AppState;
use crate::store::libraries;
use axum::extract::State;
use axum::http::{header, StatusCode};
use axum::response::IntoResponse;
use axum::Json;
use tslg_api::{CreateLibrary, LibraryView, Problem};

/// Starts a library build; poll the library until `status` is `ready`.
#[utoipa::path(post, path = "/api/v1/libraries", request_body = CreateLibrary, responses(
    (status = 202, description = "Build started", body = LibraryView),
    (status = 400, body = Problem), (status = 401, body = Problem), (status = 422, body = Problem)))]
pub async fn create(
    State(state): State<AppState>,
    ApiJson(req): ApiJson<CreateLibrary>,
) -> Result<impl IntoResponse, ServiceError> {
    let row = crate::builds::start::start(&state, req).await?;
    let location = format!("/api/v1/libraries/{}", row.id);
    Ok((
        StatusCode::ACCEPTED,
        [(header::LOCATION, location)],
        Json(live_view(&state, &row).await?),
    ))
}

/// `?status=` of the library list.
#[derive(Debug, serde::Deserialize, utoipa::IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct ListQuery {
    /// Only the libraries in this state.
    #[param(value_type = Option<String>)]
    status: Option<tslg_api::LibraryStatus>,
}

/// Every library, or those in one state (`?status=ready`), newest first.
#[utoipa::path(get, path = "/api/v1/libraries", params(ListQuery),
    responses((status = 200, body = Vec<LibraryView>), (status = 400, body = Problem)))]
pub async fn list(
    State(state): State<AppState>,
    ApiQuery(query): ApiQuery<ListQuery>,
) -> Result<Json<Vec<LibraryView>>, ServiceError> {
    let status = query.status;
    let rows = state
        .db
        .read(move |conn| libraries::list(conn, status))
        .await?;
    let mut views = Vec::with_capacity(rows.len());
    for row in &rows {
        views.push(live_view(&state, row).await?);
    }
    Ok(Json(views))
}

/// One library's state.
#[utoipa::path(get, path = "/api/v1/libraries/{id}", params(("id" = i64, Path)), responses(
    (status = 200, body = LibraryView), (status = 404, body = Problem)))]
pub async fn get_one(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<Json<LibraryView>, ServiceError> {
    Ok(Json(
        live_view(
            &state,
            &state.db.read(move |conn| libraries::get(conn, id)).await?,
        )
        .await?,
    ))
}

/// The library file in its case's format (`docs/library-format.md`): JSON
/// (`tslg-library`) for the grid cases, the binary Q-table for car-following.
#[utoipa::path(get, path = "/api/v1/libraries/{id}/file", params(("id" = i64, Path)), responses(
    (status = 200, description = "The library file: application/json for grid cases, \
     application/vnd.tslg.policy-library for car-following", content(
        (Object = "application/json"),
        (Vec<u8> = "application/vnd.tslg.policy-library"))),
    (status = 404, body = Problem), (status = 409, body = Problem)))]
pub async fn file(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<impl IntoResponse, ServiceError> {
    let (_, file) = state
        .db
        .read(move |conn| libraries::ready_file(conn, id))
        .await?;
    Ok(([(header::CONTENT_TYPE, file.media_type)], file.bytes))
}

/// A library's view with the progress of its build, while it runs.
async fn live_view(
    state: &AppState,
    row: &libraries::LibraryRow,
) -> Result<LibraryView, ServiceError> {
    let mut view = crate::campaign::views::library_view(row);
    state.build_progress.fill(&mut view);
    crate::builds::on_workers::progress(state, &mut view).await?;
    Ok(view)
}

/// Deletes a library no campaign uses, with its file (and the campaign that
/// built it on workers); 409 while it builds or is used.
#[utoipa::path(delete, path = "/api/v1/libraries/{id}", params(("id" = i64, Path)), responses(
    (status = 204), (status = 401, body = Problem), (status = 404, body = Problem),
    (status = 409, body = Problem)))]
pub async fn delete(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<StatusCode, ServiceError> {
    state
        .db
        .write(move |conn| crate::store::deletion::delete_library(conn, id))
        .await?;
    state.pictures.lock().await.remove(&id);
    tracing::info!(library = id, "library deleted");
    Ok(StatusCode::NO_CONTENT)
}
