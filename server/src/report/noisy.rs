//! Audits of programs that are not bit-reproducible (`vehicle_noise`).
//!
//! Two honest runs of one test of such a program may differ, so the
//! deterministic rule (a third run decides, the minority is flagged) would
//! flag honest workers at every knife-edge scenario. Here an audit takes
//! one replica run and is settled by it: `agreed` when the two outcomes are
//! equal, `undecided` when they are not. The first run stands either way:
//! each test is one independent draw of the vehicle's outcome, so the
//! estimator is unchanged.
//!
//! What a replica says about the workers is weighed by statistics
//! ([`tslg_method::discordance`]): every audit the secret sample chose
//! (never one chosen for its outcome, which would make one side of its
//! disagreements certain) counts for the pair of workers, and a worker
//! whose disagreements lean to one side against its partners beyond
//! e-value [`FLAG_AT`] is flagged as a liar is, its results taken back.

use crate::error::ServiceError;
use crate::report::verdict::Verdict;
use crate::store::audits::{self, AuditRow, AuditState, RunColumn};
use crate::store::credentials;
use crate::store::discordance::{self, Pairs};
use rusqlite::Connection;
use tslg_method::discordance::{worker_evidence, FLAG_AT};
use tslg_method::test_pairing::PairTally;

/// Whether a stored outcome (`audits::encode`) is an event. An invalid
/// run counts as no event: under "same program" a pair of one event and
/// one invalid run is either worker's event alike, and a worker that
/// turned its events into invalid tests (which the estimate skips) would
/// otherwise hide them for free.
fn is_event(outcome: &str) -> bool {
    outcome.starts_with("event:")
}

/// Records the replica run of `worker` with `outcome` on `audit` of a
/// noisy campaign, counts it for the two workers, and flags a worker whose
/// evidence reached [`FLAG_AT`].
pub fn record_run(
    conn: &Connection,
    audit: &AuditRow,
    worker: &str,
    outcome: &str,
) -> Result<Verdict, ServiceError> {
    match audit.state {
        AuditState::Replica => {}
        // The campaign became noisy while two runs disagreed: the first
        // run stands, and the third decides nothing.
        AuditState::Tiebreak => {
            let (column, state) = (RunColumn::Third, AuditState::Undecided);
            audits::record_run(conn, audit.id, state, column, worker, outcome)?;
            return Ok(Verdict::Undecided);
        }
        _ => return Ok(Verdict::Pending),
    }
    let agreed = outcome == audit.first_outcome;
    let state = if agreed {
        AuditState::Agreed
    } else {
        AuditState::Undecided
    };
    audits::record_run(conn, audit.id, state, RunColumn::Replica, worker, outcome)?;
    let settled = if agreed {
        Verdict::Agreed
    } else {
        Verdict::Undecided
    };
    let (first_event, replica_event) = (is_event(&audit.first_outcome), is_event(outcome));
    // Only audits the secret sample chose, whatever the outcome: not an
    // event's for its weight, nor one a worker owed for a run it gave back
    // (drawn among its unresolved tests).
    if audit.reason != "sample" || audit.owed {
        return Ok(settled);
    }
    let tally = PairTally {
        compared: 1,
        first_closer: u64::from(first_event && !replica_event),
        second_closer: u64::from(replica_event && !first_event),
    };
    // One vote per principal: pairs are counted by principal (the replica
    // ran on another principal than the first run: `audits::runnable`).
    let first_principal = credentials::principal_of(conn, &audit.first_worker)?;
    let replica_principal = credentials::principal_of(conn, worker)?;
    discordance::record(
        conn,
        Pairs::Audits,
        &first_principal,
        &replica_principal,
        tally,
    )?;
    if first_event == replica_event {
        return Ok(settled);
    }
    // The stronger evidence of the two, when both reach the level.
    let mut suspects = Vec::new();
    for (suspect, principal) in [
        (audit.first_worker.as_str(), &first_principal),
        (worker, &replica_principal),
    ] {
        let (partners, compared) = discordance::partners_of(conn, Pairs::Audits, principal)?;
        suspects.push((worker_evidence(&partners), suspect, partners, compared));
    }
    suspects.sort_by(|a, b| b.0.total_cmp(&a.0));
    if let Some((evidence, suspect, partners, compared)) = suspects.into_iter().next() {
        if evidence >= FLAG_AT {
            let own: u64 = partners.iter().map(|p| p.own_event).sum();
            let theirs: u64 = partners.iter().map(|p| p.partner_event).sum();
            let detail = format!(
                "worker `{suspect}` runs a program that behaves unlike the other workers': of \
                 {compared} sampled audits of noisy programs compared with {} other workers, \
                 {} differed, and it found the event in {own} of them, its partners in \
                 {theirs} (evidence {evidence:.3e} ≥ {FLAG_AT:e}: a false flag at most once in \
                 10⁴ honest workers; docs/statistics.md, \"Noisy vehicles\")",
                partners.len(),
                own + theirs
            );
            return Ok(Verdict::Liar {
                liar: suspect.to_owned(),
                detail,
            });
        }
    }
    Ok(settled)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::db::{Database, Durability};
    use crate::store::audits::{AuditRow, NewAudit};
    use crate::store::error::StoreError;

    /// A campaign, and a function that stores an audit of `first`'s
    /// outcome at a fresh test and runs it as `replica` with `outcome`.
    fn audit_and_run(
        conn: &rusqlite::Connection,
        index: u64,
        (first, first_outcome): (&str, &str),
        (replica, outcome): (&str, &str),
        reason: &'static str,
        owed: bool,
    ) -> Result<Verdict, ServiceError> {
        audits::insert(
            conn,
            1,
            first,
            &[NewAudit {
                test_index: index,
                reason,
                first_outcome: first_outcome.into(),
                owed,
            }],
        )?;
        let id = audits::open_id_at(conn, 1, index)?.expect("the audit is open");
        let audit: AuditRow = audits::get(conn, id)?;
        record_run(conn, &audit, replica, outcome)
    }

    const EVENT: &str = "event:3ff0000000000000";

    #[tokio::test]
    async fn a_worker_is_flagged_when_its_sampled_disagreements_lean_one_way_against_two_partners()
    {
        let dir = tempfile::tempdir().unwrap();
        let url = format!("sqlite://{}", dir.path().join("db.sqlite").display());
        let db = Database::open(&url, Durability::Full).await.unwrap();
        db.write(|conn| -> Result<(), ServiceError> {
            conn.execute_batch(
                "INSERT INTO campaigns (case_name, preset, method, exposure_name, \
                 exposure_fingerprint, vut, epsilon, beta, confidence, n_min, min_events, \
                 max_tests, seed, status, next_index, requires, vehicle_noise) \
                 VALUES ('cut-in', 'paper-code', 'library', 'builtin', 'fp', \
                 '{\"external\":\"p\"}', 0.1, 0.2, 0.9, 100, 10, 1000000, 7, 'running', \
                 0, 'p:cut-in:step', 1)",
            )
            .map_err(StoreError::from)?;
            let mut index = 0;
            let mut run = |first: (&str, &str), replica: (&str, &str), reason, owed| {
                index += 1;
                audit_and_run(conn, index, first, replica, reason, owed)
            };
            // Neither a weight audit nor an owed one counts, whatever it says.
            for _ in 0..20 {
                assert_eq!(
                    run(("a", "none"), ("b", EVENT), "weight", false)?,
                    Verdict::Undecided
                );
                assert_eq!(
                    run(("a", "none"), ("c", EVENT), "sample", true)?,
                    Verdict::Undecided
                );
            }
            assert_eq!(discordance::partners_of(conn, Pairs::Audits, "a")?.1, 0);
            // Agreement is counted but proves nothing.
            assert_eq!(
                run(("a", "none"), ("b", "none"), "sample", false)?,
                Verdict::Agreed
            );
            // `a` on the no-event side: 17 against `b` (invalid counts as
            // no event) and 16 against `c` is not enough (leaving `b` out,
            // 16 pairs give E(0, 16) = 9.2e3)...
            for _ in 0..17 {
                assert_eq!(
                    run(("a", "invalid"), ("b", EVENT), "sample", false)?,
                    Verdict::Undecided
                );
            }
            for _ in 0..16 {
                assert_eq!(
                    run(("c", EVENT), ("a", "none"), "sample", false)?,
                    Verdict::Undecided
                );
            }
            let (pairs, compared) = discordance::partners_of(conn, Pairs::Audits, "a")?;
            assert_eq!(compared, 34);
            assert!(worker_evidence(&pairs) < FLAG_AT);
            // ... the 17th against `c` is: `a` is flagged, not `c`, whose
            // one partner proves nothing either way.
            match run(("c", EVENT), ("a", "none"), "sample", false)? {
                Verdict::Liar { liar, detail } => {
                    assert_eq!(liar, "a");
                    assert!(detail.contains("of 35 sampled audits"), "{detail}");
                    assert!(
                        detail.contains("in 0 of them, its partners in 34"),
                        "{detail}"
                    );
                }
                other => panic!("{other:?}"),
            }
            let (c_pairs, _) = discordance::partners_of(conn, Pairs::Audits, "c")?;
            assert!(worker_evidence(&c_pairs) < 2.0, "{c_pairs:?}");
            // An operator who clears the flag clears the counts.
            discordance::forget(conn, "a")?;
            assert_eq!(
                discordance::partners_of(conn, Pairs::Audits, "a")?,
                (Vec::new(), 0)
            );
            assert!(discordance::partners_of(conn, Pairs::Audits, "b")?
                .0
                .is_empty());
            Ok(())
        })
        .await
        .unwrap();
    }
}
