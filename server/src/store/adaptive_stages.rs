//! The `adaptive_stages` table: an adaptive campaign's resolved stages
//! ([`tslg_method::adaptive::StageRecord`]), for its page and reports.

use crate::db::sql;
use crate::store::error::StoreError;
use rusqlite::{params, Connection};
use serde::Deserialize;
use tslg_api::AdaptiveStage;
use tslg_method::adaptive::StageRecord;

/// Stores `records` (a stage's record replaces any stored for its start).
pub fn store(conn: &Connection, campaign: i64, records: &[StageRecord]) -> Result<(), StoreError> {
    for r in records {
        sql::execute(
            conn,
            "INSERT OR REPLACE INTO adaptive_stages (campaign_id, start_index, end_index, kind, \
             events, new_failures, invalid, support, restarts_estimate) \
             VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
            params![
                campaign,
                r.start as i64,
                r.end as i64,
                r.kind,
                r.events as i64,
                r.new_failures as i64,
                r.invalid as i64,
                r.support as i64,
                r.restarts_estimate
            ],
        )?;
    }
    Ok(())
}

#[derive(Deserialize)]
struct Row {
    kind: String,
    start_index: i64,
    end_index: i64,
    events: i64,
    new_failures: i64,
    invalid: i64,
    support: i64,
    restarts_estimate: i64,
}

/// `campaign`'s stored stages in test order.
pub fn of(conn: &Connection, campaign: i64) -> Result<Vec<AdaptiveStage>, StoreError> {
    let rows: Vec<Row> = sql::all(
        conn,
        "SELECT kind, start_index, end_index, events, new_failures, invalid, support, \
         restarts_estimate FROM adaptive_stages WHERE campaign_id = ? ORDER BY start_index",
        [campaign],
    )?;
    Ok(rows
        .into_iter()
        .map(|r| AdaptiveStage {
            kind: r.kind,
            start: r.start_index as u64,
            end: r.end_index as u64,
            events: r.events as u64,
            new_failures: r.new_failures as u64,
            invalid: r.invalid as u64,
            support: r.support as u64,
            restarts_estimate: r.restarts_estimate != 0,
        })
        .collect())
}
