//! A campaign's resolved prefix as rows: where a fold may go (the
//! frontier), the fold's state and the reports' charges on the campaign's
//! row, its history points, and a stopped campaign closed.

use crate::db::sql;
use crate::store::campaign_row::CampaignRow;
use crate::store::error::StoreError;
use crate::store::leases;
use crate::store::states::{AUDIT_PAST, LEASE_ACTIVE};
use rusqlite::{params, Connection};
use tslg_api::CampaignStatus;
use tslg_method::prefix::PrefixFold;
use tslg_method::registry::AdaptiveProgress;

/// The first index the prefix may not pass: the smallest `resume_at` of
/// the campaign's active leases (below it every outcome is recorded), its
/// `next_index`, and its first open audit (a test two workers have not yet
/// agreed on, `report/audit.rs`). A noisy program's sampled audit holds
/// nothing: its first run stands whatever the replica gives
/// (`report/noisy.rs`), so a stage does not wait a test's time for it; an
/// audit a worker owes for giving audit runs back (`leasing/dodging.rs`)
/// holds the prefix for every program, so that dodging costs the dodger
/// its results' place in the prefix.
pub fn frontier(conn: &Connection, campaign: &CampaignRow) -> Result<u64, StoreError> {
    Ok(bounds(conn, campaign)?.frontier)
}

/// Where a fold may go and where its history stands.
pub struct Bounds {
    /// See [`frontier`].
    pub frontier: u64,
    /// The campaign's last stored history point.
    pub last_stored: Option<u64>,
}

/// [`Bounds`] in one read (a fold runs in every report's transaction).
pub fn bounds(conn: &Connection, campaign: &CampaignRow) -> Result<Bounds, StoreError> {
    let (open, audited, last_stored): (Option<i64>, Option<i64>, Option<i64>) = sql::one(
        conn,
        &format!(
            "SELECT (SELECT MIN(resume_at) FROM leases WHERE campaign_id = ?1 \
                     AND state = {LEASE_ACTIVE} AND audit_id IS NULL), \
                    (SELECT MIN(test_index) FROM audits WHERE campaign_id = ?1 \
                     AND state IN {open} AND (owed OR NOT ?2)), \
                    (SELECT MAX(indices) FROM history WHERE campaign_id = ?1)",
            open = crate::store::states::AUDIT_OPEN
        ),
        params![campaign.id, campaign.vehicle_noise],
    )?;
    let recorded = open.map_or(campaign.next_index, |r| r.min(campaign.next_index)) as u64;
    Ok(Bounds {
        frontier: audited.map_or(recorded, |a| (a as u64).min(recorded)),
        last_stored: last_stored.map(|i| i as u64),
    })
}

/// A report's charge to its campaign's row: the smoothed cost per test
/// (which sizes leases), the worker time and the weights of its events.
/// The fold updates the same row: one update for both instead of two (the
/// row has 51 columns, and the writer updates it for every report).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Charge {
    pub cost_per_test: Option<f64>,
    pub worker_seconds: f64,
    pub reported_s1: f64,
}

/// Writes `charge` to `campaign`'s row on its own (where no fold writes
/// the row).
pub fn charge(conn: &Connection, campaign: i64, charge: &Charge) -> Result<(), StoreError> {
    sql::execute(
        conn,
        "UPDATE campaigns SET cost_per_test = ?, worker_seconds = worker_seconds + ?, \
         reported_s1 = reported_s1 + ? WHERE id = ?",
        params![
            charge.cost_per_test,
            charge.worker_seconds,
            charge.reported_s1,
            campaign
        ],
    )?;
    Ok(())
}

/// A fold's result as the campaign's row keeps it.
pub struct FoldState<'a> {
    pub fold: &'a PrefixFold,
    /// The bound on the failure mass outside the library, where there is one.
    pub upper: Option<f64>,
    /// An anytime campaign's confidence sequence `[low, high]`.
    pub sequence: Option<(f64, f64)>,
    pub status: CampaignStatus,
    /// Why the campaign stopped, when it did.
    pub detail: Option<&'a str>,
}

/// Writes a fold's state and the report's `charge` (one update of the
/// row for both: it has 51 columns, and the writer updates it for every
/// report).
pub fn store_fold(
    conn: &Connection,
    campaign: i64,
    state: &FoldState<'_>,
    charge: Option<Charge>,
) -> Result<(), StoreError> {
    let FoldState {
        fold,
        upper,
        sequence,
        status,
        detail,
    } = *state;
    let (s1, s2) = fold.estimator.sums();
    let charged = charge.is_some();
    let charge = charge.unwrap_or(Charge {
        cost_per_test: None,
        worker_seconds: 0.0,
        reported_s1: 0.0,
    });
    sql::execute(
        conn,
        "UPDATE campaigns SET indices = ?, tests = ?, events = ?, invalid = ?, s1 = ?, s2 = ?, \
         largest = ?, outside_tests = ?, outside_events = ?, outside_s1 = ?, outside_upper = ?, \
         outside_mismatches = ?, strata_epsilon = ?, sequence_low = ?, sequence_high = ?, \
         outside_s2 = CASE WHEN outside_s2 IS NULL THEN NULL ELSE ? END, \
         status = ?, status_detail = COALESCE(?, status_detail), \
         cost_per_test = CASE WHEN ? THEN ? ELSE cost_per_test END, \
         worker_seconds = worker_seconds + ?, reported_s1 = reported_s1 + ?, \
         updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now') WHERE id = ?",
        params![
            fold.indices as i64,
            fold.estimator.tests() as i64,
            fold.estimator.events() as i64,
            fold.invalid as i64,
            s1,
            s2,
            fold.estimator.largest_term(),
            fold.outside.tests as i64,
            fold.outside.events as i64,
            fold.outside.s1,
            upper,
            fold.outside.mismatches as i64,
            fold.strata,
            sequence.map(|s| s.0),
            sequence.map(|s| s.1),
            fold.outside.s2,
            status.as_str(),
            detail,
            charged,
            charge.cost_per_test,
            charge.worker_seconds,
            charge.reported_s1,
            campaign
        ],
    )?;
    Ok(())
}

/// An adaptive campaign's state after its stages were resolved, as its row
/// keeps it: the estimation tests' fold, the running stage and the counts
/// (`progress`), every test it used (`indices`) and its status.
pub struct StagesState<'a> {
    pub indices: u64,
    pub progress: &'a AdaptiveProgress,
    pub status: CampaignStatus,
    /// Why the campaign stopped, when it did.
    pub detail: Option<&'a str>,
    /// The campaign's confidence, of its outside bound.
    pub confidence: f64,
}

/// Writes an adaptive campaign's state after resolving stages.
pub fn store_stages(
    conn: &Connection,
    campaign: i64,
    state: &StagesState<'_>,
) -> Result<(), StoreError> {
    let p = state.progress;
    let fold = &p.fold;
    let (s1, s2) = fold.estimator.sums();
    let running = p.running;
    sql::execute(
        conn,
        "UPDATE campaigns SET indices = ?, tests = ?, events = ?, invalid = ?, s1 = ?, s2 = ?, \
         largest = ?, stage_start = ?, stage_end = ?, stage_kind = ?, library_tests = ?, \
         search_tests = ?, stages = ?, support = ?, outside_tests = ?, outside_events = ?, \
         outside_s1 = ?, outside_upper = ?, status = ?, \
         status_detail = COALESCE(?, status_detail), \
         updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now') WHERE id = ?",
        params![
            state.indices as i64,
            fold.estimator.tests() as i64,
            fold.estimator.events() as i64,
            fold.invalid as i64,
            s1,
            s2,
            fold.estimator.largest_term(),
            running.map(|r| r.0 as i64),
            running.map(|r| r.1 as i64),
            running.map(|r| r.2),
            p.library_tests as i64,
            p.search_tests as i64,
            p.stages as i64,
            p.support as i64,
            p.explored.tally.tests as i64,
            p.explored.tally.events as i64,
            p.explored.tally.s1,
            p.explored.upper(state.confidence),
            state.status.as_str(),
            state.detail,
            campaign
        ],
    )?;
    Ok(())
}

/// Deletes `campaign`'s history (an estimate that starts again).
pub fn delete_history(conn: &Connection, campaign: i64) -> Result<(), StoreError> {
    sql::execute(
        conn,
        "DELETE FROM history WHERE campaign_id = ?",
        [campaign],
    )?;
    Ok(())
}

/// The valid tests of `campaign`'s last stored history point, if any.
pub fn last_history_tests(conn: &Connection, campaign: i64) -> Result<Option<u64>, StoreError> {
    let last: Option<(i64,)> = sql::optional(
        conn,
        "SELECT tests FROM history WHERE campaign_id = ? ORDER BY indices DESC LIMIT 1",
        [campaign],
    )?;
    Ok(last.map(|(tests,)| tests as u64))
}

/// Stores the history points `course` of a campaign's prefix.
pub fn store_history(
    conn: &Connection,
    campaign: i64,
    course: &[(PrefixFold, Option<(f64, f64)>)],
) -> Result<(), StoreError> {
    if !course.is_empty() {
        let mut statement = conn.prepare_cached(
            "INSERT OR REPLACE INTO history (campaign_id, indices, tests, events, s1, s2, \
             outside_tests, outside_s1, sequence_low, sequence_high, outside_s2, folded_at) \
             VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
        )?;
        let now = crate::db::now_ms();
        for (state, sequence) in course {
            let (s1, s2) = state.estimator.sums();
            statement.execute(params![
                campaign,
                state.indices as i64,
                state.estimator.tests() as i64,
                state.estimator.events() as i64,
                s1,
                s2,
                state.outside.tests as i64,
                state.outside.s1,
                sequence.map(|s| s.0),
                sequence.map(|s| s.1),
                state.within_strata.then_some(state.outside.s2),
                now
            ])?;
        }
    }
    Ok(())
}

/// Campaign `campaign` switches to exploring nearly every test from its
/// first test not yet handed out (`next_index`, at least `folded`), once:
/// a switch made is never moved.
pub fn set_explore_from(conn: &Connection, campaign: i64, folded: u64) -> Result<(), StoreError> {
    sql::execute(
        conn,
        "UPDATE campaigns SET explore_from = MAX(next_index, ?) \
         WHERE id = ? AND explore_from IS NULL",
        params![folded as i64, campaign],
    )?;
    Ok(())
}

/// A stopped campaign's leases cancelled, and its audits of tests past the
/// stop index `stop` set aside (they check tests that no longer count); a
/// noisy program's sampled audits before it too, which the stop did not
/// wait for ([`bounds`]) and nobody runs once it has stopped.
pub(crate) fn close_stopped(conn: &Connection, campaign: i64, stop: u64) -> Result<(), StoreError> {
    leases::cancel_active(conn, campaign)?;
    sql::execute(
        conn,
        &format!(
            "UPDATE audits SET state = {AUDIT_PAST} WHERE campaign_id = ?1 AND state IN {} \
             AND (test_index >= ?2 OR (NOT owed AND \
               (SELECT vehicle_noise FROM campaigns WHERE id = ?1)))",
            crate::store::states::AUDIT_OPEN
        ),
        [campaign, stop as i64],
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::db::{Database, Durability};
    use crate::store::audits::{self, NewAudit};
    use crate::store::campaigns;

    #[tokio::test]
    async fn an_open_audit_holds_the_frontier_unless_the_program_is_noisy() {
        let dir = tempfile::tempdir().unwrap();
        let url = format!("sqlite://{}", dir.path().join("db.sqlite").display());
        let db = Database::open(&url, Durability::Full).await.unwrap();
        db.write(|conn| -> Result<(), StoreError> {
            for noise in [0, 1] {
                conn.execute_batch(&format!(
                    "INSERT INTO campaigns (case_name, preset, method, exposure_name, \
                     exposure_fingerprint, vut, epsilon, beta, confidence, n_min, min_events, \
                     max_tests, seed, status, next_index, requires, vehicle_noise) \
                     VALUES ('cut-in', 'paper-code', 'library', 'builtin', 'fp', \
                     '{{\"external\":\"p\"}}', 0.1, 0.2, 0.9, 100, 10, 1000000, 7, 'running', \
                     20, 'p:cut-in:step', {noise})"
                ))
                .map_err(StoreError::from)?;
            }
            for id in [1, 2] {
                let audit = NewAudit {
                    test_index: 5,
                    reason: "sample",
                    first_outcome: "none".into(),
                    owed: false,
                };
                audits::insert(conn, id, "a", &[audit])?;
            }
            // A deterministic program's test 5 waits for two workers to
            // agree on it; a noisy program's first run stands.
            assert_eq!(bounds(conn, &campaigns::get(conn, 1)?)?.frontier, 5);
            assert_eq!(bounds(conn, &campaigns::get(conn, 2)?)?.frontier, 20);
            // An audit a dodger owes holds a noisy program's prefix too.
            let owed = NewAudit {
                test_index: 12,
                reason: "sample",
                first_outcome: "none".into(),
                owed: true,
            };
            audits::insert(conn, 2, "a", &[owed])?;
            assert_eq!(bounds(conn, &campaigns::get(conn, 2)?)?.frontier, 12);
            // Stopped at 15: the noisy campaign's sampled audit before the
            // stop is set aside with the rest; the deterministic one's
            // audit, which the stop waited for, is not touched.
            close_stopped(conn, 1, 15)?;
            close_stopped(conn, 2, 15)?;
            assert!(audits::open_id_at(conn, 1, 5)?.is_some());
            assert_eq!(audits::open_id_at(conn, 2, 5)?, None);
            assert!(audits::open_id_at(conn, 2, 12)?.is_some());
            Ok(())
        })
        .await
        .unwrap();
    }
}
