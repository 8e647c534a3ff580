//! The `libraries` table.

use crate::error::ApiError;
use sqlx::SqlitePool;
use tslg_api::{LibraryStatus, LibraryView};

#[derive(Debug, Clone, sqlx::FromRow)]
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

    pub fn view(&self) -> LibraryView {
        LibraryView {
            id: self.id,
            case: self.case_name.clone(),
            preset: self.preset.clone(),
            status: self.status,
            exposure: self.exposure_name.clone(),
            exposure_fingerprint: self.exposure_fingerprint.clone(),
            exposure_note: self.exposure_note.clone(),
            surrogate: serde_json::from_str(&self.surrogate).unwrap_or_default(),
            size: self.size.map(|v| v as u64),
            total_scenarios: self.total_scenarios as u64,
            sm_evaluations: self.sm_evaluations.map(|v| v as u64),
            mu_s: self.mu_s,
            w: self.w,
            build_seconds: self.build_seconds,
            error: self.error.clone(),
            status_detail: None,
            progress: None,
            created_at: self.created_at.clone(),
        }
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

pub async fn insert(pool: &SqlitePool, new: &NewLibrary<'_>) -> Result<LibraryRow, ApiError> {
    let sql = format!(
        "INSERT INTO libraries (case_name, preset, status, request, surrogate, exposure_name, \
         exposure_fingerprint, exposure_table, exposure_note, total_scenarios) \
         VALUES (?, ?, 'building', ?, ?, ?, ?, ?, ?, ?) RETURNING {COLUMNS}"
    );
    Ok(sqlx::query_as(&sql)
        .bind(new.case_name)
        .bind(new.preset)
        .bind(new.request)
        .bind(new.surrogate)
        .bind(new.exposure_name)
        .bind(new.exposure_fingerprint)
        .bind(new.exposure_table)
        .bind(new.exposure_note)
        .bind(new.total_scenarios as i64)
        .fetch_one(pool)
        .await?)
}

pub async fn get<'e, E>(executor: E, id: i64) -> Result<LibraryRow, ApiError>
where
    E: sqlx::Executor<'e, Database = sqlx::Sqlite>,
{
    let sql = format!("SELECT {COLUMNS} FROM libraries WHERE id = ?");
    sqlx::query_as(&sql)
        .bind(id)
        .fetch_optional(executor)
        .await?
        .ok_or_else(|| ApiError::NotFound(format!("library {id} does not exist")))
}

pub async fn list(pool: &SqlitePool) -> Result<Vec<LibraryRow>, ApiError> {
    let sql = format!("SELECT {COLUMNS} FROM libraries ORDER BY id DESC");
    Ok(sqlx::query_as(&sql).fetch_all(pool).await?)
}

pub async fn building(pool: &SqlitePool) -> Result<Vec<LibraryRow>, ApiError> {
    let sql = format!("SELECT {COLUMNS} FROM libraries WHERE status = 'building' ORDER BY id");
    Ok(sqlx::query_as(&sql).fetch_all(pool).await?)
}

/// A library file and its media type.
pub struct LibraryFile {
    pub bytes: Vec<u8>,
    pub media_type: String,
}

/// The library file, once ready.
pub async fn file(pool: &SqlitePool, id: i64) -> Result<Option<LibraryFile>, ApiError> {
    let row: Option<(Option<Vec<u8>>, Option<String>)> =
        sqlx::query_as("SELECT file, media_type FROM libraries WHERE id = ?")
            .bind(id)
            .fetch_optional(pool)
            .await?;
    Ok(match row {
        Some((Some(bytes), media_type)) => Some(LibraryFile {
            bytes,
            media_type: media_type.unwrap_or_else(|| "application/octet-stream".into()),
        }),
        _ => None,
    })
}

/// A ready library and its file; 404 if unknown, 409 if not ready (yet).
pub async fn ready_file(pool: &SqlitePool, id: i64) -> Result<(LibraryRow, LibraryFile), ApiError> {
    let row = get(pool, id).await?;
    if row.status != LibraryStatus::Ready {
        return Err(ApiError::Conflict(format!(
            "library {id} is {}, not ready",
            row.status.as_str()
        )));
    }
    let file = file(pool, id)
        .await?
        .ok_or_else(|| ApiError::Internal(anyhow::anyhow!("ready library {id} has no file")))?;
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

/// Marks a library ready and lets its pending campaigns run.
pub async fn mark_ready(pool: &SqlitePool, id: i64, built: &Built<'_>) -> Result<(), ApiError> {
    let mut tx = pool.begin().await?;
    mark_ready_in(&mut tx, id, built).await?;
    tx.commit().await?;
    Ok(())
}

/// [`mark_ready`] inside the caller's transaction.
pub async fn mark_ready_in(
    tx: &mut sqlx::SqliteConnection,
    id: i64,
    built: &Built<'_>,
) -> Result<(), ApiError> {
    sqlx::query(
        "UPDATE libraries SET status = 'ready', file = ?, media_type = ?, size = ?, \
         sm_evaluations = ?, mu_s = ?, w = ?, build_seconds = ? WHERE id = ?",
    )
    .bind(built.file)
    .bind(built.media_type)
    .bind(built.size as i64)
    .bind(built.sm_evaluations as i64)
    .bind(built.mu_s)
    .bind(built.w)
    .bind(built.seconds)
    .bind(id)
    .execute(&mut *tx)
    .await?;
    sqlx::query(
        "UPDATE campaigns SET status = 'running', \
         updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now') \
         WHERE library_id = ? AND status = 'pending'",
    )
    .bind(id)
    .execute(&mut *tx)
    .await?;
    Ok(())
}

/// Marks a library failed, and its pending campaigns with it.
pub async fn mark_failed(pool: &SqlitePool, id: i64, error: &str) -> Result<(), ApiError> {
    let mut tx = pool.begin().await?;
    mark_failed_in(&mut tx, id, error).await?;
    tx.commit().await?;
    Ok(())
}

/// [`mark_failed`] inside the caller's transaction.
pub async fn mark_failed_in(
    tx: &mut sqlx::SqliteConnection,
    id: i64,
    error: &str,
) -> Result<(), ApiError> {
    sqlx::query("UPDATE libraries SET status = 'failed', error = ? WHERE id = ?")
        .bind(error)
        .bind(id)
        .execute(&mut *tx)
        .await?;
    sqlx::query(
        "UPDATE campaigns SET status = 'failed', status_detail = ?, \
         updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now') \
         WHERE library_id = ? AND status = 'pending'",
    )
    .bind(format!("library {id} failed to build: {error}"))
    .bind(id)
    .execute(&mut *tx)
    .await?;
    Ok(())
}
