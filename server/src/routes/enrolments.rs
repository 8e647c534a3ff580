//! `/api/v1/enrolments` (admin): enrolment credentials, one per principal
//! (a host, an operator, a cluster job). A worker registering with one
//! belongs to its principal: audits, quorums and the statistical evidence
//! count principals, and a flag sticks to the principal (`crate::identity`,
//! docs/operations.md, "Who is trusted").

use crate::error::ServiceError;
use crate::routes::problem::ApiJson;
use crate::routes::ApiPath;
use crate::state::AppState;
use crate::store::enrolments;
use axum::extract::State;
use axum::http::StatusCode;
use axum::Json;
use tslg_api::{Enrolment, EnrolmentRequest, Problem};

/// The longest principal name.
const MAX_PRINCIPAL: usize = 120;

/// A principal's name: 1 to 120 letters, digits, `.`, `-` and `_` (422
/// otherwise).
fn check_principal(principal: &str) -> Result<(), ServiceError> {
    let fine = !principal.is_empty()
        && principal.len() <= MAX_PRINCIPAL
        && principal
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_'));
    if fine {
        return Ok(());
    }
    Err(ServiceError::Unprocessable(format!(
        "principal must be 1 to {MAX_PRINCIPAL} letters, digits, `.`, `-` or `_`"
    )))
}

/// Issues an enrolment credential for a principal; the secret is shown
/// once. 409 when the principal has one (revoked or not: a principal's
/// flags and evidence stay its own).
#[utoipa::path(post, path = "/api/v1/enrolments", request_body = EnrolmentRequest, responses(
    (status = 201, body = Enrolment), (status = 401, body = Problem),
    (status = 409, body = Problem), (status = 422, body = Problem)))]
pub async fn issue(
    State(state): State<AppState>,
    ApiJson(req): ApiJson<EnrolmentRequest>,
) -> Result<(StatusCode, Json<Enrolment>), ServiceError> {
    check_principal(&req.principal)?;
    let secret = format!(
        "{:032x}{:032x}",
        rand::random::<u128>(),
        rand::random::<u128>()
    );
    let hash = crate::identity::digest(&secret);
    let principal = req.principal.clone();
    let issued = state
        .db
        .write(move |conn| enrolments::issue(conn, &principal, &hash))
        .await?;
    let Some(issued_at) = issued else {
        return Err(ServiceError::Conflict(format!(
            "principal `{}` has an enrolment already; choose another name",
            req.principal
        )));
    };
    tracing::info!(principal = %req.principal, "enrolment issued");
    Ok((
        StatusCode::CREATED,
        Json(Enrolment {
            principal: req.principal,
            secret,
            issued_at,
        }),
    ))
}

/// Revokes a principal's enrolment: no worker registers with it any more
/// (its workers registered before keep their credentials; revoke those by
/// name). 404 when it has none in force.
#[utoipa::path(delete, path = "/api/v1/enrolments/{principal}", params(("principal" = String, Path)),
    responses((status = 204, description = "Revoked"), (status = 401, body = Problem),
    (status = 404, body = Problem), (status = 422, body = Problem)))]
pub async fn revoke(
    State(state): State<AppState>,
    ApiPath(principal): ApiPath<String>,
) -> Result<StatusCode, ServiceError> {
    check_principal(&principal)?;
    let name = principal.clone();
    if !state
        .db
        .write(move |conn| enrolments::revoke(conn, &name))
        .await?
    {
        return Err(ServiceError::NotFound(format!(
            "principal `{principal}` has no enrolment in force"
        )));
    }
    tracing::warn!(%principal, "enrolment revoked by an operator");
    Ok(StatusCode::NO_CONTENT)
}
