//! The writer and the readers together on a scratch database: group
//! commits, a failed or abandoned write, and reads beside an open write.

use super::{sql, Database, DbError, Durability};
use std::future::Future;
use std::sync::mpsc;
use std::time::Duration;

async fn database() -> (tempfile::TempDir, Database) {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/db.sqlite", dir.path().display());
    let db = Database::open(&url, Durability::Full).await.unwrap();
    db.write(|conn| sql::execute(conn, "CREATE TABLE rows (n INTEGER PRIMARY KEY)", []))
        .await
        .unwrap();
    (dir, db)
}

fn insert(conn: &rusqlite::Connection, n: i64) -> Result<(), DbError> {
    sql::execute(conn, "INSERT INTO rows (n) VALUES (?)", [n])?;
    Ok(())
}

async fn stored(db: &Database) -> Vec<i64> {
    let rows: Vec<(i64,)> = db
        .read(|conn| sql::all(conn, "SELECT n FROM rows ORDER BY n", []))
        .await
        .unwrap();
    rows.into_iter().map(|(n,)| n).collect()
}

/// Holds the writer thread inside a job that wrote row `n` until
/// `release` is sent; `entered` says it is inside.
fn write_and_wait(
    db: &Database,
    n: i64,
) -> (
    tokio::task::JoinHandle<Result<(), DbError>>,
    tokio::sync::oneshot::Receiver<()>,
    mpsc::Sender<()>,
) {
    let (inside, entered) = tokio::sync::oneshot::channel::<()>();
    let (release, released) = mpsc::channel::<()>();
    let db = db.clone();
    let task = tokio::spawn(async move {
        db.write(move |conn| {
            insert(conn, n)?;
            inside.send(()).unwrap();
            released.recv().unwrap();
            Ok(())
        })
        .await
    });
    (task, entered, release)
}

/// Forty concurrent writes, every third failing after its insert, and
/// one panicking: the others' rows are all stored, the failed ones'
/// none, each success is readable from another connection the moment
/// it is answered, and they shared fewer commits than there were
/// writes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_failed_write_rolls_back_only_its_own_rows() {
    let (_dir, db) = database().await;
    let (groups_before, grouped_before) = db.group_counts();
    // Held, so the writes below queue and share transactions.
    let (held, entered, release) = write_and_wait(&db, 1000);
    entered.await.unwrap();
    // Each write is queued by its first poll, here, in order; then it runs
    // on its own task. (A sleep standing in for "all queued" could end
    // too soon on a loaded host.)
    let mut cx = std::task::Context::from_waker(std::task::Waker::noop());
    let tasks: Vec<_> = (0..40)
        .map(|n| {
            let db = db.clone();
            let mut write = Box::pin(async move {
                let answer = db
                    .write(move |conn| {
                        insert(conn, n)?;
                        if n == 20 {
                            panic!("write {n} panics");
                        }
                        if n % 3 == 0 {
                            return Err(DbError::new(format!("write {n} fails")));
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
            });
            assert!(
                write.as_mut().poll(&mut cx).is_pending(),
                "write {n} queued"
            );
            tokio::spawn(write)
        })
        .collect();
    release.send(()).unwrap();
    held.await.unwrap().unwrap();
    let mut succeeded = Vec::new();
    for (n, task) in tasks.into_iter().enumerate() {
        match task.await.unwrap() {
            Ok(value) => succeeded.push(value),
            Err(e) if n == 20 => {
                assert!(e.to_string().contains("write 20 panics"), "{e}")
            }
            Err(e) => {
                assert_eq!(n % 3, 0);
                assert_eq!(e.to_string(), format!("write {n} fails"));
            }
        }
    }
    let expected: Vec<i64> = (0..40).filter(|n| n % 3 != 0 && *n != 20).collect();
    assert_eq!(succeeded, expected);
    let mut all = expected.clone();
    all.push(1000);
    assert_eq!(stored(&db).await, all);
    let (groups, grouped) = db.group_counts();
    let (groups, grouped) = (groups - groups_before, grouped - grouped_before);
    assert_eq!(grouped, 41, "every write was answered after a commit");
    assert!(groups < 10, "{groups} commits for {grouped} writes");
}

/// A write whose requester stops waiting (its client went away) still
/// runs and commits whole, and the writes queued behind it too.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_write_whose_requester_left_commits_whole() {
    let (_dir, db) = database().await;
    let (held, entered, release) = write_and_wait(&db, 1);
    entered.await.unwrap();
    // A write's first poll queues it (the writer's channel takes the job
    // at once); polled once and dropped, it is a request whose client
    // went away after asking. No sleep: the order is the polls'.
    let mut cx = std::task::Context::from_waker(std::task::Waker::noop());
    let mut gone = Box::pin(db.write(|conn| {
        insert(conn, 2)?;
        insert(conn, 3)
    }));
    assert!(gone.as_mut().poll(&mut cx).is_pending(), "queued, held");
    drop(gone);
    let mut behind = Box::pin(db.write(|conn| insert(conn, 4)));
    assert!(behind.as_mut().poll(&mut cx).is_pending(), "queued, held");
    release.send(()).unwrap();
    held.await.unwrap().unwrap();
    behind.await.unwrap();
    assert_eq!(stored(&db).await, vec![1, 2, 3, 4]);
}

/// Reads never wait on the writer: while a write holds it with its
/// rows uncommitted, a read answers, without them.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn reads_answer_while_a_write_is_uncommitted() {
    let (_dir, db) = database().await;
    db.write(|conn| insert(conn, 1)).await.unwrap();
    let (held, entered, release) = write_and_wait(&db, 2);
    entered.await.unwrap();
    let read = tokio::time::timeout(Duration::from_secs(2), stored(&db)).await;
    assert_eq!(read.expect("a read while the writer is held"), vec![1]);
    release.send(()).unwrap();
    held.await.unwrap().unwrap();
    assert_eq!(stored(&db).await, vec![1, 2]);
}
