//! Why the coordinator did not do what a request asked, in its own terms:
//! every layer below the routes returns a [`ServiceError`] (the store its
//! own [`StoreError`], the database its [`DbError`], both converted here).
//! Each variant's doc names the status the routes answer it with
//! (`routes/problem.rs`, the one place that speaks HTTP about errors).
//! Database and unexpected errors become an opaque 500 whose cause is
//! logged, never sent.

use crate::db::DbError;
use crate::store::error::StoreError;

#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    /// 400: the body is not the JSON the endpoint takes.
    #[error("{0}")]
    BadRequest(String),
    /// 401: a token is required and missing or wrong.
    #[error("{0}")]
    Unauthorized(String),
    /// 403: authenticated, but not allowed this resource (another
    /// worker's lease).
    #[error("{0}")]
    Forbidden(String),
    /// 404: no such resource.
    #[error("{0}")]
    NotFound(String),
    /// 409: the request conflicts with the resource's state.
    #[error("{0}")]
    Conflict(String),
    /// 413: the body is larger than the configured limit.
    #[error("{0}")]
    TooLarge(String),
    /// 422: well-formed, but a value is out of range or inconsistent.
    #[error("{0}")]
    Unprocessable(String),
    /// 503: the coordinator answers but cannot do its work (its database
    /// cannot be written); the detail says why.
    #[error("{0}")]
    Unavailable(String),
    /// 500: anything else; the cause is logged, not returned.
    #[error(transparent)]
    Internal(#[from] anyhow::Error),
}

impl From<DbError> for ServiceError {
    fn from(e: DbError) -> Self {
        ServiceError::Internal(e.0)
    }
}

impl From<StoreError> for ServiceError {
    fn from(e: StoreError) -> Self {
        match e {
            StoreError::NotFound(detail) => ServiceError::NotFound(detail),
            StoreError::Conflict(detail) => ServiceError::Conflict(detail),
            StoreError::NotYours(detail) => ServiceError::Forbidden(detail),
            StoreError::Database(e) => e.into(),
        }
    }
}

impl From<rusqlite::Error> for ServiceError {
    fn from(e: rusqlite::Error) -> Self {
        ServiceError::Internal(e.into())
    }
}

impl From<serde_rusqlite::Error> for ServiceError {
    fn from(e: serde_rusqlite::Error) -> Self {
        ServiceError::Internal(e.into())
    }
}
