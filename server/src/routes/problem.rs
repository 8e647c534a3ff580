//! Errors as HTTP: a [`ServiceError`] becomes its status and an
//! `application/problem+json` body (the one place the coordinator maps
//! its errors to statuses); a 500's cause is logged with its request,
//! never sent. Bodies are parsed with [`ApiJson`], whose rejection is the
//! same problem form with serde's precise message.

use crate::error::ServiceError;
use axum::extract::rejection::JsonRejection;
use axum::extract::{FromRequest, Request};
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use tslg_api::Problem;

impl ServiceError {
    /// The status the error answers with.
    fn status(&self) -> StatusCode {
        match self {
            ServiceError::BadRequest(_) => StatusCode::BAD_REQUEST,
            ServiceError::Unauthorized(_) => StatusCode::UNAUTHORIZED,
            ServiceError::Forbidden(_) => StatusCode::FORBIDDEN,
            ServiceError::NotFound(_) => StatusCode::NOT_FOUND,
            ServiceError::Conflict(_) => StatusCode::CONFLICT,
            ServiceError::TooLarge(_) => StatusCode::PAYLOAD_TOO_LARGE,
            ServiceError::Unprocessable(_) => StatusCode::UNPROCESSABLE_ENTITY,
            ServiceError::Unavailable(_) => StatusCode::SERVICE_UNAVAILABLE,
            ServiceError::Internal(_) => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }
}

/// A problem response with `status` and `detail`.
pub fn problem(status: StatusCode, detail: impl Into<String>) -> Response {
    let body = Problem {
        kind: "about:blank".into(),
        title: status.canonical_reason().unwrap_or("Error").into(),
        status: status.as_u16(),
        detail: detail.into(),
    };
    let mut response = (status, axum::Json(body)).into_response();
    response.headers_mut().insert(
        header::CONTENT_TYPE,
        header::HeaderValue::from_static("application/problem+json"),
    );
    response
}

/// The cause of a 500, carried to [`log_internal_errors`] in the
/// response's extensions (a response is not the place to log it).
#[derive(Clone)]
pub struct InternalCause(pub std::sync::Arc<anyhow::Error>);

impl IntoResponse for ServiceError {
    fn into_response(self) -> Response {
        let status = self.status();
        match self {
            ServiceError::Internal(cause) => {
                let mut response = problem(
                    status,
                    "internal error; the cause is in the coordinator's log",
                );
                response
                    .extensions_mut()
                    .insert(InternalCause(std::sync::Arc::new(cause)));
                response
            }
            other => problem(status, other.to_string()),
        }
    }
}

/// Logs the cause of every 500 with the request that met it: the client
/// gets an opaque problem, the operator the whole chain of causes.
pub async fn log_internal_errors(
    request: axum::extract::Request,
    next: axum::middleware::Next,
) -> Response {
    let (method, path) = (request.method().clone(), request.uri().path().to_owned());
    let response = next.run(request).await;
    if let Some(InternalCause(cause)) = response.extensions().get::<InternalCause>() {
        tracing::error!(%method, path, error = format!("{cause:#}"), "internal error");
    }
    response
}

/// A JSON body whose rejection is a problem response.
pub struct ApiJson<T>(pub T);

impl<T, S> FromRequest<S> for ApiJson<T>
where
    axum::Json<T>: FromRequest<S, Rejection = JsonRejection>,
    S: Send + Sync,
{
    type Rejection = ServiceError;

    async fn from_request(req: Request, state: &S) -> Result<Self, Self::Rejection> {
        match axum::Json::<T>::from_request(req, state).await {
            Ok(axum::Json(value)) => Ok(ApiJson(value)),
            Err(rejection) => Err(match rejection {
                JsonRejection::JsonDataError(e) => ServiceError::Unprocessable(format!(
                    "invalid request body: {}",
                    std::error::Error::source(&e)
                        .map(|s| s.to_string())
                        .unwrap_or_else(|| e.body_text())
                )),
                JsonRejection::BytesRejection(e) if e.status() == StatusCode::PAYLOAD_TOO_LARGE => {
                    ServiceError::TooLarge(format!("request body too large: {}", e.body_text()))
                }
                other => ServiceError::BadRequest(other.body_text()),
            }),
        }
    }
}
