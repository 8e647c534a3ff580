//! The SQLite database: one writer, a pool of readers, the migrations.
//!
//! All writes go through one connection owned by one thread
//! ([`writer::Writer`]), which commits concurrent requests together, so
//! SQLite's single writer never sees two of ours at once and "database is
//! locked" cannot arise between them; reads use separate read-only
//! connections ([`readers::Readers`]) and, in WAL mode, never block the
//! writer or each other. Both run synchronous closures over
//! [`rusqlite::Connection`]s: a request's writes are one hand-over to the
//! writer thread, not one per statement. The migrations in `migrations/`
//! are applied at start-up by sqlx's migrator (its `_sqlx_migrations`
//! table records them, as it always has).

mod error;
mod readers;
pub mod sql;
#[cfg(test)]
mod tests;
mod writer;

use anyhow::Context;
pub use error::DbError;
use readers::Readers;
use rusqlite::{Connection, OpenFlags};
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions, SqliteSynchronous};
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::Arc;
use std::time::Duration;
use writer::Writer;

/// How long a connection waits for a lock another process holds (a
/// backup, an operator's shell) before it gives up.
const BUSY_TIMEOUT: Duration = Duration::from_secs(10);

/// Read connections open at once.
const READERS: usize = 4;

/// Prepared statements each connection keeps.
const STATEMENT_CACHE: usize = 256;

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
    writer: Arc<Writer>,
    readers: Arc<Readers>,
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
            .synchronous(SqliteSynchronous::Full)
            .foreign_keys(true)
            .busy_timeout(BUSY_TIMEOUT);
        let path = file_of(&options, url)?;
        let migrator = SqlitePoolOptions::new()
            .max_connections(1)
            .connect_with(options)
            .await
            .with_context(|| format!("cannot open the database {url}"))?;
        sqlx::migrate!("../migrations")
            .run(&migrator)
            .await
            .context("cannot apply the database migrations")?;
        migrator.close().await;
        let conn = open_writer(&path, durability)
            .with_context(|| format!("cannot open the database {url} for writing"))?;
        let writer = Writer::start(conn).context("cannot start the database writer")?;
        let readers = Readers::new(READERS, Box::new(move || open_reader(&path)));
        Ok(Self {
            writer: Arc::new(writer),
            readers: Arc::new(readers),
        })
    }

    /// Runs `work` on the write connection, in the savepoint of a
    /// transaction that concurrent writes share, and answers once it is
    /// committed ([`writer::Writer::run`]).
    pub async fn write<T, E, F>(&self, work: F) -> Result<T, E>
    where
        T: Send + 'static,
        E: From<DbError> + Send + 'static,
        F: FnOnce(&Connection) -> Result<T, E> + Send + 'static,
    {
        self.writer.run(work).await
    }

    /// Runs `work` on a read-only connection, off the async runtime.
    pub async fn read<T, E, F>(&self, work: F) -> Result<T, E>
    where
        T: Send + 'static,
        E: From<DbError> + Send + 'static,
        F: FnOnce(&Connection) -> Result<T, E> + Send + 'static,
    {
        self.readers.run(work).await
    }

    /// Write transactions committed so far, and the writes they carried.
    pub fn group_counts(&self) -> (u64, u64) {
        self.writer.counts()
    }
}

/// The file behind `options`; an in-memory database is refused: its
/// readers would each see a database of their own.
fn file_of(options: &SqliteConnectOptions, url: &str) -> anyhow::Result<PathBuf> {
    let path = options.get_filename();
    let name = path.to_string_lossy();
    anyhow::ensure!(
        !(name == ":memory:" || name.starts_with("file:sqlx-in-memory")),
        "the database URL {url} names an in-memory database; the coordinator needs a file \
         (e.g. sqlite://tslg.sqlite)"
    );
    Ok(path.to_path_buf())
}

/// Settings every connection shares. Temporary storage in memory: the
/// writer's savepoints keep the pages they change in a statement journal,
/// and sorting and `RETURNING` use scratch tables, which would otherwise
/// be files.
fn configure(conn: &Connection) -> rusqlite::Result<()> {
    conn.busy_timeout(BUSY_TIMEOUT)?;
    conn.set_prepared_statement_cache_capacity(STATEMENT_CACHE);
    conn.execute_batch("PRAGMA temp_store = MEMORY;")
}

fn open_writer(path: &Path, durability: Durability) -> rusqlite::Result<Connection> {
    let conn = Connection::open(path)?;
    configure(&conn)?;
    let synchronous = match durability {
        Durability::Full => "FULL",
        Durability::Normal => "NORMAL",
    };
    conn.execute_batch(&format!(
        "PRAGMA journal_mode = WAL; PRAGMA synchronous = {synchronous}; PRAGMA foreign_keys = ON;"
    ))?;
    Ok(conn)
}

fn open_reader(path: &Path) -> rusqlite::Result<Connection> {
    let conn = Connection::open_with_flags(
        path,
        OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )?;
    configure(&conn)?;
    Ok(conn)
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
