//! The dashboard: three HTML pages and their script and style, compiled
//! into the binary (nothing is fetched at run time). The pages poll the
//! JSON API and show the server's SVG figures; see `server/assets/`.

use crate::error::ServiceError;
use crate::routes::ApiPath;
use crate::state::AppState;
use crate::store::{campaigns, libraries};
use axum::extract::State;
use axum::http::header;
use axum::response::{Html, IntoResponse, Response};

const INDEX: &str = include_str!("../../assets/index.html");
const CAMPAIGN: &str = include_str!("../../assets/campaign.html");
const LIBRARY: &str = include_str!("../../assets/library.html");
const SCRIPT: &str = include_str!("../../assets/dashboard.js");
const STYLE: &str = include_str!("../../assets/dashboard.css");

/// `GET /`: campaigns, workers and libraries.
pub async fn index() -> Html<&'static str> {
    Html(INDEX)
}

/// `GET /campaigns/{id}`: a campaign with its live figures.
pub async fn campaign(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<Html<String>, ServiceError> {
    state.db.read(move |conn| campaigns::get(conn, id)).await?;
    Ok(Html(CAMPAIGN.replace("{{ID}}", &id.to_string())))
}

/// `GET /libraries/{id}`: a library with its picture.
pub async fn library(
    State(state): State<AppState>,
    ApiPath(id): ApiPath<i64>,
) -> Result<Html<String>, ServiceError> {
    state.db.read(move |conn| libraries::get(conn, id)).await?;
    Ok(Html(LIBRARY.replace("{{ID}}", &id.to_string())))
}

pub async fn script() -> Response {
    (
        [(header::CONTENT_TYPE, "text/javascript; charset=utf-8")],
        SCRIPT,
    )
        .into_response()
}

pub async fn style() -> Response {
    ([(header::CONTENT_TYPE, "text/css; charset=utf-8")], STYLE).into_response()
}
