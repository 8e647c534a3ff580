//! Checking what workers report, the way volunteer computing does it.
//!
//! A worker is trusted with nothing the coordinator cannot check:
//!
//! - **Built-in vehicles** are run again by the coordinator
//!   ([`crate::report::replay`]): every reported event and invalid test, and a share
//!   (`--replay-share`, default 0.1) of the tests reported without an
//!   event, each drawn by a generator only this coordinator process knows
//!   (seeded by the operating system, [`crate::report::secret_sample`]), so a
//!   worker cannot tell which of its tests are checked. A grid case runs
//!   each cell once and remembers it, so a check costs a draw and a
//!   look-up.
//! - **External programs** run only on workers, so a share of their tests
//!   (`--audit-share`, default 0.01, by the same generator) and every event
//!   that would carry at least `--audit-weight-share` (0.05) of the estimate
//!   are run again by a different worker: BOINC's validation by
//!   replication. The campaign's prefix does not pass an audited test until
//!   two workers agree on it; when they disagree both results are held and
//!   a third worker decides.
//!
//! A program whose runs of one test may differ (`vehicle_noise`) is
//! audited by statistics instead ([`crate::report::noisy`]): one replica
//! run per audit, the first run stands, and a worker is flagged only when
//! its disagreements with the others lean to one side beyond doubt.
//!
//! A worker whose report the replay contradicts, that ends in the
//! minority of an audit, or whose noisy program behaves unlike the
//! others', is flagged ([`crate::report::flag::flag_worker`]): every request of its
//! is refused, every result it reported to a campaign that has not been
//! cancelled is taken back and leased to others, and a campaign that had
//! stopped on such results runs again. So the answer is the one honest
//! workers give, whatever the flagged worker did.

use crate::db::{now_ms, Database};
use crate::error::ServiceError;
use crate::report::check::CheckedReport;
use crate::report::explored::ExploredRanges;
use crate::report::flag::flag_worker;
use crate::report::fold::{fold_prefix, KnownExplored};
use crate::report::mismatch::{describe, Mismatch};
use crate::report::record::{at_lease_limit, check_effort, held_lease, stopped_ack, Recorded};
use crate::report::verdict::Verdict;
use crate::store::audits::{self, AuditRow, AuditState, NewAudit, RunColumn};
use crate::store::leases::LeaseState;
use crate::store::{campaigns, leases};
use rusqlite::Connection;
use std::sync::Arc;
use tslg_api::{CampaignStatus, ResultAck, ResultReport};
use tslg_method::prefix::SparseOutcome;
use tslg_method::registry::CampaignTests;

/// The audits of the part of an external program's report from `new_from`:
/// the tests `chosen` (the secret sample, sorted), and every event that would carry
/// at least `weight_share` of the estimate, `w ≥ share · (S₁ + w)` with
/// `S₁` the weights of the campaign's events recorded so far (folded or
/// not: the folded sum stalls while the prefix waits for audits, and would
/// make every later event look heavy).
pub fn choose_audits(
    report: &CheckedReport,
    new_from: u64,
    s1: f64,
    weight_share: f64,
    chosen: &[u64],
) -> Vec<NewAudit> {
    let outcome_at = |i: u64| {
        report
            .outcomes
            .binary_search_by_key(&i, |o| o.0)
            .ok()
            .map(|k| report.outcomes[k].1)
    };
    let heavy = |i: u64| match outcome_at(i) {
        Some(SparseOutcome::Event(w)) => weight_share < 1.0 && w >= weight_share * (s1 + w),
        _ => false,
    };
    let mut audits = Vec::new();
    let events = report
        .outcomes
        .iter()
        .map(|o| o.0)
        .filter(|&i| i >= new_from);
    let sampled = chosen.iter().copied().filter(|&i| i >= new_from);
    let mut indices: Vec<u64> = events.filter(|&i| heavy(i)).chain(sampled).collect();
    indices.sort_unstable();
    indices.dedup();
    for index in indices {
        audits.push(NewAudit {
            test_index: index,
            // A test the sample chose is a sample's, heavy or not: the
            // statistical audits of noisy programs count only tests chosen
            // whatever their outcome (`report/noisy.rs`).
            reason: if chosen.binary_search(&index).is_ok() {
                "sample"
            } else {
                "weight"
            },
            owed: false,
            first_outcome: audits::encode(outcome_at(index)),
        });
    }
    audits
}

/// Records the run of `worker` with `outcome` on `audit` (whose current
/// lease it held) and decides what two or three runs say.
pub fn record_run(
    conn: &Connection,
    audit: &AuditRow,
    worker: &str,
    outcome: &str,
) -> Result<Verdict, ServiceError> {
    let (state, column, verdict) = match audit.state {
        AuditState::Replica if outcome == audit.first_outcome => {
            (AuditState::Agreed, RunColumn::Replica, Verdict::Agreed)
        }
        AuditState::Replica => (AuditState::Tiebreak, RunColumn::Replica, Verdict::Pending),
        AuditState::Tiebreak => {
            let replica = audit.replica_outcome.as_deref().unwrap_or("");
            let replica_worker = audit.replica_worker.clone().unwrap_or_default();
            let detail = |liar: &str, said: &str, others: &str| {
                format!(
                    "worker `{liar}` reported {} for test {} of campaign {}, where two other \
                     workers found {}",
                    describe(said),
                    audit.test_index,
                    audit.campaign_id,
                    describe(others)
                )
            };
            if outcome == audit.first_outcome {
                let detail = detail(&replica_worker, replica, outcome);
                let verdict = Verdict::Liar {
                    liar: replica_worker,
                    detail,
                };
                (AuditState::Settled, RunColumn::Third, verdict)
            } else if outcome == replica {
                let detail = detail(&audit.first_worker, &audit.first_outcome, outcome);
                let liar = audit.first_worker.clone();
                (
                    AuditState::Settled,
                    RunColumn::Third,
                    Verdict::Liar { liar, detail },
                )
            } else {
                (AuditState::Undecided, RunColumn::Third, Verdict::Undecided)
            }
        }
        _ => return Ok(Verdict::Pending),
    };
    audits::record_run(conn, audit.id, state, column, worker, outcome)?;
    match &verdict {
        Verdict::Undecided => tracing::warn!(
            campaign = audit.campaign_id,
            test = audit.test_index,
            "three workers gave three outcomes; the first run stands"
        ),
        Verdict::Pending if state == AuditState::Tiebreak => tracing::warn!(
            campaign = audit.campaign_id,
            test = audit.test_index,
            first = %audit.first_worker,
            replica = worker,
            "two workers disagree; a third decides"
        ),
        _ => {}
    }
    Ok(verdict)
}

/// Records a run of an audit (a one-test lease with `audit_id`) and decides
/// the audit; a worker in the minority of three is flagged and its results
/// taken back. Then folds the prefix, which the audit may have held.
pub async fn record_audit_run(
    db: &Database,
    tests: Option<Arc<dyn CampaignTests>>,
    kept: Option<Arc<ExploredRanges>>,
    lease_id: i64,
    report: &Arc<ResultReport>,
    checked: &Arc<CheckedReport>,
) -> Result<Recorded, ServiceError> {
    let (report, checked) = (Arc::clone(report), Arc::clone(checked));
    db.write(move |conn| {
        record_audit_run_in(conn, tests, kept.as_deref(), lease_id, &report, &checked)
    })
    .await
}

/// [`record_audit_run`] on the writer connection.
fn record_audit_run_in(
    conn: &Connection,
    tests: Option<Arc<dyn CampaignTests>>,
    kept: Option<&ExploredRanges>,
    lease_id: i64,
    report: &ResultReport,
    checked: &CheckedReport,
) -> Result<Recorded, ServiceError> {
    let (lease, campaign) = held_lease(conn, lease_id, report)?;
    let (start, end) = (lease.start_index as u64, lease.end_index as u64);
    let audit = audits::get(conn, lease.audit_id.unwrap_or_default())?;
    if campaign.status.is_final()
        || lease.state != LeaseState::Active
        || audit.lease_id != Some(lease.id)
    {
        return Ok(Recorded {
            ack: stopped_ack(1, lease.resume_at as u64, end, campaign.status),
            stopped: None,
            campaign_id: campaign.id,
            partner_stopped: None,
            opens_work: false,
        });
    }
    check_effort(&lease, report, now_ms())?;
    if (checked.from, checked.to) != (start, end) {
        return Err(ServiceError::Unprocessable(format!(
            "lease {lease_id} is the audit run of test {start}: report {start}..{end}"
        )));
    }
    let outcome = audits::encode(checked.outcomes.first().map(|o| o.1));
    let verdict = if campaign.vehicle_noise {
        crate::report::noisy::record_run(conn, &audit, &report.worker, &outcome)?
    } else {
        record_run(conn, &audit, &report.worker, &outcome)?
    };
    leases::finish(conn, lease.id)?;
    crate::store::work_spans::insert(conn, &lease, true, (start, end))?;
    crate::store::standing::ran_audit(conn, &report.worker)?;
    if let Verdict::Liar { liar, detail } = &verdict {
        flag_worker(conn, liar, detail, campaign.id, start)?;
    }
    // The flag may have reset the campaign: fold from what is stored now.
    let campaign = campaigns::get(conn, campaign.id)?;
    // What the coordinator keeps for folds (the exploring tests of reports
    // it ran, an anytime campaign's sequences), so that the fold an audit
    // unblocks does not draw or fold again what it kept.
    let known = KnownExplored {
        replayed: None,
        kept,
    };
    let own = fold_prefix(conn, &campaign, tests, known, None, None)?;
    let (stopped, partner_stopped) = crate::report::pair_fold::fold_after(conn, &campaign, own)?;
    Ok(Recorded {
        ack: ResultAck {
            accepted: 1,
            duplicate: 0,
            ignored: 0,
            resume_at: end,
            lease_done: true,
            proceed: stopped.is_none(),
            campaign_status: stopped.unwrap_or(CampaignStatus::Running),
            next_lease: None,
        },
        stopped,
        campaign_id: campaign.id,
        partner_stopped,
        // An audit held the prefix: the campaign may lease again.
        opens_work: at_lease_limit(&campaign),
    })
}

/// Flags `worker` for `mismatch` (the coordinator's own run of a test it
/// reported gives another outcome) and takes back its results, in one
/// transaction.
pub async fn flag_for_mismatch(
    db: &Database,
    worker: &str,
    campaign: i64,
    mismatch: &Mismatch,
) -> Result<(), ServiceError> {
    let reason = format!("campaign {campaign}: {mismatch}");
    let (worker, index) = (worker.to_string(), mismatch.index);
    db.write(move |conn| flag_worker(conn, &worker, &reason, campaign, index))
        .await?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(from: u64, to: u64, outcomes: Vec<(u64, SparseOutcome)>) -> CheckedReport {
        CheckedReport {
            from,
            to,
            events: outcomes
                .iter()
                .filter_map(|&(i, o)| match o {
                    SparseOutcome::Event(w) => Some((i, w)),
                    SparseOutcome::Invalid => None,
                })
                .collect(),
            outcomes,
            reasons: Vec::new(),
        }
    }

    #[test]
    fn heavy_events_and_the_sample_are_audited_in_the_new_part_only() {
        let r = report(
            100,
            110,
            vec![
                (101, SparseOutcome::Event(0.5)),
                (103, SparseOutcome::Event(0.001)),
                (105, SparseOutcome::Invalid),
                (108, SparseOutcome::Event(2.0)),
            ],
        );
        // S₁ = 10: 0.5 carries 0.5/10.5 ≈ 4.8 % < 5 %, 2.0 carries 16.7 %.
        let audits = choose_audits(&r, 100, 10.0, 0.05, &[104]);
        let got: Vec<(u64, &str, &str)> = audits
            .iter()
            .map(|a| (a.test_index, a.reason, a.first_outcome.as_str()))
            .collect();
        assert_eq!(
            got,
            [
                (104, "sample", "none"),
                (108, "weight", "event:4000000000000000")
            ]
        );
        // Only from where the new part starts; an empty estimate makes
        // every event heavy.
        let audits = choose_audits(&r, 106, 0.0, 0.05, &[]);
        assert_eq!(
            audits.iter().map(|a| a.test_index).collect::<Vec<_>>(),
            [108]
        );
        assert!(choose_audits(&r, 100, 0.0, 1.0, &[]).is_empty());
        // A heavy event the sample also chose is the sample's.
        let audits = choose_audits(&r, 100, 10.0, 0.05, &[108]);
        assert_eq!(audits.len(), 1);
        assert_eq!((audits[0].test_index, audits[0].reason), (108, "sample"));
    }
}
