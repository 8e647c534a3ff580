//! Checking a report on a built-in vehicle by running its tests again.
//!
//! A built-in vehicle is deterministic: test `i` of a campaign is a pure
//! function of the plan, the seed and `i` (SPEC §7), so the coordinator can
//! run any reported test itself and compare. A grid case runs each cell
//! once and remembers it, so a check costs a draw and a look-up.
//!
//! On a library campaign whose exploring tests the fold counts, every test
//! of the new part is replayed (the fold needs each test's draw anyway).
//! Else the report's events and invalid tests and a secret sample of the
//! rest are, walked together in index order, block by block
//! ([`check_sampled`]).
//! That is the coordinator's largest cost on a high-event campaign, so the
//! range is split into blocks run on rayon's pool, each walking the
//! report's sorted outcomes with a cursor (no search per test); the blocks
//! are joined in index order, so the first contradiction reported is the
//! lowest-indexed one whatever the scheduling.

use crate::report::check::CheckedReport;
use crate::report::explored::Explored;
use crate::report::mismatch::Mismatch;
use crate::report::replay_counts::{Place, ReplayCounts};
use crate::store::audits;
use rayon::prelude::*;
use std::panic::{catch_unwind, AssertUnwindSafe};
use tslg_method::prefix::SparseOutcome;
use tslg_method::registry::{CampaignTests, TestOutcome};

/// Tests per block of a full replay: large enough that a block's overhead
/// (a task, one binary search) is negligible against its ~10⁴ draws, small
/// enough that a report of 65,536 events spreads over every core.
const REPLAY_BLOCK: u64 = 8192;

/// [`verify_builtin`] with the report's secret sample drawn by
/// `pick(from, to)` (only when the check samples: a library campaign whose
/// exploring tests the fold counts has every test run), and counted in
/// `counts` as a check at `place`.
pub fn verify_counted(
    tests: &dyn CampaignTests,
    report: &CheckedReport,
    new_from: u64,
    pick: impl FnOnce(u64, u64) -> Vec<u64>,
    (counts, place): (&ReplayCounts, Place),
) -> Verified {
    let chosen = tests
        .outside_mass()
        .is_none()
        .then(|| pick(new_from, report.to));
    let (range, sampled) = chosen.as_ref().map_or((0, 0), |c| {
        (report.to.saturating_sub(new_from), c.len() as u64)
    });
    counts.record(place, range, sampled);
    verify_builtin(
        tests,
        report,
        new_from,
        chosen.as_deref().unwrap_or_default(),
    )
}

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

/// A replayed test's outcome as a report lists it: an event with its
/// weight, or nothing (quiet).
fn as_listed(outcome: TestOutcome) -> Option<SparseOutcome> {
    outcome
        .event
        .then_some(SparseOutcome::Event(outcome.weight))
}

/// The coordinator's outcome of test `index`: its replay (invalid when the
/// simulation panics, as the worker's did if it reported invalid); `None`
/// when it cannot run the test.
fn replayed(tests: &dyn CampaignTests, index: u64) -> Option<Option<SparseOutcome>> {
    match catch_unwind(AssertUnwindSafe(|| tests.replay(index))) {
        Ok(Some(outcome)) => Some(as_listed(outcome)),
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
                .map(|(o, explores)| (as_listed(o), explores))
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
        Ok(Some((outcome, explores))) => Some((as_listed(outcome), explores)),
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
    check_sampled(&report.outcomes, new_from..report.to, chosen, |indices| {
        replayed_block(tests, indices)
    })
}

/// Tests per block of a sampled replay: a block's indices, reported and
/// replayed outcomes stay in the cache (about 200 KB). Building them for a
/// whole report at once (hundreds of thousands of chosen tests, four
/// vectors) cost more than the replay itself: 60 → 40 ns a checked test.
const CHECK_BLOCK: usize = 4096;

/// The coordinator's outcomes of `indices`, in batches where the case has
/// them; a batch that panics, or a case without batches, is replayed test
/// by test, which finds the test that does. `None` when a test cannot be
/// run here.
fn replayed_block(
    tests: &dyn CampaignTests,
    indices: &[u64],
) -> Option<Vec<Option<SparseOutcome>>> {
    let batched = catch_unwind(AssertUnwindSafe(|| tests.replay_many(indices)))
        .ok()
        .flatten()
        .filter(|outcomes| outcomes.len() == indices.len());
    match batched {
        Some(outcomes) => Some(outcomes.into_iter().map(as_listed).collect()),
        None => indices.iter().map(|&i| replayed(tests, i)).collect(),
    }
}

/// Checks the tests of `range` that `outcomes` (the report's sorted
/// non-quiet outcomes) lists, and those of `chosen` (sorted) it lists
/// nothing for, which it says are quiet, against `replay(indices)`, block
/// by block in index order: the first contradiction is the lowest-indexed
/// one. (Outside `range` the report's outcomes are not at hand, so a chosen
/// test there could not be checked.)
fn check_sampled<F>(
    outcomes: &[(u64, SparseOutcome)],
    range: std::ops::Range<u64>,
    chosen: &[u64],
    replay: F,
) -> Verified
where
    F: Fn(&[u64]) -> Option<Vec<Option<SparseOutcome>>>,
{
    // Both lists cut to the range (the callers' samples are drawn within
    // it; the cut keeps that from being this walk's assumption).
    let first = outcomes.partition_point(|o| o.0 < range.start);
    let last = outcomes.partition_point(|o| o.0 < range.end);
    let mut listed = outcomes[first..last].iter().peekable();
    let first = chosen.partition_point(|&c| c < range.start);
    let last = chosen.partition_point(|&c| c < range.end);
    let mut chosen = chosen[first..last].iter().copied().peekable();
    let mut indices = Vec::with_capacity(CHECK_BLOCK);
    let mut reported = Vec::with_capacity(CHECK_BLOCK);
    loop {
        indices.clear();
        reported.clear();
        while indices.len() < CHECK_BLOCK {
            // The next test to check: a listed one or a chosen one, once
            // when it is both.
            let next = match (listed.peek().map(|o| o.0), chosen.peek().copied()) {
                (None, None) => break,
                (Some(l), Some(c)) => l.min(c),
                (Some(l), None) => l,
                (None, Some(c)) => c,
            };
            chosen.next_if_eq(&next);
            indices.push(next);
            reported.push(listed.next_if(|o| o.0 == next).map(|o| o.1));
        }
        if indices.is_empty() {
            return Verified::default();
        }
        let Some(own) = replay(&indices).filter(|own| own.len() == indices.len()) else {
            return Verified::default();
        };
        for ((&index, &reported), own) in indices.iter().zip(&reported).zip(own) {
            if let Some(mismatch) = contradiction(index, reported, own) {
                return Verified {
                    mismatch: Some(mismatch),
                    explored: None,
                };
            }
        }
    }
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

    /// A sampled replay from [`truth`].
    fn sampled_truth(indices: &[u64]) -> Option<Vec<Option<SparseOutcome>>> {
        Some(indices.iter().map(|&i| truth(i).0).collect())
    }

    #[test]
    fn a_sampled_replay_checks_each_listed_and_chosen_test_once_in_order() {
        let (from, to) = (500u64, 500 + 3 * CHECK_BLOCK as u64 * 7);
        // Chosen: every third test, so blocks hold both kinds and overlaps.
        let chosen: Vec<u64> = (from..to).filter(|i| i % 3 == 0).collect();
        let asked = std::sync::Mutex::new(Vec::new());
        let replay = |indices: &[u64]| {
            asked.lock().unwrap().extend_from_slice(indices);
            sampled_truth(indices)
        };
        // Outcomes outside the range are not checked, nor chosen tests
        // outside it.
        let wide: Vec<u64> = (0..to + 50).filter(|i| i % 3 == 0).collect();
        let verified = check_sampled(&honest(0, to + 50), from..to, &wide, replay);
        assert!(verified.mismatch.is_none() && verified.explored.is_none());
        let expected: Vec<u64> = (from..to)
            .filter(|&i| i % 3 == 0 || truth(i).0.is_some())
            .collect();
        assert_eq!(*asked.lock().unwrap(), expected);

        // A hidden event among the chosen tests and a forged one after it:
        // the hidden one, the lower, is reported whatever the blocks.
        let hidden = (from + 2 * CHECK_BLOCK as u64..to)
            .find(|i| i % 3 == 0 && matches!(truth(*i).0, Some(SparseOutcome::Event(_))))
            .unwrap();
        let mut lies = honest(from, to);
        lies.retain(|o| o.0 != hidden);
        let forged = (hidden + 1..to).find(|i| truth(*i).0.is_none()).unwrap();
        lies.push((forged, SparseOutcome::Event(1.0)));
        lies.sort_by_key(|o| o.0);
        let mismatch = check_sampled(&lies, from..to, &chosen, sampled_truth)
            .mismatch
            .unwrap();
        assert_eq!(
            (mismatch.index, mismatch.reported.as_str()),
            (hidden, "none")
        );
        // A hidden event no chosen test covers goes unseen: the sample's
        // price, which the share sets.
        let unseen = (from..to)
            .find(|i| i % 3 != 0 && matches!(truth(*i).0, Some(SparseOutcome::Event(_))))
            .unwrap();
        let mut lies = honest(from, to);
        lies.retain(|o| o.0 != unseen);
        assert!(check_sampled(&lies, from..to, &chosen, sampled_truth)
            .mismatch
            .is_none());
        // A forged event is always seen, chosen or not.
        let mut lies = honest(from, to);
        let forged = (from..to)
            .find(|i| i % 3 != 0 && truth(*i).0.is_none())
            .unwrap();
        lies.push((forged, SparseOutcome::Event(1.0)));
        lies.sort_by_key(|o| o.0);
        let mismatch = check_sampled(&lies, from..to, &chosen, sampled_truth)
            .mismatch
            .unwrap();
        assert_eq!(mismatch.index, forged);
        // A test that cannot be replayed checks nothing in its block or
        // after it (a case replays all its tests or none).
        let mut lies = honest(from, to);
        let forged = (to - 100..to).find(|i| truth(*i).0.is_none()).unwrap();
        lies.push((forged, SparseOutcome::Event(1.0)));
        lies.sort_by_key(|o| o.0);
        let unreplayable =
            |indices: &[u64]| (!indices.contains(&forged)).then(|| sampled_truth(indices).unwrap());
        let verified = check_sampled(&lies, from..to, &chosen, unreplayable);
        assert!(verified.mismatch.is_none());
        // A contradiction in an earlier block is still found.
        let early = (from..from + 50).find(|i| truth(*i).0.is_none()).unwrap();
        lies.push((early, SparseOutcome::Event(1.0)));
        lies.sort_by_key(|o| o.0);
        let mismatch = check_sampled(&lies, from..to, &chosen, unreplayable).mismatch;
        assert_eq!(mismatch.map(|m| m.index), Some(early));
        // Nothing to check.
        assert!(check_sampled(&[], from..to, &[], |_| unreachable!())
            .mismatch
            .is_none());
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

    /// The cut-in IDM's NDD campaign seeded 1, as the coordinator replays it.
    fn cut_in_ndd() -> std::sync::Arc<dyn CampaignTests> {
        let case = tslg_method::cases::open_case(
            "cut-in",
            None,
            &tslg_method::registry::ExposureSource::Builtin,
        )
        .unwrap();
        let vut = serde_json::json!({"model": "idm"});
        case.campaign(None, &vut, 0.1, Default::default(), Default::default(), 1)
            .unwrap()
    }

    /// `/metrics` counts every test a check's sample chose, once: when the
    /// walk runs to the end, and when a contradiction in its first block
    /// ends it.
    #[test]
    fn a_check_counts_its_whole_sample_even_when_a_contradiction_ends_it() {
        let tests = cut_in_ndd();
        let (from, to) = (100, 30_100u64);
        let outcomes: Vec<(u64, SparseOutcome)> = (from..to)
            .filter_map(|i| as_listed(tests.replay(i).unwrap()).map(|o| (i, o)))
            .collect();
        let honest = CheckedReport {
            from,
            to,
            events: Vec::new(),
            outcomes: outcomes.clone(),
            reasons: Vec::new(),
        };
        // A forged event on the first quiet test.
        let quiet = (from..to)
            .find(|&i| !tests.replay(i).unwrap().event)
            .unwrap();
        let mut forged = outcomes;
        forged.push((quiet, SparseOutcome::Event(1.0)));
        forged.sort_by_key(|o| o.0);
        let forged = CheckedReport {
            outcomes: forged,
            ..honest.clone()
        };
        let every_third = |f: u64, t: u64| (f..t).step_by(3).collect::<Vec<u64>>();
        let chosen = (to - from).div_ceil(3);
        for (report, place, contradicted) in [
            (&honest, Place::Request, false),
            (&forged, Place::Pool, true),
        ] {
            let counts = ReplayCounts::default();
            let verified =
                verify_counted(tests.as_ref(), report, from, every_third, (&counts, place));
            assert_eq!(
                verified.mismatch.map(|m| m.index),
                contradicted.then_some(quiet)
            );
            let totals = counts.totals();
            assert_eq!(totals.reports[place as usize], 1);
            assert_eq!(totals.reports.iter().sum::<u64>(), 1);
            assert_eq!((totals.sample_range, totals.sampled), (to - from, chosen));
        }
    }
}
