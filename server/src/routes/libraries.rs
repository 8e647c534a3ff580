//! `/api/v1/libraries`: build requests, state and files.

use crate::builds::local::spawn_build;
use crate::builds::on_workers::{placement, Placement};
use crate::builds::request::build_request;
use crate::error::ServiceError;
use crate::routes::problem::ApiJson;
use crate::routes::{ApiPath, ApiQuery};
use crate::state::AppState;
use crate::store::libraries::{self, NewLibrary};
use crate::validate::check_name;
use axum::extract::State;
use axum::http::{header, StatusCode};
use axum::response::IntoResponse;
use axum::Json;
use tslg_api::{CreateLibrary, ExposureRequest, LibraryView, Problem};
use tslg_method::cases::open_case;

/// Starts a library build; poll the library until `status` is `ready`.
#[utoipa::path(post, path = "/api/v1/libraries", request_body = CreateLibrary, responses(
    (status = 202, description = "Build started", body = LibraryView),
    (status = 400, body = Problem), (status = 401, body = Problem), (status = 422, body = Problem)))]
pub async fn create(
    State(state): State<AppState>,
    ApiJson(req): ApiJson<CreateLibrary>,
) -> Result<impl IntoResponse, ServiceError> {
    let request = build_request(&req).map_err(ServiceError::Unprocessable)?;
    check_name("case", &req.case, 64)?;
    if let Some(preset) = &req.preset {
        check_name("preset", preset, 64)?;
    }
    if let ExposureRequest::Table { name, .. } = &req.exposure {
        check_name("exposure.name", name, 256)?;
        if name.trim().is_empty() {
            return Err(ServiceError::Unprocessable(
                "exposure.name must not be empty".into(),
            ));
        }
    }
    let checked = req.clone();
    let place = state.config.library_builds;
    let (case, surrogate, placement) = tokio::task::spawn_blocking(move || {
        let case = open_case(
            &checked.case,
            checked.preset.as_deref(),
            &tslg_client::wire::exposure_source(&checked.exposure),
        )?;
        case.check_request(&request)?;
        let surrogate = case.normalise_vehicle(&tslg_api::vehicle_spec(&checked.surrogate))?;
        let placement = placement(place, case.as_ref(), &request, &surrogate)
            .map_err(tslg_method::registry::CaseError::Unsupported)?;
        Ok::<_, tslg_method::registry::CaseError>((case, surrogate, placement))
    })
    .await
    .map_err(|e| ServiceError::Internal(e.into()))?
    .map_err(|e| ServiceError::Unprocessable(e.to_string()))?;
    let table = match &req.exposure {
        ExposureRequest::Builtin => None,
        ExposureRequest::Table { text, .. } => Some(text.clone()),
    };
    let request = serde_json::to_string(&req).map_err(|e| ServiceError::Internal(e.into()))?;
    let surrogate_spec = surrogate.clone();
    let surrogate = surrogate.to_string();
    let (name, preset, exposure_name) = (
        case.name().to_owned(),
        case.preset(),
        case.exposure_name().to_owned(),
    );
    let (fingerprint, note, total) = (
        case.exposure_fingerprint(),
        case.exposure_note(),
        case.total_scenarios(),
    );
    let row = state
        .db
        .write(move |conn| {
            libraries::insert(
                conn,
                &NewLibrary {
                    case_name: &name,
                    preset: &preset,
                    request: &request,
                    surrogate: &surrogate,
                    exposure_name: &exposure_name,
                    exposure_fingerprint: &fingerprint,
                    exposure_table: table.as_deref(),
                    exposure_note: note.as_deref(),
                    total_scenarios: total,
                },
            )
        })
        .await?;
    match placement {
        Placement::Coordinator => spawn_build(state.clone(), row.id),
        // Its surrogate runs are the workers' tests.
        Placement::Cells => {
            crate::builds::on_workers::start(&state, &row, case, &surrogate_spec).await?;
        }
        Placement::Whole => {
            crate::builds::whole::start(&state, &row, &surrogate_spec).await?;
        }
    }
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
    let mut view = crate::views::library_view(row);
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
