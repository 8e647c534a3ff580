//! The `near_misses` table: an external program's tests of an adaptive
//! campaign that came within the plan's `near_miss` of the event, with
//! their criticality (a built-in vehicle's are run again instead).

use crate::db::sql;
use crate::store::error::StoreError;
use rusqlite::{params, Connection};
use tslg_api::NearMiss;

/// Stores a report's near misses of the part `new_from..` (a program's;
/// a built-in vehicle's are run again here).
pub fn insert(
    conn: &Connection,
    campaign: i64,
    near_misses: &[NearMiss],
    new_from: u64,
) -> Result<(), StoreError> {
    for m in near_misses.iter().filter(|m| m.index >= new_from) {
        sql::execute(
            conn,
            "INSERT OR REPLACE INTO near_misses (campaign_id, test_index, criticality) \
             VALUES (?, ?, ?)",
            params![campaign, m.index as i64, m.criticality],
        )?;
    }
    Ok(())
}

/// The near misses `(test index, criticality)` of `campaign`'s tests
/// `from..to`, in index order.
pub fn of_range(
    conn: &Connection,
    campaign: i64,
    from: u64,
    to: u64,
) -> Result<Vec<(i64, f64)>, StoreError> {
    Ok(sql::all(
        conn,
        "SELECT test_index, criticality FROM near_misses \
         WHERE campaign_id = ? AND test_index >= ? AND test_index < ? ORDER BY test_index",
        params![campaign, from as i64, to as i64],
    )?)
}
