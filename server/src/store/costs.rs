//! The `test_costs` table: what one test of a vehicle costs on one thread,
//! kept across campaigns (`leasing/size.rs` sizes leases from it).

use crate::db::sql;
use crate::store::error::StoreError;
use rusqlite::{params, Connection};

/// The key of a campaign's vehicle: its program (`NAME:case:mode`), or the
/// built-in vehicle's specification on its case and preset.
pub fn key(case: &str, preset: &str, vut: &str, requires: Option<&str>) -> String {
    match requires {
        Some(program) => program.to_owned(),
        None => format!("{case}|{preset}|{vut}"),
    }
}

/// The cost of one test of the vehicle `key`, in seconds, if known.
pub fn get(conn: &Connection, key: &str) -> Result<Option<f64>, StoreError> {
    let cost: Option<(f64,)> =
        sql::optional(conn, "SELECT seconds FROM test_costs WHERE key = ?", [key])?;
    Ok(cost.map(|(c,)| c))
}

/// Records `seconds` as the cost of one test of the vehicle `key`.
pub fn put(conn: &Connection, key: &str, seconds: f64) -> Result<(), StoreError> {
    sql::execute(
        conn,
        "INSERT INTO test_costs (key, seconds) VALUES (?1, ?2) \
         ON CONFLICT (key) DO UPDATE SET seconds = ?2, \
         updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')",
        params![key, seconds],
    )?;
    Ok(())
}

/// Every known program's cost (keys of the form `NAME:case:mode`), by key.
pub fn programs(conn: &Connection) -> Result<Vec<(String, f64)>, StoreError> {
    Ok(sql::all(
        conn,
        "SELECT key, seconds FROM test_costs WHERE key NOT LIKE '%|%' ORDER BY key",
        [],
    )?)
}
