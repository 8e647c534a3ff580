//! Why the database did not do what it was asked: SQLite refused a
//! statement, a row did not have the shape read, a transaction could not
//! begin or commit, or a job panicked. Never the request's fault, so every
//! layer above answers it as an internal error, its cause logged.

/// A failure of the database, with its cause.
#[derive(Debug, thiserror::Error)]
#[error(transparent)]
pub struct DbError(#[from] pub anyhow::Error);

impl DbError {
    /// A failure described by `message`.
    pub fn new(message: impl std::fmt::Display) -> Self {
        DbError(anyhow::anyhow!("{message}"))
    }
}

impl From<rusqlite::Error> for DbError {
    fn from(e: rusqlite::Error) -> Self {
        DbError(e.into())
    }
}

impl From<serde_rusqlite::Error> for DbError {
    fn from(e: serde_rusqlite::Error) -> Self {
        DbError(e.into())
    }
}
