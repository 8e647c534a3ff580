//! `/api/v1/cases`: the cases this coordinator runs, each described by its
//! descriptor (presets, defaults, accepted tables, grid or sequential).

use axum::Json;
use tslg_api::CaseView;

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
