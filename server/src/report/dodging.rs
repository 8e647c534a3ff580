//! Audits that cannot be dodged. A worker asked to run an audit may give
//! the run back or let it expire; before, that cost it nothing, and a
//! liar that hid events and gave back every audit was caught only by the
//! 1 % sample of its own tests (escaping with probability about 0.99^k for
//! k hidden events). Now each run given back or let expire:
//!
//! - makes the worker owe an audit of its own results: one of the tests it
//!   reported and the prefix has not passed, drawn at random, is audited,
//!   and until that audit is decided the worker gets no new range (it may
//!   still run audits);
//! - doubles the share of its tests audited, `share · 2^d` for `d` runs
//!   given back in a row, and past three in a row every test it reports is
//!   audited, so its new results are held out of the prefix until another
//!   worker has run them again.
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

/// Whether a worker in `standing` may take a new range: not while an audit
/// of its own results it owes is open.
pub fn may_take_range(standing: &Standing) -> bool {
    !standing.owed_open
}

/// Counts the run of `old` (an audit's lease, about to be replaced by a
/// new run) against its holder when it was given back or let expire: it
/// is still active, so the worker neither reported nor lost it to a stop.
pub fn replaced_run(conn: &Connection, old: &LeaseRow) -> Result<(), StoreError> {
    if old.state == LeaseState::Active && old.audit_id.is_some() {
        dodged(conn, &old.worker)?;
    }
    Ok(())
}

/// Counts an audit run `worker` gave back or let expire, and makes it owe
/// an audit of one of its own unresolved tests (when it has one).
fn dodged(conn: &Connection, worker: &str) -> Result<(), StoreError> {
    let owed = match standing::unfolded_range(conn, worker)? {
        Some((campaign, from, to)) => {
            let index = rand::random_range(from..to);
            let outcome = reports::outcomes(conn, campaign, index, index + 1)?
                .first()
                .map(|&(_, o)| o);
            let audit = audits::NewAudit {
                test_index: index,
                reason: "sample",
                first_outcome: audits::encode(outcome),
            };
            audits::insert(conn, campaign, worker, &[audit])?;
            audits::id_at(conn, campaign, index)?
        }
        None => None,
    };
    tracing::warn!(
        worker,
        ?owed,
        "audit run given back or let expire: the worker owes an audit"
    );
    standing::dodged(conn, worker, owed)
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
