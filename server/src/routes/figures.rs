//! The figures as SVG: a campaign's estimate and relative half-width
//! against tests, and a library's picture. The dashboard shows these and
//! `tslg campaign report` writes the same ones (`tslg-figures`).

use crate::error::ServiceError;
use crate::routes::ApiPath;
use crate::state::AppState;
use crate::store::campaigns::{self, CampaignRow};
use crate::store::libraries;
use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use std::sync::Arc;
use tslg_figures::{FigureError, Heatmap, HeatmapAxis};
use tslg_method::cases::open_case;
use tslg_method::registry::PictureMap;

fn svg(figure: Result<String, FigureError>) -> Result<Response, ServiceError> {
    let figure = figure.map_err(|e| ServiceError::Internal(e.into()))?;
    Ok((
        [
            (header::CONTENT_TYPE, "image/svg+xml"),
            (header::CACHE_CONTROL, "no-store"),
        ],
        figure,
    )
        .into_response())
}

/// The campaign's view (with its live rate) and what `read` takes from
/// the store for it, read together.
async fn view_with<T: Send + 'static>(
    state: &AppState,
    id: i64,
    read: impl FnOnce(&rusqlite::Connection, &CampaignRow) -> Result<T, ServiceError> + Send + 'static,
) -> Result<(tslg_api::CampaignView, T), ServiceError> {
    let (row, data) = state
        .db
        .read(move |conn| -> Result<_, ServiceError> {
            let row = campaigns::get(conn, id)?;
            let data = read(conn, &row)?;
            Ok((row, data))
        })
        .await?;
    Ok((crate::campaign::views::live_view(state, &row).await?, data))
}

/// The campaign's view and its history as plotted.
async fn campaign(
    state: &AppState,
    id: i64,
) -> Result<(tslg_api::CampaignView, Vec<tslg_api::HistoryPoint>), ServiceError> {
    view_with(state, id, |conn, row| {
        Ok(crate::campaign::history::read(
            conn,
            row,
            crate::campaign::history::DEFAULT_POINTS,
        )?)
    })
    .await
}

/// The estimate with its interval band against tests (log axis).
#[utoipa::path(get, path = "/api/v1/campaigns/{id}/figures/estimate.svg", params(("id" = i64, Path)),
    responses((status = 200, content_type = "image/svg+xml", body = String), (status = 404, body = tslg_api::Problem)))]
pub async fn estimate(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<Response, ServiceError> {
    let (view, points) = campaign(&state, id).await?;
    svg(tslg_figures::estimate_svg(&view, &points))
}

/// The relative half-width against tests with the line at β (log axes).
#[utoipa::path(get, path = "/api/v1/campaigns/{id}/figures/relative-half-width.svg", params(("id" = i64, Path)),
    responses((status = 200, content_type = "image/svg+xml", body = String), (status = 404, body = tslg_api::Problem)))]
pub async fn relative_half_width(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<Response, ServiceError> {
    let (view, points) = campaign(&state, id).await?;
    svg(tslg_figures::relative_half_width_svg(&view, &points))
}

/// An adaptive campaign's view and its resolved stages.
async fn adaptive(
    state: &AppState,
    id: i64,
) -> Result<(tslg_api::CampaignView, Vec<tslg_api::AdaptiveStage>), ServiceError> {
    view_with(state, id, move |conn, _| {
        Ok(crate::store::adaptive_stages::of(conn, id)?)
    })
    .await
}

/// An adaptive campaign's stages on one axis of all its tests, coloured by
/// kind, each as high as the events its tests met.
#[utoipa::path(get, path = "/api/v1/campaigns/{id}/figures/stages.svg", params(("id" = i64, Path)),
    responses((status = 200, content_type = "image/svg+xml", body = String), (status = 404, body = tslg_api::Problem)))]
pub async fn stages(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<Response, ServiceError> {
    let (view, stages) = adaptive(&state, id).await?;
    svg(tslg_figures::stages_svg(&view, &stages))
}

/// An adaptive campaign's support (failures found and library cells
/// untested) after each stage, against all its tests.
#[utoipa::path(get, path = "/api/v1/campaigns/{id}/figures/support.svg", params(("id" = i64, Path)),
    responses((status = 200, content_type = "image/svg+xml", body = String), (status = 404, body = tslg_api::Problem)))]
pub async fn support(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<Response, ServiceError> {
    let (view, stages) = adaptive(&state, id).await?;
    svg(tslg_figures::support_svg(&view, &stages))
}

/// The exposure beside the library's sampling distribution, projected onto
/// two axes (cut-in: range × range rate; highway exit: the two background
/// vehicles' positions; car-following: initial range × range rate).
#[utoipa::path(get, path = "/api/v1/libraries/{id}/figures/picture.svg", params(("id" = i64, Path)),
    responses((status = 200, content_type = "image/svg+xml", body = String), (status = 404, body = tslg_api::Problem),
        (status = 409, body = tslg_api::Problem)))]
pub async fn library_picture(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<Response, ServiceError> {
    // A ready library never changes: its picture is drawn once, and one
    // at a time (the highway grid has 1.6 × 10⁶ cells to project).
    let mut pictures = state.pictures.lock().await;
    if let Some(picture) = pictures.get(&id) {
        return svg(Ok(picture.as_ref().clone()));
    }
    let picture = draw_picture(&state, id).await?;
    pictures.insert(id, Arc::new(picture.clone()));
    svg(Ok(picture))
}

async fn draw_picture(state: &AppState, id: i64) -> Result<String, ServiceError> {
    let (row, file) = state
        .db
        .read(move |conn| libraries::ready_file(conn, id))
        .await?;
    let surrogate: serde_json::Value = serde_json::from_str(&row.surrogate).unwrap_or_default();
    let title = format!(
        "Library {id}: {}, surrogate {}, {} of {} scenarios",
        row.case_name,
        surrogate["model"].as_str().unwrap_or("?"),
        row.size.unwrap_or(0),
        row.total_scenarios
    );
    let maps = tokio::task::spawn_blocking(move || -> anyhow::Result<Vec<PictureMap>> {
        let case = open_case(&row.case_name, Some(&row.preset), &row.exposure_source())?;
        Ok(case.library_picture(&file.bytes)?)
    })
    .await
    .map_err(|e| ServiceError::Internal(e.into()))?
    .map_err(ServiceError::Internal)?;
    let maps: Vec<Heatmap> = maps.into_iter().map(heatmap).collect();
    tslg_figures::heatmaps_svg(&title, &maps).map_err(|e| ServiceError::Internal(e.into()))
}

fn heatmap(map: PictureMap) -> Heatmap {
    Heatmap {
        title: map.title,
        x: HeatmapAxis {
            label: map.x_label,
            centres: map.x_centres,
        },
        y: HeatmapAxis {
            label: map.y_label,
            centres: map.y_centres,
        },
        values: map.values,
    }
}
