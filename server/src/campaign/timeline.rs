//! Where a campaign's wall time went (issue 68): from when each piece of
//! its work was leased and reported ([`crate::store::work_spans`]), the
//! workers busy on it over time, against the workers that ran it.
//!
//! A piece of work `from..to` of a lease began when the lease's attempt
//! was handed out, or at the lease's previous report if that was later (a
//! worker reports a long lease in pieces, running them one after another),
//! and ended at its report. Over `[t₀, t₁]`, `t₀` the first lease and `t₁`
//! the last report, `busy_share = Σ span / (W (t₁ − t₀))` with `W` the
//! workers that ran any of it: 1 when every one of them held its work all
//! the time, lower when they waited for leases, for audits of others or
//! for a stage's last test. Each bucket's `busy_workers` is the time its
//! spans overlap it over its length. A worker counts as busy while it holds
//! a piece of the campaign's work, whatever its threads.
//!
//! What it cannot show: work taken back from a flagged worker stays (it
//! was worker time), so `reported_tests` can add up to more than the
//! campaign's indices; and a history cut back (a guarded campaign's
//! estimate starting again, a flagged worker's results taken back) loses
//! the folds before the cut, so `folded` reads from the new start.

use crate::store::work_spans::WorkSpan;
use tslg_api::{CampaignTimeline, TimelineBucket};

/// Most buckets a timeline may ask for.
pub const MAX_BUCKETS: u32 = 1_000;

/// The timeline of campaign `campaign_id` from its spans (in lease, claim
/// and index order, as [`crate::store::work_spans::of`] reads them), `W`
/// workers, and the `(indices, folded_at)` of its history, in `buckets`
/// buckets.
pub fn timeline(
    campaign_id: i64,
    spans: &[WorkSpan],
    workers: u32,
    folds: &[(i64, i64)],
    buckets: u32,
) -> CampaignTimeline {
    let pieces = pieces(spans);
    let start = pieces.iter().map(|p| p.0).min().unwrap_or(0);
    let end = pieces.iter().map(|p| p.1).max().unwrap_or(start);
    let seconds = (end - start) as f64 / 1000.0;
    let seconds_of = |p: &(i64, i64, WorkSpan)| (p.1 - p.0) as f64 / 1000.0;
    let busy = pieces.iter().map(seconds_of).fold(0.0, |a, b| a + b);
    let audit = pieces
        .iter()
        .filter(|p| p.2.audit)
        .map(seconds_of)
        .fold(0.0, |a, b| a + b);
    let share = if workers > 0 && seconds > 0.0 {
        busy / (f64::from(workers) * seconds)
    } else {
        0.0
    };
    let count = if pieces.is_empty() {
        0
    } else {
        buckets.clamp(1, MAX_BUCKETS)
    };
    let width = (end - start).max(1) as f64 / f64::from(count.max(1));
    let mut out: Vec<TimelineBucket> = (0..count)
        .map(|k| TimelineBucket {
            from_seconds: f64::from(k) * width / 1000.0,
            to_seconds: f64::from(k + 1) * width / 1000.0,
            busy_workers: 0.0,
            audit_workers: 0.0,
            reported_tests: 0,
            folded: 0,
        })
        .collect();
    for &(from, to, span) in &pieces {
        let (a, b) = ((from - start) as f64, (to - start) as f64);
        let first = ((a / width) as usize).min(out.len() - 1);
        // A report at a bucket's end is in that bucket: buckets are
        // `(lo, hi]` for reports.
        let last = ((b / width).ceil() as usize)
            .saturating_sub(1)
            .clamp(first, out.len() - 1);
        for (k, bucket) in out.iter_mut().enumerate().take(last + 1).skip(first) {
            let (lo, hi) = (k as f64 * width, (k + 1) as f64 * width);
            let overlap = (b.min(hi) - a.max(lo)).max(0.0) / width;
            bucket.busy_workers += overlap;
            if span.audit {
                bucket.audit_workers += overlap;
            }
        }
        if !span.audit {
            out[last].reported_tests += (span.to_index - span.from_index) as u64;
        }
    }
    let final_bucket = out.len().saturating_sub(1);
    for (k, bucket) in out.iter_mut().enumerate() {
        // The fold of a report is written just after it, so the last
        // bucket holds every fold: the prefix as it stands.
        let at = if k == final_bucket {
            i64::MAX
        } else {
            start + (end - start) * (k as i64 + 1) / i64::from(count)
        };
        bucket.folded = folds
            .iter()
            .filter(|&&(_, folded_at)| folded_at <= at)
            .map(|&(indices, _)| indices.max(0) as u64)
            .max()
            .unwrap_or(0);
    }
    CampaignTimeline {
        campaign_id,
        seconds,
        workers,
        busy_worker_seconds: busy,
        audit_worker_seconds: audit,
        busy_share: share,
        reports: spans.len() as u64,
        buckets: out,
    }
}

/// Each span's `(began, ended, span)`: it began at its lease attempt's
/// claim or at the previous report of that attempt, whichever is later.
/// A worker holds the campaign's work or not: where its spans overlap (it
/// took its next lease before its last report reached the coordinator),
/// the later starts where the earlier ended, so that a worker is never
/// counted busy twice.
fn pieces(spans: &[WorkSpan]) -> Vec<(i64, i64, WorkSpan)> {
    let mut out = Vec::with_capacity(spans.len());
    let mut previous: Option<&WorkSpan> = None;
    for span in spans {
        let began = match previous {
            Some(p) if p.lease_id == span.lease_id && p.leased_at == span.leased_at => {
                p.reported_at.max(span.leased_at)
            }
            _ => span.leased_at,
        };
        // A report cannot precede its claim; clocks of one coordinator.
        out.push((began.min(span.reported_at), span.reported_at, *span));
        previous = Some(span);
    }
    out.sort_by_key(|&(began, ended, span)| (span.worker, began, ended));
    // Until when each worker, in turn, already held work.
    let mut held: Option<(u32, i64)> = None;
    for piece in &mut out {
        let until = match held {
            Some((worker, until)) if worker == piece.2.worker => until,
            _ => i64::MIN,
        };
        piece.0 = piece.0.max(until).min(piece.1);
        held = Some((piece.2.worker, until.max(piece.1)));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn span(lease_id: i64, worker: u32, range: (i64, i64), at: (i64, i64)) -> WorkSpan {
        WorkSpan {
            lease_id,
            worker,
            audit: false,
            from_index: range.0,
            to_index: range.1,
            leased_at: at.0,
            reported_at: at.1,
        }
    }

    #[test]
    fn two_workers_one_idle_half_the_time() {
        // Worker 0 holds work from 0 to 4 s (one lease reported in two
        // pieces: 0–2 s and 2–4 s); worker 1 from 2 to 4 s. Busy: 6
        // worker-seconds of 8.
        let spans = [
            span(1, 0, (0, 10), (1_000, 3_000)),
            span(1, 0, (10, 20), (1_000, 5_000)),
            span(2, 1, (20, 30), (3_000, 5_000)),
        ];
        let t = timeline(7, &spans, 2, &[(10, 3_000), (30, 5_000)], 2);
        assert_eq!(t.seconds, 4.0);
        assert_eq!(t.busy_worker_seconds, 6.0);
        assert_eq!(t.busy_share, 0.75);
        assert_eq!(t.reports, 3);
        let busy: Vec<f64> = t.buckets.iter().map(|b| b.busy_workers).collect();
        assert_eq!(busy, [1.0, 2.0]);
        let reported: Vec<u64> = t.buckets.iter().map(|b| b.reported_tests).collect();
        assert_eq!(reported, [10, 20]);
        let folded: Vec<u64> = t.buckets.iter().map(|b| b.folded).collect();
        assert_eq!(folded, [10, 30]);
    }

    #[test]
    fn a_lease_handed_out_again_starts_at_its_new_claim_and_audits_are_counted_apart() {
        let mut audit = span(3, 2, (5, 6), (2_000, 3_000));
        audit.audit = true;
        let spans = [
            span(1, 0, (0, 5), (0, 1_000)),
            // Attempt 2 of lease 1, claimed at 2 s by worker 1: it did not
            // run from worker 0's report at 1 s.
            span(1, 1, (5, 10), (2_000, 4_000)),
            audit,
        ];
        let t = timeline(1, &spans, 3, &[], 4);
        assert_eq!(t.busy_worker_seconds, 1.0 + 2.0 + 1.0);
        assert_eq!(t.audit_worker_seconds, 1.0);
        let audits: Vec<f64> = t.buckets.iter().map(|b| b.audit_workers).collect();
        assert_eq!(audits, [0.0, 0.0, 1.0, 0.0]);
        assert_eq!(t.buckets.iter().map(|b| b.reported_tests).sum::<u64>(), 10);
    }

    #[test]
    fn a_worker_that_took_its_next_lease_before_its_report_is_busy_once() {
        // Worker 0 claimed lease 2 at 1.5 s while lease 1 ran to 2 s.
        let spans = [
            span(1, 0, (0, 10), (0, 2_000)),
            span(2, 0, (10, 20), (1_500, 3_000)),
        ];
        let t = timeline(1, &spans, 1, &[], 3);
        assert_eq!(t.busy_worker_seconds, 3.0);
        assert_eq!(t.busy_share, 1.0);
        assert!(t
            .buckets
            .iter()
            .all(|b| (b.busy_workers - 1.0).abs() < 1e-12));
    }

    #[test]
    fn a_campaign_without_reports_has_an_empty_timeline() {
        let t = timeline(1, &[], 0, &[], 60);
        assert_eq!((t.seconds, t.busy_share, t.buckets.len()), (0.0, 0.0, 0));
    }
}
