//! Why the store did not read or write what it was asked: the row is not
//! there, its state does not allow the change, it is another worker's, or
//! the database failed. No HTTP here: the routes map these to problem
//! responses in one place (`routes/problem.rs`, through
//! [`crate::error::ServiceError`]).

use crate::db::DbError;

/// A refusal or failure of the store.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// No such row: a campaign, library, lease or audit that does not
    /// exist.
    #[error("{0}")]
    NotFound(String),
    /// The row's state does not allow it: a stopped campaign, a lease
    /// handed out again, a library in use.
    #[error("{0}")]
    Conflict(String),
    /// The row is not the caller's: a lease whose key does not match, a
    /// worker flagged for contradicted results.
    #[error("{0}")]
    NotYours(String),
    /// The database failed (or holds what it never should).
    #[error(transparent)]
    Database(#[from] DbError),
}

impl From<rusqlite::Error> for StoreError {
    fn from(e: rusqlite::Error) -> Self {
        StoreError::Database(e.into())
    }
}

impl From<serde_rusqlite::Error> for StoreError {
    fn from(e: serde_rusqlite::Error) -> Self {
        StoreError::Database(e.into())
    }
}

impl From<anyhow::Error> for StoreError {
    fn from(e: anyhow::Error) -> Self {
        StoreError::Database(DbError(e))
    }
}
