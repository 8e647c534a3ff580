//! The `test_pairing_walks` table: how far each campaign's pairing of
//! tests walked its resolved prefix, and the tests waiting there for a
//! partner (`report/evidence.rs`).

use crate::db::sql;
use crate::store::error::StoreError;
use rusqlite::{params, Connection};

/// Where campaign `campaign`'s walk stopped and its waiting tests (JSON);
/// `None` before its first walk.
pub fn get(conn: &Connection, campaign: i64) -> Result<Option<(u64, String)>, StoreError> {
    let row: Option<(i64, String)> = sql::optional(
        conn,
        "SELECT walked_to, waiting FROM test_pairing_walks WHERE campaign_id = ?",
        [campaign],
    )?;
    Ok(row.map(|(to, waiting)| (to as u64, waiting)))
}

/// Stores campaign `campaign`'s walk, walked to `walked_to`.
pub fn put(
    conn: &Connection,
    campaign: i64,
    walked_to: u64,
    waiting: &str,
) -> Result<(), StoreError> {
    sql::execute(
        conn,
        "INSERT INTO test_pairing_walks (campaign_id, walked_to, waiting) VALUES (?1, ?2, ?3) \
         ON CONFLICT (campaign_id) DO UPDATE SET walked_to = ?2, waiting = ?3",
        params![campaign, walked_to as i64, waiting],
    )?;
    Ok(())
}
