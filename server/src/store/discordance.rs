//! The `worker_discordance` table: per pair of workers, the sampled audits
//! of noisy programs both ran, and on how many of them only one of the two
//! found an event (`report/noisy.rs` weighs them).

use crate::db::sql;
use crate::store::error::StoreError;
use rusqlite::{params, Connection};
use tslg_method::discordance::Discordant;

/// Counts one sampled audit of a noisy program that `first` and `replica`
/// both ran, with whether each found an event, in both directions.
pub fn record(
    conn: &Connection,
    first: &str,
    replica: &str,
    first_event: bool,
    replica_event: bool,
) -> Result<(), StoreError> {
    for (worker, partner, own, theirs) in [
        (first, replica, first_event, replica_event),
        (replica, first, replica_event, first_event),
    ] {
        sql::execute(
            conn,
            "INSERT INTO worker_discordance (worker, partner, compared, own_event, partner_event) \
             VALUES (?, ?, 1, ?, ?) \
             ON CONFLICT (worker, partner) DO UPDATE SET compared = compared + 1, \
               own_event = own_event + excluded.own_event, \
               partner_event = partner_event + excluded.partner_event",
            params![worker, partner, own && !theirs, theirs && !own],
        )?;
    }
    Ok(())
}

/// `worker`'s discordant pairs with each partner that is not flagged (a
/// flagged worker's runs say nothing about the others), and the audits
/// compared with all partners.
pub fn partners_of(conn: &Connection, worker: &str) -> Result<(Vec<Discordant>, u64), StoreError> {
    let rows: Vec<(i64, i64, i64)> = sql::all(
        conn,
        "SELECT compared, own_event, partner_event FROM worker_discordance \
         WHERE worker = ? AND partner NOT IN (SELECT name FROM flagged_workers)",
        [worker],
    )?;
    let compared = rows.iter().map(|r| r.0 as u64).sum();
    let pairs = rows
        .into_iter()
        .map(|(_, own, theirs)| Discordant {
            own_event: own as u64,
            partner_event: theirs as u64,
        })
        .collect();
    Ok((pairs, compared))
}

/// Every worker's pairs, by name, for the workers' view.
pub fn all(conn: &Connection) -> Result<Vec<(String, Vec<Discordant>, u64)>, StoreError> {
    let rows: Vec<(String, i64, i64, i64)> = sql::all(
        conn,
        "SELECT worker, compared, own_event, partner_event FROM worker_discordance \
         WHERE partner NOT IN (SELECT name FROM flagged_workers) ORDER BY worker",
        [],
    )?;
    let mut out: Vec<(String, Vec<Discordant>, u64)> = Vec::new();
    for (worker, compared, own, theirs) in rows {
        if out.last().map(|o| &o.0) != Some(&worker) {
            out.push((worker.clone(), Vec::new(), 0));
        }
        let last = out.last_mut().expect("pushed");
        last.1.push(Discordant {
            own_event: own as u64,
            partner_event: theirs as u64,
        });
        last.2 += compared as u64;
    }
    Ok(out)
}

/// Forgets every pair of `worker` (an operator cleared its flag: its
/// evidence starts afresh, and a cleared liar's past runs do not count for
/// or against the others).
pub fn forget(conn: &Connection, worker: &str) -> Result<(), StoreError> {
    sql::execute(
        conn,
        "DELETE FROM worker_discordance WHERE worker = ?1 OR partner = ?1",
        [worker],
    )?;
    Ok(())
}
