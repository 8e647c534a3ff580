//! A report checked for shape before anything is stored: its range, its
//! size (at most [`MAX_REPORT_TESTS`] tests, [`MAX_REPORT_EVENTS`] events
//! and [`MAX_REPORT_INVALID`] invalid tests), the effort it claims, and its
//! outcomes sorted, disjoint and inside the range.

use crate::error::ServiceError;
use tslg_api::{
    ResultReport, MAX_INVALID_REASON, MAX_REPORT_EVENTS, MAX_REPORT_INVALID, MAX_REPORT_TESTS,
    MAX_THREADS,
};
use tslg_method::number::Num;
use tslg_method::prefix::SparseOutcome;

/// Longest a report may say it took, in seconds (a day): with the
/// attempt's age it keeps the cost per test, and so the fairness turn it
/// sets, finite.
pub const MAX_COMPUTE_SECONDS: f64 = 86_400.0;

/// A report checked for shape: sorted, disjoint, inside its range, within
/// the size limits.
#[derive(Debug, Clone)]
pub struct CheckedReport {
    pub from: u64,
    pub to: u64,
    /// Events, sorted by index.
    pub events: Vec<(u64, f64)>,
    /// Events and invalid tests, sorted by index.
    pub outcomes: Vec<(u64, SparseOutcome)>,
    /// Invalid tests with their reasons, sorted by index.
    pub reasons: Vec<(u64, String)>,
}

pub fn check_report(report: &ResultReport) -> Result<CheckedReport, ServiceError> {
    let bad = |m: String| Err(ServiceError::Unprocessable(m));
    if report.from >= report.to {
        return bad(format!(
            "empty range: from {} must be < to {}",
            report.from, report.to
        ));
    }
    if report.to > i64::MAX as u64 {
        return bad(format!("to {} is out of range", report.to));
    }
    if report.to - report.from > MAX_REPORT_TESTS {
        return bad(format!(
            "the range {}..{} covers {} tests; a report covers at most {MAX_REPORT_TESTS}: \
             report it in parts",
            report.from,
            report.to,
            report.to - report.from
        ));
    }
    if !(report.compute_seconds.is_finite()
        && (0.0..=MAX_COMPUTE_SECONDS).contains(&report.compute_seconds))
    {
        return bad(format!(
            "compute_seconds = {} must be in [0, {MAX_COMPUTE_SECONDS}]",
            Num(report.compute_seconds)
        ));
    }
    if !(1..=MAX_THREADS).contains(&report.threads) {
        return bad(format!(
            "threads = {} must be in 1..={MAX_THREADS}",
            report.threads
        ));
    }
    let mut events = report.event_list().map_err(ServiceError::Unprocessable)?;
    if events.len() > MAX_REPORT_EVENTS {
        return bad(format!(
            "the report lists {} events; at most {MAX_REPORT_EVENTS} per report: report the \
             range in parts",
            events.len()
        ));
    }
    if report.invalid.len() > MAX_REPORT_INVALID {
        return bad(format!(
            "the report lists {} invalid tests; at most {MAX_REPORT_INVALID} per report: \
             report the range in parts",
            report.invalid.len()
        ));
    }
    if let Some(&(index, weight)) = events.iter().find(|(_, w)| !(w.is_finite() && *w >= 0.0)) {
        return bad(format!(
            "event at test {index} has weight {}; weights are finite and ≥ 0",
            Num(weight)
        ));
    }
    events.sort_by_key(|&(i, _)| i);
    let mut outcomes = Vec::with_capacity(events.len() + report.invalid.len());
    outcomes.extend(events.iter().map(|&(i, w)| (i, SparseOutcome::Event(w))));
    let mut reasons = Vec::with_capacity(report.invalid.len());
    for i in &report.invalid {
        if i.reason.len() > MAX_INVALID_REASON {
            return bad(format!(
                "the reason for invalid test {} exceeds {MAX_INVALID_REASON} bytes",
                i.index
            ));
        }
        outcomes.push((i.index, SparseOutcome::Invalid));
        reasons.push((i.index, i.reason.clone()));
    }
    outcomes.sort_by_key(|&(i, _)| i);
    for pair in outcomes.windows(2) {
        if pair[0].0 == pair[1].0 {
            return bad(format!(
                "test {} is reported more than once in this report",
                pair[0].0
            ));
        }
    }
    if let Some(&(i, _)) = outcomes
        .iter()
        .find(|&&(i, _)| i < report.from || i >= report.to)
    {
        return bad(format!(
            "test {i} lies outside the reported range {}..{}",
            report.from, report.to
        ));
    }
    reasons.sort_by_key(|(i, _)| *i);
    check_near_misses(report)?;
    Ok(CheckedReport {
        from: report.from,
        to: report.to,
        events,
        outcomes,
        reasons,
    })
}

/// Near misses: at most one per test of the range, in increasing index,
/// each criticality a number in `[0, 1]`.
fn check_near_misses(report: &ResultReport) -> Result<(), ServiceError> {
    let bad = |m: String| Err(ServiceError::Unprocessable(m));
    let mut last = None;
    for m in &report.near_misses {
        if m.index < report.from || m.index >= report.to {
            return bad(format!(
                "near miss at test {} lies outside the reported range {}..{}",
                m.index, report.from, report.to
            ));
        }
        if last.is_some_and(|l| m.index <= l) {
            return bad(format!(
                "near misses must be in increasing index; test {} follows {}",
                m.index,
                last.unwrap_or_default()
            ));
        }
        if !(0.0..=1.0).contains(&m.criticality) {
            return bad(format!(
                "near miss at test {} has criticality {}; it must be in [0, 1]",
                m.index,
                Num(m.criticality)
            ));
        }
        last = Some(m.index);
    }
    Ok(())
}
