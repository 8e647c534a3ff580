//! The SQLite database: connection pools and migrations.
//!
//! All writes go through one connection (`write`), so SQLite's single
//! writer never sees two of ours at once and "database is locked" cannot
//! arise between them; reads use a separate pool and, in WAL mode, never
//! block the writer or each other.

use crate::group_commit::GroupCommit;
use anyhow::Context;
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions, SqliteSynchronous};
use sqlx::SqlitePool;
use std::str::FromStr;
use std::sync::Arc;
use std::time::Duration;

/// How hard each commit is pushed to disk (SQLite's `synchronous` in WAL
/// mode).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Durability {
    /// fsync the write-ahead log at every commit: an acknowledged result
    /// survives a power failure.
    Full,
    /// fsync only at checkpoints: an acknowledged result survives a crash
    /// of the coordinator, not of the machine.
    Normal,
}

#[derive(Clone)]
pub struct Database {
    /// The single write connection, for writes off the hot paths.
    pub write: SqlitePool,
    /// Leases and reports: their writes share transactions and fsyncs
    /// ([`GroupCommit`]), on the same connection.
    pub group: Arc<GroupCommit>,
    pub read: SqlitePool,
}

impl Database {
    /// Opens (creating when missing) the database at `url` and applies the
    /// migrations in `migrations/`. With `durability` full, every commit
    /// (and so every acknowledged result) is on stable storage before the
    /// answer leaves; with normal, commits survive a crash of the process
    /// but the last ones can be lost to a power failure or a kernel crash.
    pub async fn open(url: &str, durability: Durability) -> anyhow::Result<Self> {
        let options = SqliteConnectOptions::from_str(url)
            .with_context(|| format!("invalid database URL {url}"))?
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(match durability {
                Durability::Full => SqliteSynchronous::Full,
                Durability::Normal => SqliteSynchronous::Normal,
            })
            .foreign_keys(true)
            .busy_timeout(Duration::from_secs(10));
        let write = SqlitePoolOptions::new()
            .max_connections(1)
            .connect_with(options.clone())
            .await
            .with_context(|| format!("cannot open the database {url}"))?;
        sqlx::migrate!("../migrations")
            .run(&write)
            .await
            .context("cannot apply the database migrations")?;
        let read = SqlitePoolOptions::new()
            .max_connections(4)
            .connect_with(options.read_only(true))
            .await
            .with_context(|| format!("cannot open the database {url} for reading"))?;
        let group = GroupCommit::start(write.clone());
        Ok(Self { write, group, read })
    }
}

/// Unix time in milliseconds.
pub fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

/// Copies the database at `url` to a new file `out` while coordinators may
/// be using it: SQLite's `VACUUM INTO` reads one consistent snapshot (a
/// read transaction, which in WAL mode never blocks the writer) and writes
/// it compacted, including what is still only in the write-ahead log. A
/// plain file copy of a live WAL database can miss committed transactions
/// or tear. Refuses to overwrite `out`.
pub async fn backup(url: &str, out: &std::path::Path) -> anyhow::Result<u64> {
    anyhow::ensure!(
        !out.exists(),
        "{} exists; a backup never overwrites a file",
        out.display()
    );
    let target = out
        .to_str()
        .with_context(|| format!("{} is not a UTF-8 path", out.display()))?;
    let options = SqliteConnectOptions::from_str(url)
        .with_context(|| format!("invalid database URL {url}"))?
        .create_if_missing(false)
        .busy_timeout(Duration::from_secs(30));
    let pool = SqlitePoolOptions::new()
        .max_connections(1)
        .connect_with(options)
        .await
        .with_context(|| format!("cannot open the database {url}"))?;
    sqlx::query("VACUUM INTO ?")
        .bind(target)
        .execute(&pool)
        .await
        .with_context(|| format!("cannot write the backup {}", out.display()))?;
    pool.close().await;
    Ok(std::fs::metadata(out)?.len())
}
