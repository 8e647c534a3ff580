//! `/api/v1/campaigns`: starting, watching and cancelling campaigns.

use crate::campaign;
use crate::campaign::history;
use crate::campaign::timeline;
use crate::campaign::views::live_view;
use crate::error::ServiceError;
use crate::routes::problem::ApiJson;
use crate::routes::{ApiPath, ApiQuery};
use crate::state::AppState;
use crate::store::{adaptive_stages, campaigns, work_spans};
use axum::extract::State;
use axum::http::{header, StatusCode};
use axum::response::IntoResponse;
use axum::Json;
use tslg_api::{
    AdaptiveStages, CampaignList, CampaignPlan, CampaignTimeline, CampaignView, CreateCampaign,
    History, Problem,
};

/// Starts a campaign. It runs as soon as its library is ready.
#[utoipa::path(post, path = "/api/v1/campaigns", request_body = CreateCampaign, responses(
    (status = 201, body = CampaignView), (status = 400, body = Problem),
    (status = 401, body = Problem), (status = 422, body = Problem)))]
pub async fn create(
    State(state): State<AppState>,
    ApiJson(req): ApiJson<CreateCampaign>,
) -> Result<impl IntoResponse, ServiceError> {
    let row = campaign::start::start(&state, req).await?;
    let location = format!("/api/v1/campaigns/{}", row.id);
    let view = live_view(&state, &row).await?;
    Ok((
        StatusCode::CREATED,
        [(header::LOCATION, location)],
        Json(view),
    ))
}

/// `?status=` of the campaign list.
#[derive(Debug, serde::Deserialize, utoipa::IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct ListQuery {
    /// Only the campaigns in this state.
    #[param(value_type = Option<String>)]
    status: Option<tslg_api::CampaignStatus>,
}

/// Every campaign, or those in one state (`?status=running`), newest first.
#[utoipa::path(get, path = "/api/v1/campaigns", params(ListQuery),
    responses((status = 200, body = CampaignList), (status = 400, body = Problem)))]
pub async fn list(
    State(state): State<AppState>,
    ApiQuery(query): ApiQuery<ListQuery>,
) -> Result<Json<CampaignList>, ServiceError> {
    let status = query.status;
    let rows = state
        .db
        .read(move |conn| campaigns::list(conn, status))
        .await?;
    let mut views = Vec::with_capacity(rows.len());
    for row in &rows {
        views.push(live_view(&state, row).await?);
    }
    Ok(Json(CampaignList { campaigns: views }))
}

/// One campaign's state and estimate over its resolved prefix.
#[utoipa::path(get, path = "/api/v1/campaigns/{id}", params(("id" = i64, Path)), responses(
    (status = 200, body = CampaignView), (status = 404, body = Problem)))]
pub async fn get_one(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<Json<CampaignView>, ServiceError> {
    Ok(Json(
        live_view(&state, &read_campaign(&state, id).await?).await?,
    ))
}

/// Campaign `id` as stored.
pub async fn read_campaign(
    state: &AppState,
    id: i64,
) -> Result<campaigns::CampaignRow, ServiceError> {
    Ok(state.db.read(move |conn| campaigns::get(conn, id)).await?)
}

/// An adaptive campaign's resolved stages in test order: where each
/// stage's tests sit, what they found and the support after it (empty for
/// other campaigns).
#[utoipa::path(get, path = "/api/v1/campaigns/{id}/stages", params(("id" = i64, Path)),
    responses((status = 200, body = AdaptiveStages), (status = 404, body = Problem)))]
pub async fn stages(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<Json<AdaptiveStages>, ServiceError> {
    let stages = state
        .db
        .read(move |conn| -> Result<_, ServiceError> {
            campaigns::get(conn, id)?;
            Ok(adaptive_stages::of(conn, id)?)
        })
        .await?;
    Ok(Json(AdaptiveStages {
        campaign_id: id,
        stages,
    }))
}

/// `?points=N` of the history read.
#[derive(Debug, serde::Deserialize, utoipa::IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct HistoryQuery {
    /// The most points to return (2 to 5000, default 300), logarithmically
    /// spaced in the number of tests.
    points: Option<usize>,
}

/// The estimate in the course of the campaign, in test order, from the
/// first fold to the current prefix, at most `points` of them spaced
/// logarithmically in the number of tests.
#[utoipa::path(get, path = "/api/v1/campaigns/{id}/history", params(("id" = i64, Path), HistoryQuery),
    responses((status = 200, body = History), (status = 400, body = Problem), (status = 404, body = Problem)))]
pub async fn history(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
    ApiQuery(query): ApiQuery<HistoryQuery>,
) -> Result<Json<History>, ServiceError> {
    let max = query.points.unwrap_or(history::DEFAULT_POINTS);
    if !(2..=history::MAX_POINTS).contains(&max) {
        return Err(ServiceError::BadRequest(format!(
            "points = {max} must be in 2..={}",
            history::MAX_POINTS
        )));
    }
    let points = state
        .db
        .read(move |conn| {
            let row = campaigns::get(conn, id)?;
            history::read(conn, &row, max)
        })
        .await?;
    Ok(Json(History {
        campaign_id: id,
        points,
    }))
}

/// `?buckets=N` of the timeline read.
#[derive(Debug, serde::Deserialize, utoipa::IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct TimelineQuery {
    /// Buckets of equal length from the first lease to the last report
    /// (1 to 1000, default 60).
    buckets: Option<u32>,
}

/// Where the campaign's wall time went: its workers busy on it over time,
/// from when each piece of its work was leased and reported.
#[utoipa::path(get, path = "/api/v1/campaigns/{id}/timeline", params(("id" = i64, Path), TimelineQuery),
    responses((status = 200, body = CampaignTimeline), (status = 400, body = Problem), (status = 404, body = Problem)))]
pub async fn timeline(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
    ApiQuery(query): ApiQuery<TimelineQuery>,
) -> Result<Json<CampaignTimeline>, ServiceError> {
    let buckets = query.buckets.unwrap_or(60);
    if !(1..=timeline::MAX_BUCKETS).contains(&buckets) {
        return Err(ServiceError::BadRequest(format!(
            "buckets = {buckets} must be in 1..={}",
            timeline::MAX_BUCKETS
        )));
    }
    let (spans, workers, folds) = state
        .db
        .read(move |conn| -> Result<_, ServiceError> {
            campaigns::get(conn, id)?;
            let (spans, workers) = work_spans::of(conn, id)?;
            Ok((spans, workers, work_spans::folds(conn, id)?))
        })
        .await?;
    Ok(Json(timeline::timeline(
        id, &spans, workers, &folds, buckets,
    )))
}

/// What a worker needs to reproduce any test of the campaign.
#[utoipa::path(get, path = "/api/v1/campaigns/{id}/plan", params(("id" = i64, Path)), responses(
    (status = 200, body = CampaignPlan), (status = 404, body = Problem)))]
pub async fn plan(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<Json<CampaignPlan>, ServiceError> {
    let (row, library, user_case) = state
        .db
        .read(move |conn| -> Result<_, ServiceError> {
            let row = campaigns::get(conn, id)?;
            let library = match row.library_id {
                Some(library) if row.method.runs_whole() => {
                    Some(crate::store::libraries::get(conn, library)?)
                }
                _ => None,
            };
            let user_case = crate::store::user_cases::get(conn, &row.case_name)?;
            Ok((row, library, user_case))
        })
        .await?;
    let (build_search, build_threshold) = match library {
        Some(library) => {
            let request: tslg_api::CreateLibrary = serde_json::from_str(&library.request)
                .map_err(|e| ServiceError::Internal(e.into()))?;
            (request.search, request.threshold)
        }
        _ => (None, None),
    };
    Ok(Json(CampaignPlan {
        campaign_id: row.id,
        case: row.case_name.clone(),
        preset: row.preset.clone(),
        exposure: row.exposure_request(),
        exposure_fingerprint: row.exposure_fingerprint.clone(),
        method: row.method,
        library_id: if row.method.uses_library() {
            row.library_id
        } else {
            None
        },
        epsilon: row.epsilon,
        outside: row.outside,
        split: row.split,
        seed: row.seed(),
        vut: serde_json::from_str(&row.vut).map_err(|e| ServiceError::Internal(e.into()))?,
        near_miss: (row.method.in_stages())
            .then(|| tslg_method::adaptive::AdaptiveSettings::default().near_miss),
        criticality_below: crate::report::evidence::criticality_below(&row),
        user_case: user_case.map(|d| tslg_api::UserCaseDefinition {
            file: d.file,
            table_name: d.table_name,
            table: d.table,
        }),
        build_search,
        build_threshold,
    }))
}

/// Cancels a pending or running campaign (with the other campaign of its
/// pair, if it has one); its leases are told to stop.
#[utoipa::path(post, path = "/api/v1/campaigns/{id}/cancel", params(("id" = i64, Path)), responses(
    (status = 200, body = CampaignView), (status = 404, body = Problem), (status = 409, body = Problem)))]
pub async fn cancel(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<Json<CampaignView>, ServiceError> {
    let row = crate::campaign::end::cancel(&state, id).await?;
    Ok(Json(live_view(&state, &row).await?))
}

/// Deletes a stopped campaign and everything recorded for it; 409 while it
/// runs (cancel it first).
#[utoipa::path(delete, path = "/api/v1/campaigns/{id}", params(("id" = i64, Path)), responses(
    (status = 204), (status = 401, body = Problem), (status = 404, body = Problem),
    (status = 409, body = Problem)))]
pub async fn delete(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<axum::http::StatusCode, ServiceError> {
    crate::campaign::end::delete(&state, id).await?;
    Ok(axum::http::StatusCode::NO_CONTENT)
}
