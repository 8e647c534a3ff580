//! The `libraries` table.

use crate::db::sql;
use crate::store::error::StoreError;
use crate::store::states::{
    CAMPAIGN_FAILED, CAMPAIGN_PENDING, CAMPAIGN_RUNNING, LIBRARY_BUILDING, LIBRARY_FAILED,
    LIBRARY_READY,
};
use const_format::formatcp;
use rusqlite::{params, Connection};
use tslg_api::LibraryStatus;

#[derive(Debug, Clone, serde::Deserialize)]
pub struct LibraryRow {
    pub id: i64,
    pub case_name: String,
    pub preset: String,
    pub status: LibraryStatus,
    pub request: String,
    pub surrogate: String,
    pub exposure_name: String,
    pub exposure_fingerprint: String,
    pub exposure_table: Option<String>,
    pub exposure_note: Option<String>,
    pub total_scenarios: i64,
    pub size: Option<i64>,
    pub sm_evaluations: Option<i64>,
    pub mu_s: Option<f64>,
    pub w: Option<f64>,
    pub build_seconds: Option<f64>,
    pub error: Option<String>,
    pub created_at: String,
}

const COLUMNS: &str = "id, case_name, preset, status, request, surrogate, exposure_name, \
    exposure_fingerprint, exposure_table, exposure_note, total_scenarios, size, sm_evaluations, \
    mu_s, w, build_seconds, error, created_at";

impl LibraryRow {
    pub fn exposure_source(&self) -> tslg_method::registry::ExposureSource {
        tslg_client::wire::stored_exposure(&self.exposure_name, self.exposure_table.as_ref())
    }
}

/// What a new library row records.
pub struct NewLibrary<'a> {
    pub case_name: &'a str,
    pub preset: &'a str,
    pub request: &'a str,
    pub surrogate: &'a str,
    pub exposure_name: &'a str,
    pub exposure_fingerprint: &'a str,
    pub exposure_table: Option<&'a str>,
    pub exposure_note: Option<&'a str>,
    pub total_scenarios: usize,
}

pub fn insert(conn: &Connection, new: &NewLibrary<'_>) -> Result<LibraryRow, StoreError> {
    let sql = format!(
        "INSERT INTO libraries (case_name, preset, status, request, surrogate, exposure_name, \
         exposure_fingerprint, exposure_table, exposure_note, total_scenarios) \
         VALUES (?, ?, {LIBRARY_BUILDING}, ?, ?, ?, ?, ?, ?, ?) RETURNING {COLUMNS}"
    );
    Ok(sql::one(
        conn,
        &sql,
        params![
            new.case_name,
            new.preset,
            new.request,
            new.surrogate,
            new.exposure_name,
            new.exposure_fingerprint,
            new.exposure_table,
            new.exposure_note,
            new.total_scenarios as i64
        ],
    )?)
}

pub fn get(conn: &Connection, id: i64) -> Result<LibraryRow, StoreError> {
    sql::optional(
        conn,
        &format!("SELECT {COLUMNS} FROM libraries WHERE id = ?"),
        [id],
    )?
    .ok_or_else(|| StoreError::NotFound(format!("library {id} does not exist")))
}

/// Every library, or those in `status`, newest first.
pub fn list(
    conn: &Connection,
    status: Option<LibraryStatus>,
) -> Result<Vec<LibraryRow>, StoreError> {
    Ok(sql::all(
        conn,
        &format!(
            "SELECT {COLUMNS} FROM libraries WHERE ?1 IS NULL OR status = ?1 ORDER BY id DESC"
        ),
        [status.map(LibraryStatus::as_str)],
    )?)
}

pub fn building(conn: &Connection) -> Result<Vec<LibraryRow>, StoreError> {
    Ok(sql::all(
        conn,
        &format!("SELECT {COLUMNS} FROM libraries WHERE status = {LIBRARY_BUILDING} ORDER BY id"),
        [],
    )?)
}

/// A library file and its media type.
pub struct LibraryFile {
    pub bytes: Vec<u8>,
    pub media_type: String,
}

/// The library file, once ready.
pub fn file(conn: &Connection, id: i64) -> Result<Option<LibraryFile>, StoreError> {
    let row: Option<(Option<Vec<u8>>, Option<String>)> = sql::optional(
        conn,
        "SELECT file, media_type FROM libraries WHERE id = ?",
        [id],
    )?;
    Ok(match row {
        Some((Some(bytes), media_type)) => Some(LibraryFile {
            bytes,
            media_type: media_type.unwrap_or_else(|| "application/octet-stream".into()),
        }),
        _ => None,
    })
}

/// A ready library and its file; 404 if unknown, 409 if not ready (yet).
pub fn ready_file(conn: &Connection, id: i64) -> Result<(LibraryRow, LibraryFile), StoreError> {
    let row = get(conn, id)?;
    if row.status != LibraryStatus::Ready {
        return Err(StoreError::Conflict(format!(
            "library {id} is {}, not ready",
            row.status.as_str()
        )));
    }
    let file = file(conn, id)?.ok_or_else(|| {
        StoreError::Database(crate::db::DbError::new(format!(
            "ready library {id} has no file"
        )))
    })?;
    Ok((row, file))
}

/// A finished build: the library file and its summary.
pub struct Built<'a> {
    pub file: &'a [u8],
    pub media_type: &'a str,
    pub size: usize,
    pub sm_evaluations: usize,
    pub mu_s: f64,
    pub w: f64,
    pub seconds: f64,
}

impl<'a> Built<'a> {
    /// A build's result, `seconds` long.
    pub fn of(library: &'a tslg_method::registry::BuiltLibrary, seconds: f64) -> Self {
        Self {
            file: &library.file,
            media_type: library.media_type,
            size: library.size,
            sm_evaluations: library.sm_evaluations,
            mu_s: library.mu_s,
            w: library.w,
            seconds,
        }
    }
}

/// Marks a library ready and lets its pending campaigns run (a write).
pub fn mark_ready(conn: &Connection, id: i64, built: &Built<'_>) -> Result<(), StoreError> {
    sql::execute(
        conn,
        formatcp!(
            "UPDATE libraries SET status = {LIBRARY_READY}, file = ?, media_type = ?, size = ?, \
         sm_evaluations = ?, mu_s = ?, w = ?, build_seconds = ? WHERE id = ?"
        ),
        params![
            built.file,
            built.media_type,
            built.size as i64,
            built.sm_evaluations as i64,
            built.mu_s,
            built.w,
            built.seconds,
            id
        ],
    )?;
    sql::execute(
        conn,
        formatcp!(
            "UPDATE campaigns SET status = {CAMPAIGN_RUNNING}, \
         updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now') \
         WHERE library_id = ? AND status = {CAMPAIGN_PENDING}"
        ),
        [id],
    )?;
    Ok(())
}

/// Marks a library failed, and its pending campaigns with it (a write).
pub fn mark_failed(conn: &Connection, id: i64, error: &str) -> Result<(), StoreError> {
    sql::execute(
        conn,
        formatcp!("UPDATE libraries SET status = {LIBRARY_FAILED}, error = ? WHERE id = ?"),
        params![error, id],
    )?;
    sql::execute(
        conn,
        formatcp!(
            "UPDATE campaigns SET status = {CAMPAIGN_FAILED}, status_detail = ?, \
         updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now') \
         WHERE library_id = ? AND status = {CAMPAIGN_PENDING}"
        ),
        params![format!("library {id} failed to build: {error}"), id],
    )?;
    Ok(())
}
