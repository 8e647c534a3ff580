//! Group commit: concurrent requests share one transaction and one fsync.
//!
//! With `durability` full every commit fsyncs the write-ahead log, so a
//! coordinator that commits once per lease and once per report is bound by
//! the disk's fsync rate. Here a request's writes run in a *savepoint* of a
//! transaction that stays open while other requests queue behind it; a
//! committer task commits the whole group at once, and only then does each
//! request get its answer. So a result is still acknowledged only once it
//! is on disk, and a request's failure rolls back its own savepoint only.
//!
//! Ordering: the requests take the writer in arrival order (tokio's mutex
//! is fair); the committer waits in the same queue, so every request that
//! queued before it joins the group it commits, and those after it form
//! the next one. The group's transaction holds the write pool's only
//! connection until it commits, so the writes that do not go through here
//! (`Database::write`) still never meet a second writer.
//!
//! Cancellation: a request dropped while it runs (its client went away)
//! drops its savepoint, which sqlx rolls back on the connection's next use,
//! and wakes the committer, so the group it would have joined still
//! commits.

use crate::error::ApiError;
use sqlx::{Connection, Sqlite, SqliteConnection, SqlitePool, Transaction};
use std::sync::Arc;
use tokio::sync::{oneshot, Mutex, Notify};

/// The answer a request waits for: its group's commit.
type CommitResult = Result<(), Arc<str>>;

/// The open group: its transaction and the requests waiting for its
/// commit.
#[derive(Default)]
struct Group {
    transaction: Option<Transaction<'static, Sqlite>>,
    waiting: Vec<oneshot::Sender<CommitResult>>,
}

/// The writer requests share (see the module documentation).
pub struct GroupCommit {
    pool: SqlitePool,
    group: Mutex<Group>,
    commit_due: Arc<Notify>,
}

impl GroupCommit {
    /// A group writer on `pool` (the single write connection) and its
    /// committer task, which ends when the last handle is dropped.
    pub fn start(pool: SqlitePool) -> Arc<Self> {
        let commit_due = Arc::new(Notify::new());
        let writer = Arc::new(Self {
            pool,
            group: Mutex::new(Group::default()),
            commit_due: Arc::clone(&commit_due),
        });
        let weak = Arc::downgrade(&writer);
        tokio::spawn(async move {
            loop {
                // Woken by a request that joined a group (or failed or was
                // dropped), or every second, to notice that the writer is
                // gone.
                let due = commit_due.notified();
                let _ = tokio::time::timeout(std::time::Duration::from_secs(1), due).await;
                let Some(writer) = weak.upgrade() else { return };
                writer.commit().await;
            }
        });
        writer
    }

    /// Runs `job` on the writer connection, in a savepoint of the open
    /// group's transaction, and answers once the group is committed: the
    /// job's value when both succeeded, the job's error (its writes rolled
    /// back, the others' kept) or the commit's.
    pub async fn run<T>(
        &self,
        job: impl AsyncFnOnce(&mut SqliteConnection) -> Result<T, ApiError>,
    ) -> Result<T, ApiError> {
        let committed = {
            let mut group = self.group.lock().await;
            // Whatever happens below, the committer looks at the group
            // once this request lets go of it.
            let _wake = WakeOnDrop(&self.commit_due);
            if group.transaction.is_none() {
                group.transaction = Some(self.pool.begin().await?);
            }
            let transaction = group.transaction.as_mut().expect("opened above");
            let mut savepoint = Connection::begin(&mut **transaction).await?;
            let value = job(&mut savepoint).await?;
            savepoint.commit().await?;
            let (done, committed) = oneshot::channel();
            group.waiting.push(done);
            (value, committed)
        };
        let (value, committed) = committed;
        match committed.await {
            Ok(Ok(())) => Ok(value),
            Ok(Err(reason)) => Err(ApiError::Internal(anyhow::anyhow!(
                "the group commit failed: {reason}"
            ))),
            Err(_) => Err(ApiError::Internal(anyhow::anyhow!(
                "the group writer stopped before committing"
            ))),
        }
    }

    /// Commits the open group, if any, and answers its requests.
    async fn commit(&self) {
        let mut group = self.group.lock().await;
        let Some(transaction) = group.transaction.take() else {
            return;
        };
        let waiting = std::mem::take(&mut group.waiting);
        let result: CommitResult = transaction.commit().await.map_err(|e| {
            tracing::error!(error = %e, requests = waiting.len(), "a group commit failed");
            Arc::from(e.to_string())
        });
        drop(group);
        for done in waiting {
            // A request whose client went away no longer listens.
            let _ = done.send(result.clone());
        }
    }
}

/// Wakes the committer when dropped: after a request joined the group, and
/// also when it failed or was cancelled while holding the writer (the
/// requests already in the group must still be committed).
struct WakeOnDrop<'a>(&'a Notify);

impl Drop for WakeOnDrop<'_> {
    fn drop(&mut self) {
        self.0.notify_one();
    }
}
