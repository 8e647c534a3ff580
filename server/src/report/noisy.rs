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
use crate::report::audit::Verdict;
use crate::store::audits::{self, AuditRow, AuditState, RunColumn};
use crate::store::discordance;
use rusqlite::Connection;
use tslg_method::discordance::{worker_evidence, FLAG_AT};

/// Whether a stored outcome (`audits::encode`) is an event; `None` for an
/// invalid test, which says nothing about the vehicle.
fn is_event(outcome: &str) -> Option<bool> {
    match outcome {
        "invalid" => None,
        other => Some(other.starts_with("event:")),
    }
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
    let (Some(first_event), Some(replica_event)) =
        (is_event(&audit.first_outcome), is_event(outcome))
    else {
        return Ok(settled);
    };
    if audit.reason != "sample" {
        return Ok(settled);
    }
    discordance::record(
        conn,
        &audit.first_worker,
        worker,
        first_event,
        replica_event,
    )?;
    if first_event == replica_event {
        return Ok(settled);
    }
    for suspect in [audit.first_worker.as_str(), worker] {
        let (partners, compared) = discordance::partners_of(conn, suspect)?;
        let evidence = worker_evidence(&partners);
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
