//! Checking a report on a built-in vehicle by running its tests again.
//!
//! A built-in vehicle is deterministic: test `i` of a campaign is a pure
//! function of the plan, the seed and `i` (SPEC §7), so the coordinator can
//! run any reported test itself and compare. A grid case runs each cell
//! once and remembers it, so a check costs a draw and a look-up.
//!
//! On a library campaign whose exploring tests the fold counts, every test
//! of the new part is replayed (the fold needs each test's draw anyway).
//! That is the coordinator's largest cost on a high-event campaign, so the
//! range is split into blocks run on rayon's pool, each walking the
//! report's sorted outcomes with a cursor (no search per test); the blocks
//! are joined in index order, so the first contradiction reported is the
//! lowest-indexed one whatever the scheduling.

use crate::audit::Mismatch;
use crate::report_check::CheckedReport;
use crate::store::audits;
use rayon::prelude::*;
use std::panic::{catch_unwind, AssertUnwindSafe};
use tslg_method::prefix::SparseOutcome;
use tslg_method::registry::CampaignTests;

/// Tests per block of a full replay: large enough that a block's overhead
/// (a task, one binary search) is negligible against its ~10⁴ draws, small
/// enough that a report of 65,536 events spreads over every core.
const REPLAY_BLOCK: u64 = 8192;

/// What the coordinator's own runs of a report gave.
#[derive(Debug, Default)]
pub struct Verified {
    /// The first contradiction, if any.
    pub mismatch: Option<Mismatch>,
    /// The tests of the report's range that explore outside the library,
    /// when every test was run (a library campaign of a grid case): the
    /// fold then need not draw them again.
    pub explored: Option<Explored>,
}

/// The exploring tests of `from..to`, sorted.
#[derive(Debug, Clone, PartialEq)]
pub struct Explored {
    pub from: u64,
    pub to: u64,
    pub tests: Vec<u64>,
}

/// The coordinator's outcome of test `index`: its replay (invalid when the
/// simulation panics, as the worker's did if it reported invalid); `None`
/// when it cannot run the test.
fn replayed(tests: &dyn CampaignTests, index: u64) -> Option<Option<SparseOutcome>> {
    match catch_unwind(AssertUnwindSafe(|| tests.replay(index))) {
        Ok(Some(outcome)) => Some(
            outcome
                .event
                .then_some(SparseOutcome::Event(outcome.weight)),
        ),
        Ok(None) => None,
        Err(_) => Some(Some(SparseOutcome::Invalid)),
    }
}

/// Tests `from..to` replayed with whether each explores, in batches where
/// the case has them; a batch that panics is replayed test by test, which
/// finds the test that does. `None` when a test cannot be run here.
fn replayed_explored_span(
    tests: &dyn CampaignTests,
    from: u64,
    to: u64,
) -> Option<Vec<(Option<SparseOutcome>, bool)>> {
    let batched = catch_unwind(AssertUnwindSafe(|| tests.replay_explored_span(from, to)));
    match batched {
        Ok(Some(outcomes)) if outcomes.len() as u64 == to - from => Some(
            outcomes
                .into_iter()
                .map(|(o, explores)| (o.event.then_some(SparseOutcome::Event(o.weight)), explores))
                .collect(),
        ),
        Ok(None) => None,
        _ => (from..to).map(|i| replayed_explored(tests, i)).collect(),
    }
}

/// Test `index` replayed with whether it explores: `None` when it cannot be
/// run here.
fn replayed_explored(
    tests: &dyn CampaignTests,
    index: u64,
) -> Option<(Option<SparseOutcome>, bool)> {
    match catch_unwind(AssertUnwindSafe(|| tests.replay_explored(index))) {
        Ok(Some((outcome, explores))) => Some((
            outcome
                .event
                .then_some(SparseOutcome::Event(outcome.weight)),
            explores,
        )),
        Ok(None) => None,
        Err(_) => Some((Some(SparseOutcome::Invalid), tests.explores(index))),
    }
}

/// Two outcomes are the same when their kinds are and, for events, their
/// weights to the bit.
fn same(a: Option<SparseOutcome>, b: Option<SparseOutcome>) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(SparseOutcome::Invalid), Some(SparseOutcome::Invalid)) => true,
        (Some(SparseOutcome::Event(x)), Some(SparseOutcome::Event(y))) => {
            x.to_bits() == y.to_bits()
        }
        _ => false,
    }
}

fn contradiction(
    index: u64,
    reported: Option<SparseOutcome>,
    own: Option<SparseOutcome>,
) -> Option<Mismatch> {
    (!same(own, reported)).then(|| Mismatch {
        index,
        reported: audits::encode(reported),
        replayed: audits::encode(own),
    })
}

/// How one block of a full replay ended.
enum Block {
    /// Every test agreed; these explore.
    Agreed(Vec<u64>),
    Contradicted(Mismatch),
    /// A test cannot be replayed here: nothing is checked.
    Unreplayable,
}

/// Replays every test of `from..to` with `replay(start, end)` (each test's
/// outcome and whether it explores, for a block of tests) and compares it
/// with `outcomes`, the report's sorted non-quiet outcomes (those outside
/// the range are ignored).
fn replay_every_test<F>(
    outcomes: &[(u64, SparseOutcome)],
    from: u64,
    to: u64,
    replay: F,
) -> Verified
where
    F: Fn(u64, u64) -> Option<Vec<(Option<SparseOutcome>, bool)>> + Sync,
{
    let blocks = to.saturating_sub(from).div_ceil(REPLAY_BLOCK);
    let run_block = |b: u64| {
        let start = from + b * REPLAY_BLOCK;
        let end = (start + REPLAY_BLOCK).min(to);
        let first = outcomes.partition_point(|o| o.0 < start);
        let mut listed = outcomes[first..]
            .iter()
            .take_while(|o| o.0 < end)
            .peekable();
        let Some(replayed) = replay(start, end).filter(|r| r.len() as u64 == end - start) else {
            return Block::Unreplayable;
        };
        let mut explored = Vec::new();
        for (index, (own, explores)) in (start..end).zip(replayed) {
            let reported = listed.next_if(|o| o.0 == index).map(|o| o.1);
            if let Some(mismatch) = contradiction(index, reported, own) {
                return Block::Contradicted(mismatch);
            }
            if explores {
                explored.push(index);
            }
        }
        Block::Agreed(explored)
    };
    // One block runs here: handing it to the pool would cost more.
    let results: Vec<Block> = if blocks <= 1 {
        (0..blocks).map(run_block).collect()
    } else {
        (0..blocks).into_par_iter().map(run_block).collect()
    };
    let mut tests = Vec::new();
    for block in results {
        match block {
            Block::Agreed(explored) => tests.extend(explored),
            Block::Contradicted(mismatch) => {
                return Verified {
                    mismatch: Some(mismatch),
                    explored: None,
                }
            }
            Block::Unreplayable => return Verified::default(),
        }
    }
    Verified {
        mismatch: None,
        explored: Some(Explored { from, to, tests }),
    }
}

/// Runs again, on the coordinator, the tests `new_from..to` of a report on
/// a built-in vehicle (the part it adds): on a library campaign whose
/// exploring tests the fold counts, every test (the fold needs each test's
/// draw anyway, and a grid case remembers each cell's outcome, so checking
/// all costs no more); else every event and invalid test and the tests
/// `chosen` (sorted) among the others. CPU work: call off the async runtime.
pub fn verify_builtin(
    tests: &dyn CampaignTests,
    report: &CheckedReport,
    new_from: u64,
    chosen: &[u64],
) -> Verified {
    if tests.outside_mass().is_some() {
        return replay_every_test(&report.outcomes, new_from, report.to, |from, to| {
            replayed_explored_span(tests, from, to)
        });
    }
    let listed = report
        .outcomes
        .iter()
        .filter(|o| o.0 >= new_from)
        .map(|&(i, o)| (i, Some(o)));
    // The chosen tests the report lists nothing for, by walking both
    // sorted lists together.
    let mut reported = report.outcomes.iter().map(|o| o.0).peekable();
    let quiet = chosen
        .iter()
        .copied()
        .filter(|&i| {
            while reported.next_if(|&r| r < i).is_some() {}
            reported.peek() != Some(&i)
        })
        .map(|i| (i, None));
    let checks: Vec<(u64, Option<SparseOutcome>)> = listed.chain(quiet).collect();
    // In batches where the case has them; a batch that panics is replayed
    // test by test, which finds the test that does.
    let indices: Vec<u64> = checks.iter().map(|c| c.0).collect();
    let batched = catch_unwind(AssertUnwindSafe(|| tests.replay_many(&indices)))
        .ok()
        .flatten()
        .filter(|outcomes| outcomes.len() == indices.len());
    for (k, (index, outcome)) in checks.into_iter().enumerate() {
        let own = match &batched {
            Some(outcomes) => Some(
                outcomes[k]
                    .event
                    .then_some(SparseOutcome::Event(outcomes[k].weight)),
            ),
            None => replayed(tests, index),
        };
        let Some(own) = own else {
            return Verified::default();
        };
        if let Some(mismatch) = contradiction(index, outcome, own) {
            return Verified {
                mismatch: Some(mismatch),
                explored: None,
            };
        }
    }
    Verified::default()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A block replay from a replay of each test.
    fn per_test<F>(
        replay: F,
    ) -> impl Fn(u64, u64) -> Option<Vec<(Option<SparseOutcome>, bool)>> + Sync
    where
        F: Fn(u64) -> Option<(Option<SparseOutcome>, bool)> + Sync,
    {
        move |from, to| (from..to).map(&replay).collect()
    }

    /// A made-up campaign: test `i` is an event of weight `i` when `i % 7
    /// == 0`, invalid when `i % 11 == 0`, and explores when `i % 5 == 0`.
    fn truth(i: u64) -> (Option<SparseOutcome>, bool) {
        let outcome = if i.is_multiple_of(11) {
            Some(SparseOutcome::Invalid)
        } else if i.is_multiple_of(7) {
            Some(SparseOutcome::Event(i as f64))
        } else {
            None
        };
        (outcome, i.is_multiple_of(5))
    }

    fn honest(from: u64, to: u64) -> Vec<(u64, SparseOutcome)> {
        (from..to)
            .filter_map(|i| truth(i).0.map(|o| (i, o)))
            .collect()
    }

    #[test]
    fn an_honest_report_over_many_blocks_gives_every_exploring_test_in_order() {
        let (from, to) = (1_000, 1_000 + 5 * REPLAY_BLOCK + 17);
        let verified = replay_every_test(&honest(from, to), from, to, per_test(|i| Some(truth(i))));
        assert!(verified.mismatch.is_none());
        let explored = verified.explored.unwrap();
        let expected: Vec<u64> = (from..to).filter(|i| i % 5 == 0).collect();
        assert_eq!((explored.from, explored.to), (from, to));
        assert_eq!(explored.tests, expected);
        // Outcomes before the new part are ignored, not misread.
        let verified = replay_every_test(&honest(0, to), from, to, per_test(|i| Some(truth(i))));
        assert_eq!(verified.explored.unwrap().tests, expected);
    }

    #[test]
    fn the_first_contradiction_is_the_lowest_whatever_block_finds_it() {
        let (from, to) = (0, 4 * REPLAY_BLOCK);
        let mut lies = honest(from, to);
        // A hidden event in the last block, a forged one in the second.
        let hidden = (3 * REPLAY_BLOCK..to)
            .find(|i| i % 7 == 0 && i % 11 != 0)
            .unwrap();
        lies.retain(|o| o.0 != hidden);
        let forged = REPLAY_BLOCK + 1;
        assert!(truth(forged).0.is_none());
        lies.push((forged, SparseOutcome::Event(1.0)));
        lies.sort_by_key(|o| o.0);
        let verified = replay_every_test(&lies, from, to, per_test(|i| Some(truth(i))));
        let mismatch = verified.mismatch.unwrap();
        assert_eq!(mismatch.index, forged);
        assert_eq!(mismatch.replayed, "none");
        assert!(verified.explored.is_none());
        // A weight off by one bit is a contradiction too.
        let mut off = honest(from, to);
        let k = off.len() / 2;
        if let SparseOutcome::Event(w) = off[k].1 {
            off[k].1 = SparseOutcome::Event(f64::from_bits(w.to_bits() + 1));
        } else {
            off[k].1 = SparseOutcome::Event(1.0);
        }
        let verified = replay_every_test(&off, from, to, per_test(|i| Some(truth(i))));
        assert_eq!(verified.mismatch.unwrap().index, off[k].0);
    }

    #[test]
    fn a_test_that_cannot_be_replayed_checks_nothing() {
        let (from, to) = (0, 3 * REPLAY_BLOCK);
        let verified = replay_every_test(
            &honest(from, to),
            from,
            to,
            per_test(|i| (i != 2 * REPLAY_BLOCK + 3).then(|| truth(i))),
        );
        assert!(verified.mismatch.is_none() && verified.explored.is_none());
        let empty = replay_every_test(&[], 10, 10, per_test(|i| Some(truth(i))));
        assert_eq!(empty.explored.unwrap().tests, Vec::<u64>::new());
    }
}
