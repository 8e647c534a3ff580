//! Per pair of workers, the pairs of their runs compared, and on how many
//! only one of the two found an event: the sampled audits of noisy
//! programs both ran (`worker_discordance`, weighed by `report/noisy.rs`)
//! and, apart, pairs of their tests of one campaign and cell
//! (`worker_test_evidence`, weighed by `report/evidence.rs`), one e-value
//! per campaign (campaigns that reuse a seed draw the same tests again).

use crate::db::sql;
use crate::store::error::StoreError;
use rusqlite::{params, Connection};
use tslg_method::discordance::Discordant;
use tslg_method::test_pairing::PairTally;

/// Which pairs: each kind is its own e-value (an audited test's first run
/// may be in a pair of each kind, and one e-value must not count a run
/// twice).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pairs {
    /// An audit's two runs of one test.
    Audits,
    /// Two workers' tests of one campaign (its id) and cell.
    Tests(i64),
}

impl Pairs {
    fn table(self) -> &'static str {
        match self {
            Pairs::Audits => "worker_discordance",
            Pairs::Tests(_) => "worker_test_evidence",
        }
    }

    /// The campaign column and its value, where the kind has one.
    fn campaign(self) -> Option<i64> {
        match self {
            Pairs::Audits => None,
            Pairs::Tests(campaign) => Some(campaign),
        }
    }

    /// `AND campaign_id = N` for a campaign's pairs (an integer: nothing
    /// to quote).
    fn scope(self) -> String {
        self.campaign()
            .map_or_else(String::new, |id| format!(" AND campaign_id = {id}"))
    }
}

/// Counts `tally.compared` pairs of `first`'s and `second`'s runs, in
/// `tally.first_closer` of which `first`'s found the event (or came
/// closer to it) and `second`'s not, in `tally.second_closer` the other
/// way round, in both directions.
pub fn record(
    conn: &Connection,
    kind: Pairs,
    first: &str,
    second: &str,
    tally: PairTally,
) -> Result<(), StoreError> {
    for (worker, partner, own, theirs) in [
        (first, second, tally.first_closer, tally.second_closer),
        (second, first, tally.second_closer, tally.first_closer),
    ] {
        // A campaign's pairs carry its id (an integer: nothing to quote).
        let (column, value, key) = match kind.campaign() {
            Some(id) => ("campaign_id, ", format!("{id}, "), "campaign_id, "),
            None => ("", String::new(), ""),
        };
        sql::execute(
            conn,
            &format!(
                "INSERT INTO {} ({column}worker, partner, compared, own_event, partner_event) \
                 VALUES ({value}?, ?, ?, ?, ?) \
                 ON CONFLICT ({key}worker, partner) DO UPDATE SET \
                   compared = compared + excluded.compared, \
                   own_event = own_event + excluded.own_event, \
                   partner_event = partner_event + excluded.partner_event",
                kind.table()
            ),
            params![
                worker,
                partner,
                tally.compared as i64,
                own as i64,
                theirs as i64
            ],
        )?;
    }
    Ok(())
}

/// `worker`'s discordant pairs of `kind` with each partner that is not
/// flagged (a flagged worker's runs say nothing about the others), and the
/// pairs compared with all partners.
pub fn partners_of(
    conn: &Connection,
    kind: Pairs,
    worker: &str,
) -> Result<(Vec<Discordant>, u64), StoreError> {
    let rows: Vec<(i64, i64, i64)> = sql::all(
        conn,
        &format!(
            "SELECT compared, own_event, partner_event FROM {} \
             WHERE worker = ? AND partner NOT IN ({}){}",
            kind.table(),
            crate::store::audits::FLAGGED_PRINCIPALS,
            kind.scope()
        ),
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

/// Every worker's pairs of the audits, by name, for the workers' view;
/// with `tests`, of the tests instead, one entry a worker and campaign.
pub fn all(
    conn: &Connection,
    tests: bool,
) -> Result<Vec<(String, Vec<Discordant>, u64)>, StoreError> {
    // The audits' pairs are a worker's whole life: one entry, campaign 0.
    let (table, campaign) = if tests {
        ("worker_test_evidence", "campaign_id")
    } else {
        ("worker_discordance", "0 AS campaign_id")
    };
    let rows: Vec<(String, i64, i64, i64, i64)> = sql::all(
        conn,
        &format!(
            "SELECT worker, {campaign}, compared, own_event, partner_event FROM {table} \
             WHERE partner NOT IN ({}) ORDER BY worker, campaign_id",
            crate::store::audits::FLAGGED_PRINCIPALS
        ),
        [],
    )?;
    let mut out: Vec<(String, Vec<Discordant>, u64)> = Vec::new();
    let mut last_key = None;
    for (worker, campaign, compared, own, theirs) in rows {
        let key = Some((worker.clone(), campaign));
        if last_key != key {
            last_key = key;
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
    for table in ["worker_discordance", "worker_test_evidence"] {
        sql::execute(
            conn,
            &format!("DELETE FROM {table} WHERE worker = ?1 OR partner = ?1"),
            [worker],
        )?;
    }
    Ok(())
}
