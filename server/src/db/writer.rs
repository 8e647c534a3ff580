//! The single writer: one thread owns the only write connection and
//! commits concurrent requests together (group commit).
//!
//! With `durability` full every commit fsyncs the write-ahead log, so a
//! coordinator that committed once per lease and once per report would be
//! bound by the disk's fsync rate, and one whose every statement crossed
//! threads (an async driver runs each statement on the connection's own
//! thread and wakes the caller after it) by thread switches. Here a request
//! hands its whole write, a synchronous closure, to the writer thread. The
//! thread takes the first waiting job, opens a transaction
//! (`BEGIN IMMEDIATE`), runs it in a savepoint, then every job that queued
//! meanwhile, each in its own savepoint, and commits them all at once;
//! only then does each request get its answer. So a result is still
//! acknowledged only once it is on disk, a request's failure rolls back its
//! own savepoint only, and no two writers ever meet ("database is locked"
//! cannot arise between ours).
//!
//! A group is cut at [`MAX_GROUP_TIME`], so a steady stream of requests
//! cannot hold back the first one's answer, and at a number of jobs that
//! follows the commit's cost ([`GroupCap`]): about as many jobs as the
//! commit takes time, so that a group that fills to its cap spends about as
//! long on its jobs as on its commit, while the answers leave in groups
//! small enough that the request threads send one group's answers and take
//! in new requests while the writer runs the next (docs/benchmarks.md,
//! "Coordinator under load").
//!
//! Cancellation: a request whose client goes away stops waiting, but its
//! job, once queued, still runs and commits whole (a lease then expires
//! unused; a report's worker sends it again and it is a duplicate). Nothing
//! is half-written either way.

use super::error::DbError;
use rusqlite::Connection;
use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::oneshot;

/// The most jobs one transaction carries.
const MAX_GROUP: usize = 256;

/// The fewest jobs a group is cut at: below it the commits' own work
/// (their statements and the log's sync) grew faster than the overlap
/// gained (measured with 8).
const MIN_GROUP_CAP: usize = 16;

/// The longest a group keeps taking jobs after its first started.
const MAX_GROUP_TIME: Duration = Duration::from_millis(20);

/// A write waiting for the writer thread.
trait Job: Send {
    /// Runs the write on `conn`, inside the job's savepoint; whether it
    /// succeeded (a failed job's savepoint is rolled back).
    fn run(&mut self, conn: &Connection) -> bool;
    /// The job failed around its write (its savepoint could not be set).
    fn fail(&mut self, error: DbError);
    /// Answers the requester once the group's commit is known.
    fn answer(self: Box<Self>, commit: &Result<(), Arc<str>>);
}

/// A job and where its answer goes.
struct Pending<T, E, F> {
    work: Option<F>,
    outcome: Option<Result<T, E>>,
    reply: oneshot::Sender<Result<T, E>>,
}

impl<T, E, F> Job for Pending<T, E, F>
where
    T: Send,
    E: From<DbError> + Send,
    F: FnOnce(&Connection) -> Result<T, E> + Send,
{
    fn run(&mut self, conn: &Connection) -> bool {
        let Some(work) = self.work.take() else {
            return false;
        };
        // A panicking write is a failed request, not a dead writer.
        let outcome = std::panic::catch_unwind(AssertUnwindSafe(|| work(conn)))
            .unwrap_or_else(|panic| Err(panicked("a write", &*panic).into()));
        let ok = outcome.is_ok();
        self.outcome = Some(outcome);
        ok
    }

    fn fail(&mut self, error: DbError) {
        self.work = None;
        self.outcome = Some(Err(error.into()));
    }

    fn answer(self: Box<Self>, commit: &Result<(), Arc<str>>) {
        let outcome = match (self.outcome, commit) {
            (Some(Ok(value)), Ok(())) => Ok(value),
            (Some(Ok(_)), Err(reason)) => {
                Err(DbError::new(format!("the group commit failed: {reason}")).into())
            }
            (Some(Err(e)), _) => Err(e),
            (None, _) => Err(DbError::new("a write was answered without running").into()),
        };
        // A request whose client went away no longer listens.
        let _ = self.reply.send(outcome);
    }
}

/// The failure of a panic in `what`, with its message.
pub(super) fn panicked(what: &str, panic: &(dyn std::any::Any + Send)) -> DbError {
    let message = panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "no message".into());
    DbError::new(format!("{what} panicked: {message}"))
}

/// Groups committed and the jobs they carried (for `/metrics`: their ratio
/// is the mean group size).
#[derive(Default)]
struct Counters {
    groups: AtomicU64,
    grouped: AtomicU64,
}

/// The handle requests hand their writes to.
pub struct Writer {
    jobs: mpsc::Sender<Box<dyn Job>>,
    counters: Arc<Counters>,
}

impl Writer {
    /// Starts the writer thread on `conn`; it ends when the last handle is
    /// dropped, after the jobs already queued.
    pub fn start(conn: Connection) -> std::io::Result<Self> {
        let (jobs, queue) = mpsc::channel();
        let counters = Arc::new(Counters::default());
        let counted = Arc::clone(&counters);
        std::thread::Builder::new()
            .name("tslg-writer".into())
            .spawn(move || serve(&conn, &queue, &counted))?;
        Ok(Self { jobs, counters })
    }

    /// Runs `work` on the write connection in a savepoint of the group's
    /// transaction, and answers once the group is committed: the work's
    /// value when both succeeded, the work's error (its writes rolled
    /// back, the others' kept) or the commit's.
    pub async fn run<T, E, F>(&self, work: F) -> Result<T, E>
    where
        T: Send + 'static,
        E: From<DbError> + Send + 'static,
        F: FnOnce(&Connection) -> Result<T, E> + Send + 'static,
    {
        let (reply, answer) = oneshot::channel();
        let job = Box::new(Pending {
            work: Some(work),
            outcome: None,
            reply,
        });
        self.jobs
            .send(job)
            .map_err(|_| DbError::new("the database writer has stopped"))?;
        answer
            .await
            .map_err(|_| DbError::new("the database writer stopped before answering"))?
    }

    /// Groups committed so far, and the jobs they answered.
    pub fn counts(&self) -> (u64, u64) {
        (
            self.counters.groups.load(Ordering::Relaxed),
            self.counters.grouped.load(Ordering::Relaxed),
        )
    }
}

/// How many jobs a group takes: the commit's time over a job's, both
/// smoothed over the groups so far (exponential averages, weight 0.2),
/// within [`MIN_GROUP_CAP`, `MAX_GROUP`]. On a disk whose sync is quick
/// the commit costs a few jobs and groups stay at the floor; on a slow one
/// (a sync of several milliseconds) groups grow so that each sync is
/// shared by about as many jobs as it takes time for.
#[derive(Debug, Clone, Copy, Default)]
struct GroupCap {
    /// Seconds of one job, and of one commit.
    job: Option<f64>,
    commit: Option<f64>,
}

impl GroupCap {
    const WEIGHT: f64 = 0.2;

    fn smooth(previous: Option<f64>, sample: f64) -> Option<f64> {
        Some(match previous {
            Some(p) => p + Self::WEIGHT * (sample - p),
            None => sample,
        })
    }

    /// A group of `jobs` that ran for `work` and committed in `commit`.
    fn record(&mut self, jobs: usize, work: Duration, commit: Duration) {
        if jobs > 0 {
            self.job = Self::smooth(self.job, work.as_secs_f64() / jobs as f64);
        }
        self.commit = Self::smooth(self.commit, commit.as_secs_f64());
    }

    /// The jobs the next group takes at most.
    fn jobs(&self) -> usize {
        let (Some(job), Some(commit)) = (self.job, self.commit) else {
            return MIN_GROUP_CAP;
        };
        // A job measured as taking no time gives ∞: the most.
        let jobs = commit / job;
        if jobs.is_nan() {
            return MIN_GROUP_CAP;
        }
        jobs.ceil().clamp(MIN_GROUP_CAP as f64, MAX_GROUP as f64) as usize
    }
}

/// The writer thread: a group per transaction until every handle is gone.
fn serve(conn: &Connection, queue: &mpsc::Receiver<Box<dyn Job>>, counters: &Counters) {
    let mut cap = GroupCap::default();
    while let Ok(first) = queue.recv() {
        let started = Instant::now();
        let most = cap.jobs();
        let begun = run_statement(conn, "BEGIN IMMEDIATE");
        let mut group: Vec<Box<dyn Job>> = Vec::new();
        let mut next = Some(first);
        while let Some(mut job) = next {
            match &begun {
                Ok(()) => run_in_savepoint(conn, job.as_mut()),
                Err(e) => job.fail(DbError::new(format!(
                    "cannot begin a write transaction: {e}"
                ))),
            }
            group.push(job);
            next = if group.len() < most && started.elapsed() < MAX_GROUP_TIME {
                queue.try_recv().ok()
            } else {
                None
            };
        }
        let committing = Instant::now();
        let commit: Result<(), Arc<str>> = match &begun {
            Ok(()) => run_statement(conn, "COMMIT").map_err(|e| {
                tracing::error!(error = %e, requests = group.len(), "a group commit failed");
                let _ = run_statement(conn, "ROLLBACK");
                Arc::from(e.to_string())
            }),
            Err(e) => Err(Arc::from(e.to_string())),
        };
        // Only a group that began and committed measures the two costs.
        if begun.is_ok() && commit.is_ok() {
            cap.record(group.len(), committing - started, committing.elapsed());
        }
        if commit.is_ok() {
            counters.groups.fetch_add(1, Ordering::Relaxed);
            counters
                .grouped
                .fetch_add(group.len() as u64, Ordering::Relaxed);
        }
        for job in group {
            job.answer(&commit);
        }
    }
}

/// Runs one of the writer's own statements, prepared once.
fn run_statement(conn: &Connection, sql: &str) -> rusqlite::Result<()> {
    conn.prepare_cached(sql)?.execute([])?;
    Ok(())
}

/// Runs `job` in a savepoint of the open transaction: released when it
/// succeeds, rolled back (and released) when it fails.
fn run_in_savepoint(conn: &Connection, job: &mut dyn Job) {
    if let Err(e) = run_statement(conn, "SAVEPOINT job") {
        job.fail(DbError::new(format!("cannot open a savepoint: {e}")));
        return;
    }
    let ended = if job.run(conn) {
        run_statement(conn, "RELEASE job")
    } else {
        run_statement(conn, "ROLLBACK TO job").and_then(|()| run_statement(conn, "RELEASE job"))
    };
    if let Err(e) = ended {
        job.fail(DbError::new(format!("cannot close a savepoint: {e}")));
    }
}

#[cfg(test)]
mod tests {
    /// A group takes about as many jobs as its commit takes time, within
    /// its bounds: a quick sync keeps groups at the floor, a slow one lets
    /// them grow, a start with nothing measured takes the floor, and
    /// nonsense (a job measured as taking no time) the most.
    #[test]
    fn groups_grow_with_the_commit_s_cost() {
        use super::{GroupCap, MAX_GROUP, MIN_GROUP_CAP};
        use std::time::Duration;
        let ms = Duration::from_secs_f64;
        assert_eq!(GroupCap::default().jobs(), MIN_GROUP_CAP);
        let mut quick = GroupCap::default();
        quick.record(30, ms(0.003), ms(0.000_5));
        assert_eq!(quick.jobs(), MIN_GROUP_CAP);
        // Jobs of 100 µs, a sync of 4 ms: 40 jobs.
        let mut slow = GroupCap::default();
        slow.record(30, ms(0.003), ms(0.004));
        assert_eq!(slow.jobs(), 40);
        // Smoothed: one group with a sync of 14 ms moves the commit's
        // estimate a fifth of the way, 4 → 6 ms: 60 jobs.
        slow.record(30, ms(0.003), ms(0.014));
        assert_eq!(slow.jobs(), 60);
        let mut stalled = GroupCap::default();
        stalled.record(10, ms(0.001), ms(1.0));
        assert_eq!(stalled.jobs(), MAX_GROUP);
        let mut instant = GroupCap::default();
        instant.record(10, Duration::ZERO, ms(0.001));
        assert_eq!(instant.jobs(), MAX_GROUP);
        instant.record(0, Duration::ZERO, ms(0.001));
        assert_eq!(instant.jobs(), MAX_GROUP);
    }
}
