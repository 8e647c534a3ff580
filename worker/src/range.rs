//! Running a range of a lease's tests on the rayon pool: on the campaign's
//! built-in vehicle (span by span where the case runs tests in batches)
//! or on an external program, keeping the events, the invalid tests and
//! the near misses in index order.

use crate::external::{Program, ProgramRun};
use crate::prepared::PreparedCampaign;
use rayon::prelude::*;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, Ordering};
use tslg_api::{EventResult, InvalidResult, NearMiss};
use tslg_method::registry::TestOutcome;

/// Times a test whose simulation panics is tried before it is reported
/// `invalid`.
const INVALID_TRIES: usize = 2;

/// What a range of tests gave.
#[derive(Debug, Default)]
pub struct RangeRun {
    /// Tests `from..end` ran; `end < to` when an external program turned
    /// unhealthy (the rest is left for others) or the lease was stopped.
    pub end: u64,
    pub events: Vec<EventResult>,
    pub invalid: Vec<InvalidResult>,
    /// Tests without the event that came within the plan's `near_miss`
    /// (adaptive campaigns) or its `criticality_below` (others).
    pub near_misses: Vec<NearMiss>,
}

/// The tests a lease names (adaptive campaigns): the cell and weight of
/// each index from `first`.
pub struct Planned {
    pub first: u64,
    pub tests: Vec<(u64, f64)>,
    /// Criticality at or below which a test is reported as a near miss.
    pub near_miss: Option<f64>,
}

/// Runs tests `from..to` in parallel, on the campaign's built-in vehicle or
/// with `program`; returns the events and invalid tests in index order.
/// Once `go_on` turns false (the campaign stopped, the lease is gone) no
/// test starts any more: the range ends at the first test not run, and
/// only what ran before it is kept (the built-in vehicle's spans, each a
/// few microseconds, run to their end).
pub fn run_range(
    p: &PreparedCampaign,
    program: Option<&Program>,
    planned: Option<&Planned>,
    campaign: i64,
    (from, to): (u64, u64),
    go_on: &AtomicBool,
) -> RangeRun {
    if program.is_none() && planned.is_none() {
        if let Some(ran) = run_spans(p, from, to) {
            return ran;
        }
    }
    let level = planned.and_then(|p| p.near_miss).or(p.criticality_below);
    let near = |c: Option<f64>| level.is_some_and(|n| c.is_some_and(|c| c <= n));
    let mut found: Vec<(u64, ProgramRun)> = (from..to)
        .into_par_iter()
        .filter_map(|index| {
            if !go_on.load(Ordering::Relaxed) {
                return Some((index, ProgramRun::Skipped));
            }
            // A planned test's cell and weight: from an adaptive lease, or,
            // where criticalities are asked for, the campaign's own draw
            // (a cell's run gives its criticality).
            let cell = planned
                .map(|p| p.tests[(index - p.first) as usize])
                .or_else(|| {
                    p.criticality_below?;
                    program?;
                    let test = p.tests.planned(index)?;
                    Some((test.cell as u64, test.weight))
                });
            let run = match (program, cell) {
                (Some(program), None) => program.run_test(p.tests.as_ref(), campaign, index),
                (Some(program), Some((cell, weight))) => {
                    program.run_cell(p.tests.as_ref(), campaign, index, cell as usize, weight)
                }
                (None, cell) => match run_builtin(p, index, cell) {
                    Ok((outcome, criticality)) => ProgramRun::Done(outcome, criticality),
                    Err(reason) => ProgramRun::Invalid(reason),
                },
            };
            match run {
                ProgramRun::Done(outcome, c) if !outcome.event && !near(c) => None,
                other => Some((index, other)),
            }
        })
        .collect();
    found.sort_by_key(|(i, _)| *i);
    let end = found
        .iter()
        .find(|(_, run)| *run == ProgramRun::Skipped)
        .map_or(to, |(i, _)| *i);
    let mut ran = RangeRun {
        end,
        ..RangeRun::default()
    };
    for (index, run) in found.into_iter().take_while(|(i, _)| *i < end) {
        match run {
            ProgramRun::Done(outcome, _) if outcome.event => ran.events.push(EventResult {
                index,
                weight: outcome.weight,
            }),
            ProgramRun::Done(_, criticality) => ran.near_misses.push(NearMiss {
                index,
                criticality: criticality.unwrap_or(1.0),
            }),
            ProgramRun::Invalid(reason) => ran.invalid.push(InvalidResult { index, reason }),
            ProgramRun::Skipped => unreachable!("skipped tests are past the end"),
        }
    }
    ran
}

/// Tests per span of a built-in vehicle's range, each run in batches
/// where its case has them (`CampaignTests::run_span`).
const SPAN: u64 = 1024;

/// `from..to` on the campaign's built-in vehicle, span by span in parallel;
/// `None` when the case runs tests one by one, or when a span panicked
/// (the one-by-one path then retries each test and reports what fails).
fn run_spans(p: &PreparedCampaign, from: u64, to: u64) -> Option<RangeRun> {
    let starts: Vec<u64> = (from..to).step_by(SPAN as usize).collect();
    let spans: Option<Vec<Vec<EventResult>>> = starts
        .into_par_iter()
        .map(|start| {
            let end = (start + SPAN).min(to);
            let outcomes =
                catch_unwind(AssertUnwindSafe(|| p.tests.run_span(start, end))).ok()??;
            Some(
                (start..end)
                    .zip(outcomes)
                    .filter(|(_, o)| o.event)
                    .map(|(index, o)| EventResult {
                        index,
                        weight: o.weight,
                    })
                    .collect(),
            )
        })
        .collect();
    Some(RangeRun {
        end: to,
        events: spans?.into_iter().flatten().collect(),
        ..RangeRun::default()
    })
}

/// Runs test `index` on the built-in vehicle: drawn from the campaign's
/// plan, or on the `(cell, weight)` its lease names; a panic is tried
/// again, up to [`INVALID_TRIES`] times, before the test is `invalid`.
fn run_builtin(
    p: &PreparedCampaign,
    index: u64,
    cell: Option<(u64, f64)>,
) -> Result<(TestOutcome, Option<f64>), String> {
    let run = || match cell {
        None => p.tests.run_with(index, None).map(|o| (o, None)),
        Some((cell, weight)) => p
            .tests
            .run_cell(index, cell as usize, None)
            .map(|(event, c)| (TestOutcome { event, weight }, c)),
    };
    let mut last = String::new();
    for _ in 0..INVALID_TRIES {
        match catch_unwind(AssertUnwindSafe(run)) {
            Ok(Ok(outcome)) => return Ok(outcome),
            Ok(Err(e)) => return Err(e.0),
            Err(panic) => last = crate::panics::panic_message(panic.as_ref()),
        }
    }
    Err(format!(
        "the simulation failed {INVALID_TRIES} times: {last}"
    ))
}
