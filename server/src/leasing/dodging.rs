//! Audits that cannot be dodged. A worker asked to run an audit may give
//! the run back or let it expire; before, that cost it nothing, and a
//! liar that hid events and gave back every audit was caught only by the
//! 1 % sample of its own tests (escaping with probability about 0.99^k for
//! k hidden events). Now each run given back (counted at once) or let
//! expire (counted when the run is handed out again; heartbeats keep a
//! live worker's runs, `leasing/fence.rs`):
//!
//! - goes to other workers first (`store/audits.rs`, `runnable`);
//! - makes the worker owe an audit of its own results: one of the tests it
//!   reported and the prefix has not passed, drawn uniformly, is audited,
//!   and until that audit is decided (at most [`standing::OWED_SECONDS`])
//!   the worker gets no range; it may run audits, so workers owing each
//!   other settle by running each other's;
//! - doubles the share of its tests audited, `share · 2^d` for `d` runs
//!   given back in a row; past three in a row every test it reports is
//!   audited, and so are all of its tests the prefix has not passed yet:
//!   its results are held out of the prefix until another worker has run
//!   them again.
//!
//! Running an audit ends the streak. An honest worker that gives a run back
//! now and then (it is shutting down, its program is unhealthy) pays one
//! audit of its own results and a short wait; a dodger's results are all
//! checked (docs/operations.md, "Results are checked").

use crate::store::error::StoreError;
use crate::store::leases::{LeaseRow, LeaseState};
use crate::store::standing::{self, Standing};
use crate::store::{audits, reports};
use rusqlite::Connection;

/// Runs given back in a row past which every test a worker reports is
/// audited.
pub const MAX_DODGES_IN_ROW: i64 = 3;

/// The share of `standing`'s worker's tests audited when the base share is
/// `base`: `min(1, base · 2^d)`, and 1 past [`MAX_DODGES_IN_ROW`].
pub fn audit_share(base: f64, standing: &Standing) -> f64 {
    match standing.dodged_in_row {
        d if d > MAX_DODGES_IN_ROW => 1.0,
        d => (base * 2f64.powi(d.max(0) as i32)).min(1.0),
    }
}

/// Whether a worker in `standing` owes an audit of its own results that is
/// still open: it then gets no lease at all, neither a range nor an audit
/// run (which it could give back again, keeping it from the honest
/// workers), until other workers have decided it.
pub fn owes(standing: &Standing) -> bool {
    standing.owed_open
}

/// The most tests of its own a worker's run given back puts under audit
/// at once (past [`MAX_DODGES_IN_ROW`], all of its unresolved tests, up
/// to this many).
const MAX_AUDITED_AT_ONCE: u64 = 4096;

/// Draws of a test to owe before giving up (each lands on a test audited
/// and decided before with at most the share of those among the worker's
/// unresolved tests).
const DRAWS: usize = 16;

/// Counts the run of `old` (an audit's lease, about to be replaced by a
/// new run) against its holder when it let it expire: it is still active,
/// so the worker neither reported it, nor gave it back (counted then),
/// nor lost it to a stop.
pub fn replaced_run(conn: &Connection, old: &LeaseRow) -> Result<(), StoreError> {
    if old.state == LeaseState::Active && old.audit_id.is_some() {
        gave_back(conn, &old.worker)?;
    }
    Ok(())
}

/// Counts an audit run `worker` gave back or let expire, and puts tests of
/// its own under audit: one unresolved test drawn at random, which it owes
/// before its next range, or past [`MAX_DODGES_IN_ROW`] in a row all of
/// them, so that none of its results passes a prefix unchecked.
pub fn gave_back(conn: &Connection, worker: &str) -> Result<(), StoreError> {
    let in_row = standing::get(conn, worker)?.dodged_in_row + 1;
    let ranges = standing::unfolded_ranges(conn, worker, 4096)?;
    let mut owed = None;
    if in_row > MAX_DODGES_IN_ROW {
        let mut left = MAX_AUDITED_AT_ONCE;
        for &(campaign, from, to) in &ranges {
            let to = to.min(from + left);
            put_under_audit(conn, campaign, worker, from..to)?;
            if owed.is_none() {
                owed = audits::open_of_in(conn, campaign, worker, from, to)?;
            }
            left -= to - from;
            if left == 0 {
                break;
            }
        }
    } else {
        // A test audited and decided before is drawn again (a few times):
        // what is owed is an open audit.
        for _ in 0..DRAWS {
            let Some((campaign, index)) = draw(&ranges) else {
                break;
            };
            put_under_audit(conn, campaign, worker, index..index + 1)?;
            owed = audits::open_id_at(conn, campaign, index)?;
            if owed.is_some() {
                break;
            }
        }
    }
    tracing::warn!(
        worker,
        in_row,
        ?owed,
        "audit run given back or let expire: tests of its own audited"
    );
    standing::dodged(conn, worker, owed)
}

/// A test drawn uniformly from `ranges` (`(campaign, from, to)`): a
/// worker cannot tell which of its unresolved tests will be checked.
fn draw(ranges: &[(i64, u64, u64)]) -> Option<(i64, u64)> {
    let total: u64 = ranges.iter().map(|(_, from, to)| to - from).sum();
    if total == 0 {
        return None;
    }
    let mut at = rand::random_range(0..total);
    for &(campaign, from, to) in ranges {
        if at < to - from {
            return Some((campaign, from + at));
        }
        at -= to - from;
    }
    None
}

/// Audits `worker`'s reported tests `range` of `campaign` (those audited
/// already stay as they are).
fn put_under_audit(
    conn: &Connection,
    campaign: i64,
    worker: &str,
    range: std::ops::Range<u64>,
) -> Result<(), StoreError> {
    let outcomes = reports::outcomes(conn, campaign, range.start, range.end)?;
    let outcome_at = |i: u64| {
        outcomes
            .binary_search_by_key(&i, |o| o.0)
            .ok()
            .map(|k| outcomes[k].1)
    };
    let audits: Vec<audits::NewAudit> = range
        .map(|index| audits::NewAudit {
            test_index: index,
            reason: "sample",
            first_outcome: audits::encode(outcome_at(index)),
            owed: true,
        })
        .collect();
    audits::insert(conn, campaign, worker, &audits)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_share_doubles_per_run_given_back_and_is_whole_past_three() {
        let at = |d| {
            audit_share(
                0.01,
                &Standing {
                    dodged_in_row: d,
                    ..Standing::default()
                },
            )
        };
        assert_eq!([at(0), at(1), at(2), at(3)], [0.01, 0.02, 0.04, 0.08]);
        assert_eq!((at(4), at(40)), (1.0, 1.0));
        assert_eq!(
            audit_share(
                0.4,
                &Standing {
                    dodged_in_row: 2,
                    ..Standing::default()
                }
            ),
            1.0
        );
    }
}
