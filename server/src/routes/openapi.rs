//! The OpenAPI 3 document, generated from the handlers and wire types.

use axum::Json;
use utoipa::OpenApi;

#[derive(OpenApi)]
#[openapi(
    info(
        title = "tslg coordinator",
        description = "Testing scenario library generation: \
        libraries, importance-sampling campaigns and the leases workers take."
    ),
    paths(
        super::health::healthz,
        super::libraries::create,
        super::libraries::list,
        super::libraries::get_one,
        super::libraries::file,
        super::campaigns::create,
        super::campaigns::list,
        super::campaigns::get_one,
        super::campaigns::history,
        super::campaigns::plan,
        super::campaigns::cancel,
        super::leases::claim,
        super::leases::heartbeat,
        super::leases::release,
        super::leases::results,
        super::leases::workers,
        super::figures::estimate,
        super::figures::relative_half_width,
        super::figures::library_picture,
    )
)]
pub struct ApiDoc;

/// `GET /api/v1/openapi.json`.
pub async fn document() -> Json<utoipa::openapi::OpenApi> {
    Json(ApiDoc::openapi())
}
