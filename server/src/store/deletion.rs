//! Deleting what a user no longer wants: a stopped campaign with everything
//! recorded for it, and a library no campaign uses (with the campaign that
//! built it on workers, if any). Running work is never deleted: a running
//! campaign is cancelled first, a building library waits for its build.

use crate::db::sql;
use crate::store::campaign_row::methods_where;
use crate::store::error::StoreError;
use rusqlite::Connection;
use tslg_api::LibraryStatus;

/// The tables holding a campaign's records, children before parents
/// (leases name audits).
const CAMPAIGN_TABLES: [&str; 10] = [
    "leases",
    "work_spans",
    "worker_test_evidence",
    "test_pairing_walks",
    "adaptive_stages",
    "audits",
    "near_misses",
    "reports",
    "invalid_tests",
    "history",
];

fn delete_campaign_rows(conn: &Connection, id: i64) -> Result<(), StoreError> {
    for table in CAMPAIGN_TABLES {
        sql::execute(
            conn,
            &format!("DELETE FROM {table} WHERE campaign_id = ?"),
            [id],
        )?;
    }
    // The counters on /metrics keep what it resolved (deleted_totals).
    sql::execute(
        conn,
        "UPDATE deleted_totals SET \
         indices = indices + (SELECT indices FROM campaigns WHERE id = ?1), \
         events = events + (SELECT events FROM campaigns WHERE id = ?1), \
         invalid = invalid + (SELECT invalid FROM campaigns WHERE id = ?1) WHERE id = 1",
        [id],
    )?;
    sql::execute(conn, "DELETE FROM campaigns WHERE id = ?", [id])?;
    Ok(())
}

/// Deletes stopped campaign `id` and its records, with the other campaign
/// of its pair if it has one (a write), and returns that one's id; 409
/// while either runs.
pub fn delete_campaign(conn: &Connection, id: i64) -> Result<Option<i64>, StoreError> {
    let row = crate::store::campaigns::get(conn, id)?;
    if !row.status.is_final() {
        return Err(StoreError::Conflict(format!(
            "campaign {id} is {}: cancel it first (POST /api/v1/campaigns/{id}/cancel)",
            row.status.as_str()
        )));
    }
    if row.method.builds_library() {
        if let Some(library) = row.library_id {
            return Err(StoreError::Conflict(format!(
                "campaign {id} built library {library}: it goes with the library \
                 (DELETE /api/v1/libraries/{library})"
            )));
        }
    }
    // A paired campaign goes with its pair: both campaigns and the pair.
    if let Some(partner) = row.paired_with {
        let other = crate::store::campaigns::get(conn, partner)?;
        if !other.status.is_final() {
            return Err(StoreError::Conflict(format!(
                "campaign {id} is paired with campaign {partner}, which is {}: cancel it first \
                 (POST /api/v1/campaigns/{partner}/cancel)",
                other.status.as_str()
            )));
        }
        crate::store::pairs::unlink(conn, &row)?;
        delete_campaign_rows(conn, partner)?;
    }
    delete_campaign_rows(conn, id)?;
    Ok(row.paired_with)
}

/// Deletes library `id` and its file, with the campaign that built it on
/// workers (a write); 409 while it builds or while campaigns use it.
pub fn delete_library(conn: &Connection, id: i64) -> Result<(), StoreError> {
    let library = crate::store::libraries::get(conn, id)?;
    if library.status == LibraryStatus::Building {
        return Err(StoreError::Conflict(format!(
            "library {id} is building: delete it once its build has ended"
        )));
    }
    let users: Vec<(i64,)> = sql::all(
        conn,
        &format!(
            "SELECT id FROM campaigns WHERE library_id = ? AND method NOT IN {} ORDER BY id",
            methods_where(|m| m.builds.is_some())
        ),
        [id],
    )?;
    if !users.is_empty() {
        let ids: Vec<String> = users.iter().map(|(c,)| c.to_string()).collect();
        return Err(StoreError::Conflict(format!(
            "library {id} is used by campaign(s) {}: delete them first (DELETE \
             /api/v1/campaigns/ID; a running one is cancelled before)",
            ids.join(", ")
        )));
    }
    let builds: Vec<(i64,)> = sql::all(
        conn,
        &format!(
            "SELECT id FROM campaigns WHERE library_id = ? AND method IN {}",
            methods_where(|m| m.builds.is_some())
        ),
        [id],
    )?;
    for (campaign,) in builds {
        delete_campaign_rows(conn, campaign)?;
    }
    sql::execute(conn, "DELETE FROM libraries WHERE id = ?", [id])?;
    Ok(())
}
