//! Deleting what a user no longer wants: a stopped campaign with everything
//! recorded for it, and a library no campaign uses (with the campaign that
//! built it on workers, if any). Running work is never deleted: a running
//! campaign is cancelled first, a building library waits for its build.

use crate::error::ApiError;
use sqlx::{SqliteConnection, SqlitePool};
use tslg_api::LibraryStatus;

/// The tables holding a campaign's records, children before parents
/// (leases name audits).
const CAMPAIGN_TABLES: [&str; 6] = [
    "leases",
    "audits",
    "near_misses",
    "reports",
    "invalid_tests",
    "history",
];

async fn delete_campaign_rows(conn: &mut SqliteConnection, id: i64) -> Result<(), ApiError> {
    for table in CAMPAIGN_TABLES {
        sqlx::query(&format!("DELETE FROM {table} WHERE campaign_id = ?"))
            .bind(id)
            .execute(&mut *conn)
            .await?;
    }
    sqlx::query("DELETE FROM campaigns WHERE id = ?")
        .bind(id)
        .execute(&mut *conn)
        .await?;
    Ok(())
}

/// Deletes stopped campaign `id` and its records; 409 while it runs.
pub async fn delete_campaign(pool: &SqlitePool, id: i64) -> Result<(), ApiError> {
    let mut tx = pool.begin().await?;
    let row = crate::store::campaigns::get(&mut *tx, id).await?;
    if !row.status.is_final() {
        return Err(ApiError::Conflict(format!(
            "campaign {id} is {}: cancel it first (POST /api/v1/campaigns/{id}/cancel)",
            row.status.as_str()
        )));
    }
    if matches!(
        row.method,
        tslg_api::Method::Enumerate | tslg_api::Method::Build
    ) {
        if let Some(library) = row.library_id {
            return Err(ApiError::Conflict(format!(
                "campaign {id} built library {library}: it goes with the library \
                 (DELETE /api/v1/libraries/{library})"
            )));
        }
    }
    delete_campaign_rows(&mut tx, id).await?;
    tx.commit().await?;
    Ok(())
}

/// Deletes library `id` and its file, with the campaign that built it on
/// workers; 409 while it builds or while campaigns use it.
pub async fn delete_library(pool: &SqlitePool, id: i64) -> Result<(), ApiError> {
    let mut tx = pool.begin().await?;
    let library = crate::store::libraries::get(&mut *tx, id).await?;
    if library.status == LibraryStatus::Building {
        return Err(ApiError::Conflict(format!(
            "library {id} is building: delete it once its build has ended"
        )));
    }
    let users: Vec<(i64,)> = sqlx::query_as(
        "SELECT id FROM campaigns WHERE library_id = ? AND enumerate = 0 ORDER BY id",
    )
    .bind(id)
    .fetch_all(&mut *tx)
    .await?;
    if !users.is_empty() {
        let ids: Vec<String> = users.iter().map(|(c,)| c.to_string()).collect();
        return Err(ApiError::Conflict(format!(
            "library {id} is used by campaign(s) {}: delete them first (DELETE \
             /api/v1/campaigns/ID; a running one is cancelled before)",
            ids.join(", ")
        )));
    }
    let builds: Vec<(i64,)> =
        sqlx::query_as("SELECT id FROM campaigns WHERE library_id = ? AND enumerate >= 1")
            .bind(id)
            .fetch_all(&mut *tx)
            .await?;
    for (campaign,) in builds {
        delete_campaign_rows(&mut tx, campaign).await?;
    }
    sqlx::query("DELETE FROM libraries WHERE id = ?")
        .bind(id)
        .execute(&mut *tx)
        .await?;
    tx.commit().await?;
    Ok(())
}
