//! `/api/v1/campaigns`: starting, watching and cancelling campaigns.

use crate::error::{ApiError, ApiJson};
use crate::history;
use crate::routes::{ApiPath, ApiQuery};
use crate::state::AppState;
use crate::store::campaigns::{self, NewCampaign};
use crate::store::libraries;
use axum::extract::State;
use axum::http::{header, StatusCode};
use axum::response::IntoResponse;
use axum::Json;
use tslg_api::{
    CampaignList, CampaignPlan, CampaignStatus, CampaignView, CreateCampaign, History,
    LibraryStatus, Method, Outside, Problem,
};
use tslg_method::estimator::{default_n_min, StoppingRule, DEFAULT_MIN_EVENTS};
use tslg_method::external::ExternalVut;
use tslg_method::registry::{exploring_share, open_case, ExposureSource, SEQUENTIAL_CASES};
use tslg_method::sampling::OutsideSpread;

/// Largest accepted test budget.
const MAX_TESTS_LIMIT: u64 = 1 << 50;

/// Starts a campaign. It runs as soon as its library is ready.
#[utoipa::path(post, path = "/api/v1/campaigns", request_body = CreateCampaign, responses(
    (status = 201, body = CampaignView), (status = 400, body = Problem),
    (status = 401, body = Problem), (status = 422, body = Problem)))]
pub async fn create(
    State(state): State<AppState>,
    ApiJson(req): ApiJson<CreateCampaign>,
) -> Result<impl IntoResponse, ApiError> {
    let bad = |m: String| ApiError::Unprocessable(m);
    if !(0.0..1.0).contains(&req.epsilon) {
        return Err(bad(format!("epsilon = {} must be in [0, 1)", req.epsilon)));
    }
    let rule = StoppingRule {
        beta: req.beta,
        confidence: req.confidence,
        n_min: req.n_min.unwrap_or_else(|| {
            default_n_min(
                exploring_share(&req.case, req.method == Method::Library, req.epsilon),
                req.max_tests,
            )
        }),
        min_events: req.min_events.unwrap_or(DEFAULT_MIN_EVENTS),
        max_tests: req.max_tests,
        guard_outside: req.guard_outside,
    };
    rule.validate().map_err(|e| bad(e.to_string()))?;
    if rule.n_min == 0 {
        return Err(bad("n_min must be at least 1".into()));
    }
    if req.max_tests > MAX_TESTS_LIMIT {
        return Err(bad(format!(
            "max_tests = {} exceeds the limit 2^50",
            req.max_tests
        )));
    }
    if req.guard_outside && req.method == Method::Ndd {
        return Err(bad(
            "guard_outside bounds the failure mass outside a library; an ndd campaign samples \
             every scenario by its exposure and has no outside to guard"
                .into(),
        ));
    }
    if req.guard_outside && SEQUENTIAL_CASES.contains(&req.case.as_str()) {
        return Err(bad(format!(
            "guard_outside applies to the grid cases (cut-in, highway-exit): a {} campaign \
             explores per decision, and no bound on its outside mass is defined",
            req.case
        )));
    }
    let library = match (req.method, req.library_id) {
        (Method::Library, None) => {
            return Err(bad("method `library` needs a library_id".into()));
        }
        (_, Some(id)) => Some(
            libraries::get(&state.db.read, id)
                .await
                .map_err(|_| bad(format!("library_id {id} does not name a library")))?,
        ),
        (Method::Ndd, None) => None,
    };
    if let Some(lib) = &library {
        if lib.case_name != req.case {
            return Err(bad(format!(
                "library {} was built for case `{}`, not `{}`",
                lib.id, lib.case_name, req.case
            )));
        }
        if lib.status() == LibraryStatus::Failed && req.method == Method::Library {
            return Err(bad(format!(
                "library {} failed to build: {}",
                lib.id,
                lib.error.as_deref().unwrap_or("unknown reason")
            )));
        }
    }
    let exposure = match &library {
        Some(lib) => match &lib.exposure_table {
            Some(text) => ExposureSource::Table {
                name: lib.exposure_name.clone(),
                text: text.clone(),
            },
            None => ExposureSource::Builtin,
        },
        None => ExposureSource::Builtin,
    };
    let preset = library.as_ref().map(|l| l.preset.clone());
    // A ready library's file, to prepare the campaign's tests now: what a
    // worker could not prepare must be refused here, not leased forever.
    let file = match &library {
        Some(lib) if req.method == Method::Library && lib.status() == LibraryStatus::Ready => Some(
            libraries::file(&state.db.read, lib.id)
                .await?
                .ok_or_else(|| {
                    ApiError::Internal(anyhow::anyhow!("ready library {} has no file", lib.id))
                })?
                .bytes,
        ),
        _ => None,
    };
    let prepare = req.method == Method::Ndd || file.is_some();
    let (case_name, vut, epsilon, requested, seed) = (
        req.case.clone(),
        req.vut.clone(),
        req.epsilon,
        req.outside,
        req.seed,
    );
    let source = exposure.clone();
    let (case, vut, outside, tests) = tokio::task::spawn_blocking(move || {
        let case = open_case(&case_name, preset.as_deref(), &source)?;
        let vut = case.normalise_vehicle(&vut)?;
        let outside = match requested {
            Some(Outside::Uniform) => OutsideSpread::Uniform,
            Some(Outside::Ndd) => OutsideSpread::Ndd,
            None => case.default_outside(),
        };
        let tests = if prepare {
            Some(case.campaign(file.as_deref(), &vut, epsilon, outside, seed)?)
        } else {
            None
        };
        Ok::<_, tslg_method::registry::CaseError>((case, vut, outside, tests))
    })
    .await
    .map_err(|e| ApiError::Internal(e.into()))?
    .map_err(|e| bad(e.to_string()))?;
    let outside = match outside {
        OutsideSpread::Uniform => Outside::Uniform,
        OutsideSpread::Ndd => Outside::Ndd,
    };
    // Only workers offering an external program get its tests.
    let requires = ExternalVut::from_spec(&vut)
        .and_then(Result::ok)
        .map(|e| e.requirement(case.name()));
    let status = match &library {
        Some(lib) if req.method == Method::Library && lib.status() == LibraryStatus::Building => {
            CampaignStatus::Pending
        }
        _ => CampaignStatus::Running,
    };
    let row = campaigns::insert(
        &state.db.write,
        &NewCampaign {
            case_name: case.name().to_owned(),
            preset: case.preset(),
            method: req.method,
            library_id: req.library_id,
            exposure_name: case.exposure_name().to_owned(),
            exposure_fingerprint: case.exposure_fingerprint(),
            exposure_table: match exposure {
                ExposureSource::Table { text, .. } => Some(text),
                ExposureSource::Builtin => None,
            },
            vut: vut.to_string(),
            requires,
            epsilon: req.epsilon,
            outside,
            rule,
            seed: req.seed,
            status,
        },
    )
    .await?;
    if let Some(tests) = tests {
        state.samplers.insert(row.id, tests);
    }
    let location = format!("/api/v1/campaigns/{}", row.id);
    Ok((
        StatusCode::CREATED,
        [(header::LOCATION, location)],
        Json(row.view()),
    ))
}

/// Every campaign, newest first.
#[utoipa::path(get, path = "/api/v1/campaigns", responses((status = 200, body = CampaignList)))]
pub async fn list(State(state): State<AppState>) -> Result<Json<CampaignList>, ApiError> {
    let rows = campaigns::list(&state.db.read).await?;
    Ok(Json(CampaignList {
        campaigns: rows.iter().map(|r| live_view(&state, r)).collect(),
    }))
}

/// One campaign's state and estimate over its resolved prefix.
#[utoipa::path(get, path = "/api/v1/campaigns/{id}", params(("id" = i64, Path)), responses(
    (status = 200, body = CampaignView), (status = 404, body = Problem)))]
pub async fn get_one(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<Json<CampaignView>, ApiError> {
    Ok(Json(live_view(
        &state,
        &campaigns::get(&state.db.read, id).await?,
    )))
}

/// A campaign's view with its current rate and the time left.
pub fn live_view(state: &AppState, row: &campaigns::CampaignRow) -> CampaignView {
    let mut view = row.view();
    state.throughput.fill(&mut view);
    view
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
) -> Result<Json<History>, ApiError> {
    let max = query.points.unwrap_or(history::DEFAULT_POINTS);
    if !(2..=history::MAX_POINTS).contains(&max) {
        return Err(ApiError::BadRequest(format!(
            "points = {max} must be in 2..={}",
            history::MAX_POINTS
        )));
    }
    let row = campaigns::get(&state.db.read, id).await?;
    Ok(Json(History {
        campaign_id: id,
        points: campaigns::history(&state.db.read, &row, max).await?,
    }))
}

/// What a worker needs to reproduce any test of the campaign.
#[utoipa::path(get, path = "/api/v1/campaigns/{id}/plan", params(("id" = i64, Path)), responses(
    (status = 200, body = CampaignPlan), (status = 404, body = Problem)))]
pub async fn plan(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<Json<CampaignPlan>, ApiError> {
    let row = campaigns::get(&state.db.read, id).await?;
    Ok(Json(CampaignPlan {
        campaign_id: row.id,
        case: row.case_name.clone(),
        preset: row.preset.clone(),
        exposure: row.exposure_request(),
        exposure_fingerprint: row.exposure_fingerprint.clone(),
        method: row.method(),
        library_id: if row.method() == Method::Library {
            row.library_id
        } else {
            None
        },
        epsilon: row.epsilon,
        outside: row.outside(),
        seed: row.seed(),
        vut: serde_json::from_str(&row.vut).map_err(|e| ApiError::Internal(e.into()))?,
    }))
}

/// Cancels a pending or running campaign; its leases are told to stop.
#[utoipa::path(post, path = "/api/v1/campaigns/{id}/cancel", params(("id" = i64, Path)), responses(
    (status = 200, body = CampaignView), (status = 404, body = Problem), (status = 409, body = Problem)))]
pub async fn cancel(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<Json<CampaignView>, ApiError> {
    let row = campaigns::cancel(&state.db.write, id).await?;
    state.samplers.forget(id);
    state.throughput.forget(id);
    Ok(Json(row.view()))
}
