//! The `reports` and `invalid_tests` tables: what workers reported.
//!
//! One row per accepted report: its range, its lease and worker, and its
//! events packed ([`tslg_api::packed`]); invalid tests one row each with
//! the reason. Tests of a reported range that are not listed had no event.
//! Storage grows with reports and events, never with tests: a report row
//! costs about 40 bytes plus 2 to 10 bytes per event (a dictionary of
//! weights makes a grid case's events 2 to 3 bytes each), so a campaign
//! with 4 million events keeps about 12 MB of them, read back in tens of
//! milliseconds.

use crate::db::sql;
use crate::store::error::StoreError;
use rusqlite::{params, Connection};
use tslg_api::{packed, MAX_REPORT_TESTS};
use tslg_method::prefix::SparseOutcome;

/// A report to store: the range, who sent it, its events (index order)
/// and invalid tests with their reasons (index order).
pub struct NewReport<'a> {
    pub campaign_id: i64,
    pub lease_id: i64,
    pub worker: &'a str,
    pub from: u64,
    pub to: u64,
    pub events: &'a [(u64, f64)],
    pub invalid: &'a [(u64, &'a str)],
    /// The criticality of tests without the event (index order), kept for
    /// the pairing of tests (`report/evidence.rs`); empty: none.
    pub near: &'a [(u64, f64)],
    /// Made on a lease handed out again (attempt > 1): left out of the
    /// pairing, since its range may have been chosen by outcomes.
    pub handed_again: bool,
}

pub fn insert(conn: &Connection, report: &NewReport<'_>) -> Result<(), StoreError> {
    sql::execute(
        conn,
        "INSERT INTO reports (campaign_id, from_index, to_index, lease_id, worker, events, packed, \
         near_packed, handed_again) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
        params![
            report.campaign_id,
            report.from as i64,
            report.to as i64,
            report.lease_id,
            report.worker,
            report.events.len() as i64,
            packed::pack(report.from, report.events),
            (!report.near.is_empty()).then(|| packed::pack(report.from, report.near)),
            report.handed_again
        ],
    )?;
    if report.invalid.is_empty() {
        return Ok(());
    }
    let mut statement = conn.prepare_cached(
        "INSERT INTO invalid_tests (campaign_id, test_index, reason) VALUES (?, ?, ?)",
    )?;
    for &(index, reason) in report.invalid {
        statement.execute(params![report.campaign_id, index as i64, reason])?;
    }
    Ok(())
}

/// The packed events of the reports' rows that reach into `from..to`, as
/// SQL binding campaign, from, to as ?1, ?2, ?3. Workers' report rows
/// never overlap (each covers the new part of one lease's range), so of
/// those starting at or before `from` only the last can reach into the
/// range: the scan starts there, and costs the rows in the range, not the
/// campaign's history. Rows moved from the old per-event table (worker
/// `''`) may overlap others and are few: they are looked up apart, by the
/// index on the worker (the planner would otherwise walk the key from the
/// campaign's first row).
const REPORTS_REACHING: &str = "\
    WITH start AS (SELECT COALESCE((SELECT MAX(from_index) FROM reports \
                   WHERE campaign_id = ?1 AND from_index <= ?2), ?2) AS at) \
    SELECT from_index, packed FROM reports, start WHERE campaign_id = ?1 \
      AND from_index >= start.at AND from_index < ?3 AND to_index > ?2 AND events > 0 \
    UNION ALL SELECT from_index, packed FROM reports INDEXED BY reports_by_worker, start \
      WHERE worker = '' AND campaign_id = ?1 AND from_index < start.at AND to_index > ?2 AND events > 0";

/// Appends the events of the report row starting at `start` that fall in
/// `range`.
fn unpack_into(
    events: &mut Vec<(u64, f64)>,
    campaign: i64,
    start: i64,
    bytes: &[u8],
    range: std::ops::Range<u64>,
) -> Result<(), StoreError> {
    let unpacked = packed::unpack(start as u64, bytes).map_err(|e| {
        anyhow::anyhow!("stored report at {start} of campaign {campaign} is damaged: {e}")
    })?;
    events.extend(unpacked.into_iter().filter(|&(i, _)| range.contains(&i)));
    Ok(())
}

/// The first `limit` events of `campaign` in `from..to`, by test index
/// (a page of `GET /api/v1/campaigns/{id}/events`): reads report rows in
/// order from the one reaching `from` until `limit` events are found.
pub fn events_page(
    conn: &Connection,
    campaign: i64,
    from: u64,
    to: u64,
    limit: usize,
) -> Result<Vec<(u64, f64)>, StoreError> {
    // Rows are read in small batches; the first may hold events before
    // `from`, each later one at least one event in range (`events > 0`).
    // A row holds up to 65,536 events: batches of `limit + 1` rows
    // unpacked up to 2.7 × 10⁸ events for one page of 10,000.
    let batch = limit.clamp(1, 16) + 1;
    let mut events = Vec::new();
    let mut at = from;
    while events.len() < limit && at < to {
        let rows: Vec<(i64, Vec<u8>)> = sql::all(
            conn,
            &format!("{REPORTS_REACHING} ORDER BY from_index LIMIT ?4"),
            params![campaign, at as i64, to as i64, batch as i64],
        )?;
        let mut found = Vec::new();
        for (start, bytes) in &rows {
            unpack_into(&mut found, campaign, *start, bytes, at..to)?;
        }
        found.sort_by_key(|&(i, _)| i);
        found.dedup_by_key(|e| e.0);
        events.extend(found);
        if rows.len() < batch {
            break;
        }
        // Past the last row read: its events are in.
        let (last, _) = rows.last().expect("a full batch");
        let next = sql::one::<(i64,)>(
            conn,
            "SELECT to_index FROM reports WHERE campaign_id = ?1 AND from_index = ?2",
            params![campaign, last],
        )?
        .0 as u64;
        at = next.max(at + 1);
    }
    events.truncate(limit);
    Ok(events)
}

/// Stored events and invalid tests of `campaign` in `from..to`, sorted by
/// index, in one read (a fold runs in every report's transaction).
pub fn outcomes(
    conn: &Connection,
    campaign: i64,
    from: u64,
    to: u64,
) -> Result<Vec<(u64, SparseOutcome)>, StoreError> {
    // A report row carries its packed events; an invalid test, none.
    let rows: Vec<(i64, Option<Vec<u8>>)> = sql::all(
        conn,
        &format!(
            "{REPORTS_REACHING} \
             UNION ALL SELECT test_index, NULL FROM invalid_tests \
             WHERE campaign_id = ?1 AND test_index >= ?2 AND test_index < ?3"
        ),
        params![campaign, from as i64, to as i64],
    )?;
    let mut events = Vec::new();
    let mut outcomes = Vec::new();
    for (start, bytes) in rows {
        match bytes {
            Some(bytes) => unpack_into(&mut events, campaign, start, &bytes, from..to)?,
            None => outcomes.push((start as u64, SparseOutcome::Invalid)),
        }
    }
    outcomes.extend(
        events
            .into_iter()
            .map(|(i, w)| (i, SparseOutcome::Event(w))),
    );
    // Rows moved from the old per-event table may overlap newer reports'
    // ranges (never their events): sort once.
    outcomes.sort_by_key(|&(i, _)| i);
    Ok(outcomes)
}

/// Events moved from the old per-event table go into report rows of at
/// most this many events.
const LEGACY_CHUNK: usize = 65_536;

/// Packs the rows of the old `legacy_events` table (databases from before
/// the `reports` table) into report rows without a worker, and drops it.
/// Runs at start-up, after the migrations, in one transaction.
pub async fn move_legacy_events(db: &crate::db::Database) -> anyhow::Result<()> {
    let moved = db
        .write(|conn| move_legacy_rows(conn).map_err(StoreError::from))
        .await
        .map_err(|e| anyhow::anyhow!("cannot move the old event rows into report rows: {e}"))?;
    if moved > 0 {
        tracing::info!(events = moved, "old event rows packed into report rows");
    }
    Ok(())
}

fn move_legacy_rows(conn: &Connection) -> Result<u64, anyhow::Error> {
    let (exists,): (i64,) = sql::one(
        conn,
        "SELECT COUNT(*) FROM sqlite_master WHERE type = 'table' AND name = 'legacy_events'",
        [],
    )?;
    if exists == 0 {
        return Ok(0);
    }
    let rows: Vec<(i64, i64, f64)> = sql::all(
        conn,
        "SELECT campaign_id, test_index, weight FROM legacy_events ORDER BY campaign_id, test_index",
        [],
    )?;
    let moved = rows.len() as u64;
    let mut at = 0;
    while at < rows.len() {
        let campaign = rows[at].0;
        // One campaign's events, at most LEGACY_CHUNK of them, spanning
        // fewer than MAX_REPORT_TESTS indices like every report.
        let first = rows[at].1;
        let end = rows[at..]
            .iter()
            .position(|r| r.0 != campaign || r.1 - first >= MAX_REPORT_TESTS as i64)
            .map_or(rows.len(), |k| at + k)
            .min(at + LEGACY_CHUNK);
        let events: Vec<(u64, f64)> = rows[at..end]
            .iter()
            .map(|&(_, i, w)| (i as u64, w))
            .collect();
        let (from, to) = (events[0].0, events[events.len() - 1].0 + 1);
        sql::execute(
            conn,
            "INSERT INTO reports (campaign_id, from_index, to_index, lease_id, worker, events, packed) \
             VALUES (?, ?, ?, NULL, '', ?, ?)",
            params![
                campaign,
                from as i64,
                to as i64,
                events.len() as i64,
                packed::pack(from, &events)
            ],
        )?;
        at = end;
    }
    conn.execute_batch("DROP TABLE legacy_events")?;
    Ok(moved)
}

/// The campaigns `worker` reported to.
pub fn campaigns_of_worker(conn: &Connection, worker: &str) -> Result<Vec<i64>, StoreError> {
    let rows: Vec<(i64,)> = sql::all(
        conn,
        "SELECT DISTINCT campaign_id FROM reports WHERE worker = ?",
        [worker],
    )?;
    Ok(rows.into_iter().map(|(id,)| id).collect())
}

/// The criticalities kept with the reports of `from..to` (index order).
pub fn near_between(
    conn: &Connection,
    campaign: i64,
    from: u64,
    to: u64,
) -> Result<Vec<(u64, f64)>, StoreError> {
    let rows: Vec<(i64, Vec<u8>)> = sql::all(
        conn,
        "WITH start AS (SELECT COALESCE((SELECT MAX(from_index) FROM reports \
                        WHERE campaign_id = ?1 AND from_index <= ?2), ?2) AS at) \
         SELECT from_index, near_packed FROM reports, start WHERE campaign_id = ?1 \
           AND from_index >= start.at AND from_index < ?3 AND to_index > ?2 \
           AND near_packed IS NOT NULL ORDER BY from_index",
        params![campaign, from as i64, to as i64],
    )?;
    let mut near = Vec::new();
    for (start, bytes) in rows {
        unpack_into(&mut near, campaign, start, &bytes, from..to)?;
    }
    Ok(near)
}

/// Who ran the tests of `from..to`: the reports' ranges reaching into it,
/// clipped to it, `(from, to, worker)` in index order (rows moved from the
/// old per-event table, which name no worker, and reports made on a lease
/// handed out again, left out). Report rows never
/// overlap, so the scan starts at the last row starting at or before
/// `from`, as in [`outcomes`].
pub fn workers_between(
    conn: &Connection,
    campaign: i64,
    from: u64,
    to: u64,
) -> Result<Vec<(u64, u64, String)>, StoreError> {
    let rows: Vec<(i64, i64, String)> = sql::all(
        conn,
        "WITH start AS (SELECT COALESCE((SELECT MAX(from_index) FROM reports \
                        WHERE campaign_id = ?1 AND from_index <= ?2), ?2) AS at) \
         SELECT from_index, to_index, worker FROM reports, start WHERE campaign_id = ?1 \
           AND from_index >= start.at AND from_index < ?3 AND to_index > ?2 AND worker != '' \
           AND handed_again = 0 ORDER BY from_index",
        params![campaign, from as i64, to as i64],
    )?;
    Ok(rows
        .into_iter()
        .map(|(a, b, worker)| ((a as u64).max(from), (b as u64).min(to), worker))
        .collect())
}

/// The ranges `(from, to)` of `worker`'s reports to `campaign`, in order.
pub fn ranges_of_worker(
    conn: &Connection,
    campaign: i64,
    worker: &str,
) -> Result<Vec<(i64, i64)>, StoreError> {
    Ok(sql::all(
        conn,
        "SELECT from_index, to_index FROM reports WHERE campaign_id = ? AND worker = ? \
         ORDER BY from_index",
        params![campaign, worker],
    )?)
}

/// Deletes the report of `campaign` that starts at `from` and the invalid
/// tests of its range `from..to`.
pub fn delete_range(
    conn: &Connection,
    campaign: i64,
    from: i64,
    to: i64,
) -> Result<(), StoreError> {
    sql::execute(
        conn,
        "DELETE FROM reports WHERE campaign_id = ? AND from_index = ?",
        [campaign, from],
    )?;
    sql::execute(
        conn,
        "DELETE FROM invalid_tests WHERE campaign_id = ? AND test_index >= ? \
         AND test_index < ?",
        [campaign, from, to],
    )?;
    Ok(())
}

/// Why test `index` of `campaign` was invalid, as its worker said.
pub fn invalid_reason(
    conn: &Connection,
    campaign: i64,
    index: u64,
) -> Result<Option<String>, StoreError> {
    let reason: Option<(String,)> = sql::optional(
        conn,
        "SELECT reason FROM invalid_tests WHERE campaign_id = ? AND test_index = ?",
        [campaign, index as i64],
    )?;
    Ok(reason.map(|(r,)| r))
}
