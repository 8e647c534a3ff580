//! Read-only connections for the API, the dashboard and the checks made
//! before a write. In WAL mode a reader sees the last commit and never
//! waits for the writer, nor the writer for it.
//!
//! A read is a synchronous closure run on tokio's blocking pool with a
//! connection taken from this pool (at most [`Readers::new`]'s `size` at
//! once; a connection is opened when none is idle, and kept after).

use super::error::DbError;
use super::writer::panicked;
use rusqlite::Connection;
use std::panic::AssertUnwindSafe;
use std::sync::Mutex;
use tokio::sync::Semaphore;

/// Opens one read connection.
type Opener = Box<dyn Fn() -> rusqlite::Result<Connection> + Send + Sync>;

pub struct Readers {
    idle: Mutex<Vec<Connection>>,
    permits: Semaphore,
    open: Opener,
}

impl Readers {
    /// A pool of at most `size` connections made by `open`.
    pub fn new(size: usize, open: Opener) -> Self {
        Self {
            idle: Mutex::new(Vec::new()),
            permits: Semaphore::new(size),
            open,
        }
    }

    /// Runs `work` on a read connection off the async runtime.
    pub async fn run<T, E, F>(&self, work: F) -> Result<T, E>
    where
        T: Send + 'static,
        E: From<DbError> + Send + 'static,
        F: FnOnce(&Connection) -> Result<T, E> + Send + 'static,
    {
        let _permit = self
            .permits
            .acquire()
            .await
            .map_err(|e| DbError(e.into()))?;
        let idle = self.idle.lock().unwrap_or_else(|p| p.into_inner()).pop();
        let conn = match idle {
            Some(conn) => conn,
            None => (self.open)()
                .map_err(|e| DbError::new(format!("cannot open the database for reading: {e}")))?,
        };
        let (conn, outcome) = tokio::task::spawn_blocking(move || {
            let outcome = std::panic::catch_unwind(AssertUnwindSafe(|| work(&conn)))
                .unwrap_or_else(|panic| Err(panicked("a read", &*panic).into()));
            (conn, outcome)
        })
        .await
        .map_err(|e| DbError(e.into()))?;
        self.idle
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .push(conn);
        outcome
    }
}
