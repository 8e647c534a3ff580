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
//! drops its savepoint, which sqlx rolls back on the connection's next use
//! (before any later statement), and wakes the committer, so the group it
//! would have joined still commits.

use crate::error::ApiError;
use sqlx::{Connection, Sqlite, SqliteConnection, SqlitePool, Transaction};
use std::sync::atomic::{AtomicU64, Ordering};
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
    /// The request that opened the transaction runs without a savepoint
    /// (it is alone in it); set while it runs, so that if it is cancelled
    /// the next one to take the writer rolls the whole transaction back.
    opener_running: bool,
}

impl Group {
    /// The open transaction, rolled back first when the request that
    /// opened it did not finish.
    fn open(&mut self) -> Option<&mut Transaction<'static, Sqlite>> {
        if self.opener_running {
            // Dropped uncommitted: sqlx rolls it back before the
            // connection's next statement.
            self.transaction = None;
            self.opener_running = false;
        }
        self.transaction.as_mut()
    }
}

/// The writer requests share (see the module documentation).
pub struct GroupCommit {
    pool: SqlitePool,
    group: Mutex<Group>,
    commit_due: Arc<Notify>,
    /// Groups committed, and the requests they answered (for `/metrics`:
    /// their ratio is the mean group size).
    groups: AtomicU64,
    grouped: AtomicU64,
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
            groups: AtomicU64::new(0),
            grouped: AtomicU64::new(0),
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
            let value = if let Some(transaction) = group.open() {
                // Released when the job succeeds: leaving each request's
                // savepoint open until the commit saves a statement but
                // was measured slower (64 workers: 1,900-2,300 against
                // 2,800-3,450 requests/s).
                let mut savepoint = Connection::begin(&mut **transaction).await?;
                let value = job(&mut savepoint).await?;
                savepoint.commit().await?;
                value
            } else {
                // The first request of a group needs no savepoint: if it
                // fails, the transaction holds nothing else and is rolled
                // back whole (two statements fewer, which counts when few
                // workers make the groups small).
                group.opener_running = true;
                let transaction = group.transaction.insert(self.pool.begin().await?);
                let outcome = job(&mut **transaction).await;
                group.opener_running = false;
                match outcome {
                    Ok(value) => value,
                    Err(e) => {
                        group.transaction = None;
                        return Err(e);
                    }
                }
            };
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

    /// Groups committed so far, and the requests they answered.
    pub fn counts(&self) -> (u64, u64) {
        (
            self.groups.load(Ordering::Relaxed),
            self.grouped.load(Ordering::Relaxed),
        )
    }

    /// Commits the open group, if any, and answers its requests.
    async fn commit(&self) {
        let mut group = self.group.lock().await;
        if group.open().is_none() {
            return;
        }
        let Some(transaction) = group.transaction.take() else {
            return;
        };
        let waiting = std::mem::take(&mut group.waiting);
        let result: CommitResult = transaction.commit().await.map_err(|e| {
            tracing::error!(error = %e, requests = waiting.len(), "a group commit failed");
            Arc::from(e.to_string())
        });
        drop(group);
        if result.is_ok() {
            self.groups.fetch_add(1, Ordering::Relaxed);
            self.grouped
                .fetch_add(waiting.len() as u64, Ordering::Relaxed);
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::db::{Database, Durability};
    use std::time::Duration;

    async fn database() -> (tempfile::TempDir, Database) {
        let dir = tempfile::tempdir().unwrap();
        let url = format!("sqlite://{}/db.sqlite", dir.path().display());
        let db = Database::open(&url, Durability::Full).await.unwrap();
        sqlx::query("CREATE TABLE rows (n INTEGER PRIMARY KEY)")
            .execute(&db.write)
            .await
            .unwrap();
        (dir, db)
    }

    async fn insert(conn: &mut SqliteConnection, n: i64) -> Result<(), ApiError> {
        sqlx::query("INSERT INTO rows (n) VALUES (?)")
            .bind(n)
            .execute(conn)
            .await?;
        Ok(())
    }

    async fn stored(db: &Database) -> Vec<i64> {
        sqlx::query_scalar("SELECT n FROM rows ORDER BY n")
            .fetch_all(&db.read)
            .await
            .unwrap()
    }

    /// A request that writes row `n`, says so, and never finishes (until
    /// it is aborted).
    fn write_and_hang(
        db: &Database,
        n: i64,
    ) -> (
        tokio::task::JoinHandle<Result<(), ApiError>>,
        oneshot::Receiver<()>,
    ) {
        let (inside, entered) = oneshot::channel::<()>();
        let db = db.clone();
        let task = tokio::spawn(async move {
            db.group
                .run(async |conn| {
                    insert(conn, n).await?;
                    inside.send(()).unwrap();
                    std::future::pending::<()>().await;
                    Ok(())
                })
                .await
        });
        (task, entered)
    }

    /// Forty concurrent requests, every third failing after its write: the
    /// others' rows are all stored, the failed ones' none, each success is
    /// readable from another connection the moment it is answered, and
    /// they shared fewer commits than there were requests.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_failed_request_rolls_back_only_its_own_writes() {
        let (_dir, db) = database().await;
        let tasks: Vec<_> = (0..40)
            .map(|n| {
                let db = db.clone();
                tokio::spawn(async move {
                    let answer = db
                        .group
                        .run(async |conn| {
                            insert(conn, n).await?;
                            if n % 3 == 0 {
                                return Err(ApiError::Conflict(format!("request {n} fails")));
                            }
                            Ok(n)
                        })
                        .await;
                    if answer.is_ok() {
                        // Answered only once committed: another connection
                        // sees the row.
                        assert!(stored(&db).await.contains(&n), "row {n} not committed");
                    }
                    answer
                })
            })
            .collect();
        let mut succeeded = Vec::new();
        for (n, task) in tasks.into_iter().enumerate() {
            match task.await.unwrap() {
                Ok(value) => succeeded.push(value),
                Err(e) => {
                    assert_eq!(n % 3, 0);
                    assert_eq!(e.to_string(), format!("request {n} fails"));
                }
            }
        }
        let expected: Vec<i64> = (0..40).filter(|n| n % 3 != 0).collect();
        assert_eq!(succeeded, expected);
        assert_eq!(stored(&db).await, expected);
        let (groups, grouped) = db.group.counts();
        assert_eq!(grouped, expected.len() as u64);
        assert!(groups < grouped, "{groups} commits for {grouped} requests");
    }

    /// A request cancelled while it holds the writer (its client went
    /// away) leaves nothing behind, and the request that joined the group
    /// before it and the one queued behind it are still committed.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_cancelled_request_is_rolled_back_and_the_group_still_commits() {
        let (_dir, db) = database().await;
        let (a_inside, a_entered) = oneshot::channel::<()>();
        let (a_go, a_released) = oneshot::channel::<()>();
        let first = tokio::spawn({
            let db = db.clone();
            async move {
                db.group
                    .run(async |conn| {
                        insert(conn, 1).await?;
                        a_inside.send(()).unwrap();
                        a_released.await.unwrap();
                        Ok(())
                    })
                    .await
            }
        });
        a_entered.await.unwrap();
        // The second request queues for the writer while the first holds
        // it, so it takes the writer before the committer does.
        let (stuck, b_entered) = write_and_hang(&db, 2);
        tokio::time::sleep(Duration::from_millis(100)).await;
        a_go.send(()).unwrap();
        b_entered.await.unwrap();
        let behind = tokio::spawn({
            let db = db.clone();
            async move { db.group.run(async |conn| insert(conn, 3).await).await }
        });
        tokio::time::sleep(Duration::from_millis(100)).await;
        assert!(
            !first.is_finished(),
            "the first request is answered only when its group commits"
        );
        stuck.abort();
        assert!(stuck.await.unwrap_err().is_cancelled());
        for answer in [first, behind] {
            tokio::time::timeout(Duration::from_secs(10), answer)
                .await
                .expect("answered after the cancellation")
                .unwrap()
                .unwrap();
        }
        assert_eq!(stored(&db).await, vec![1, 3]);
    }

    /// The request that opens a group runs without a savepoint; cancelled
    /// mid-way, its writes are rolled back whole before the next request
    /// runs, and that one is committed alone. Meanwhile reads go on.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_cancelled_first_request_of_a_group_leaves_nothing() {
        let (_dir, db) = database().await;
        let (opener, entered) = write_and_hang(&db, 1);
        entered.await.unwrap();
        // Reads never wait on the writer: while a request holds it with
        // its write uncommitted, a read answers, without that write.
        let read = tokio::time::timeout(Duration::from_secs(1), stored(&db)).await;
        assert_eq!(
            read.expect("a read while the writer is held"),
            Vec::<i64>::new()
        );
        opener.abort();
        assert!(opener.await.unwrap_err().is_cancelled());
        tokio::time::timeout(
            Duration::from_secs(10),
            db.group.run(async |conn| insert(conn, 2).await),
        )
        .await
        .expect("answered")
        .unwrap();
        assert_eq!(stored(&db).await, vec![2]);
    }
}
