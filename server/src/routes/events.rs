//! Results leaving the service: a campaign's events, paged, and any test of
//! a grid case as an OpenSCENARIO file (`event_export.rs` does the work).

use crate::error::ServiceError;
use crate::routes::{ApiPath, ApiQuery};
use crate::state::AppState;
use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::Json;
use tslg_api::{EventPage, Problem};

/// `?after=&limit=` of the event list.
#[derive(Debug, serde::Deserialize, utoipa::IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct EventQuery {
    /// Only events at test indices above this one (the previous page's
    /// `next_after`); from the first when absent.
    after: Option<u64>,
    /// The most events to return (1 to 10,000, default 1,000).
    #[param(minimum = 1, maximum = 10000)]
    limit: Option<usize>,
}

/// The events of the campaign's resolved prefix in increasing test index:
/// index, weight, scenario by dimension name, the library's criticality.
#[utoipa::path(get, path = "/api/v1/campaigns/{id}/events", params(("id" = i64, Path), EventQuery),
    responses((status = 200, body = EventPage), (status = 400, body = Problem), (status = 404, body = Problem)))]
pub async fn list(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
    ApiQuery(query): ApiQuery<EventQuery>,
) -> Result<Json<EventPage>, ServiceError> {
    Ok(Json(
        crate::campaign::events::page(&state, id, query.after, query.limit).await?,
    ))
}

/// Test `index` of the campaign as an ASAM OpenSCENARIO 1.0 file (grid
/// cases: cut-in, highway-exit), on the straight road `tslg_straight_road.xodr`
/// (`tslg campaign events --format xosc` writes it beside the files).
#[utoipa::path(get, path = "/api/v1/campaigns/{id}/tests/{index}/openscenario",
    params(("id" = i64, Path), ("index" = u64, Path)),
    responses((status = 200, content_type = "application/xml", body = String), (status = 404, body = Problem)))]
pub async fn openscenario(
    State(state): State<AppState>,
    ApiPath((id, index)): ApiPath<(i64, u64)>,
) -> Result<Response, ServiceError> {
    let xml = crate::campaign::events::openscenario(&state, id, index).await?;
    Ok(([(header::CONTENT_TYPE, "application/xml")], xml).into_response())
}
