//! Which tests of the reported ranges the fold has not reached yet draw
//! outside the library, as the coordinator found them.
//!
//! A library campaign's fold counts the tests drawn outside the library
//! (the outside bound, docs/statistics.md). The coordinator learns which
//! tests those are when it runs a report's tests again, all of them
//! ([`crate::report::replay`]). But a report ahead of the resolved prefix is
//! folded later, by the report that fills the gap before it, and that fold
//! drew every test of the ranges it passed once more, on the writer's
//! thread while every other write waited: about one lease per other
//! worker at each such fold. The sets found are kept here, per campaign,
//! until the fold passes them; the fold draws only what no report brought
//! (after a restart, or when the memory cap below turned a set away).
//!
//! A set is a function of the campaign's seed and the tests' indices alone
//! (not of anything a worker reported), so keeping one longer than needed,
//! or one from a report whose write failed, changes no result.

use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// The exploring tests of `from..to`, sorted.
#[derive(Debug, Clone, PartialEq)]
pub struct Explored {
    pub from: u64,
    pub to: u64,
    pub tests: Vec<u64>,
}

/// Test indices kept in all, over every campaign (8 bytes each: 32 MiB),
/// a set counting one more for itself (a set of no exploring test is not
/// free). One campaign held back by a stuck lease can fill it; the others
/// then draw again, as before the sets were kept.
const MAX_KEPT: usize = 1 << 22;

/// The kept sets, by campaign and by their range's start.
#[derive(Default)]
pub struct ExploredRanges {
    inner: Mutex<Kept>,
    /// Tests the folds drew again because no kept set covered them, since
    /// the coordinator started (`tslg_fold_drawn_tests_total`).
    drawn: AtomicU64,
    /// The anytime campaigns' folds, kept between reports likewise.
    pub anytime: crate::report::anytime::AnytimeFolds,
}

#[derive(Default)]
struct Kept {
    campaigns: HashMap<i64, BTreeMap<u64, Arc<Explored>>>,
    /// Test indices held by all the sets.
    indices: usize,
}

impl ExploredRanges {
    /// Keeps `explored`, campaign `campaign`'s exploring tests of its range,
    /// unless that would pass the memory cap or a set kept from the same
    /// start reaches as far.
    pub fn remember(&self, campaign: i64, explored: Arc<Explored>) {
        let mut kept = self.lock();
        let size = weight(&explored);
        if explored.from >= explored.to || kept.indices + size > MAX_KEPT {
            return;
        }
        let sets = kept.campaigns.entry(campaign).or_default();
        if sets
            .get(&explored.from)
            .is_some_and(|s| s.to >= explored.to)
        {
            return;
        }
        let replaced = sets.insert(explored.from, explored);
        kept.indices += size;
        if let Some(old) = replaced {
            kept.indices -= weight(&old);
        }
    }

    /// The kept sets of `campaign` whose ranges meet `from..to`, by start.
    pub fn meeting(&self, campaign: i64, from: u64, to: u64) -> Vec<Arc<Explored>> {
        let kept = self.lock();
        let Some(sets) = kept.campaigns.get(&campaign) else {
            return Vec::new();
        };
        sets.range(..to)
            .map(|(_, set)| set)
            .filter(|set| set.to > from)
            .cloned()
            .collect()
    }

    /// Drops `campaign`'s sets that end at or below `prefix`: the fold has
    /// passed them.
    pub fn passed(&self, campaign: i64, prefix: u64) {
        let mut kept = self.lock();
        let Some(sets) = kept.campaigns.get_mut(&campaign) else {
            return;
        };
        let mut freed = 0;
        sets.retain(|_, set| {
            let keep = set.to > prefix;
            if !keep {
                freed += weight(set);
            }
            keep
        });
        if sets.is_empty() {
            kept.campaigns.remove(&campaign);
        }
        kept.indices -= freed;
    }

    /// Counts `tests` a fold drew again.
    pub fn note_drawn(&self, tests: u64) {
        self.drawn.fetch_add(tests, Ordering::Relaxed);
    }

    /// Tests the folds drew again since the coordinator started.
    pub fn drawn(&self) -> u64 {
        self.drawn.load(Ordering::Relaxed)
    }

    /// Drops every set of a campaign that has stopped.
    pub fn forget(&self, campaign: i64) {
        self.anytime.forget(campaign);
        let mut kept = self.lock();
        if let Some(sets) = kept.campaigns.remove(&campaign) {
            kept.indices -= sets.values().map(|s| weight(s)).sum::<usize>();
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Kept> {
        self.inner
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

/// What a kept set counts against the cap: its indices and itself.
fn weight(set: &Explored) -> usize {
    set.tests.len() + 1
}

/// The exploring tests of `from..to`, in increasing order: from `known`
/// (sets of ranges, in any order, possibly overlapping, each complete for
/// its range) where they cover it, and from `draw(start, end)` (every
/// exploring test of `start..end`) for the gaps between them.
pub fn exploring_in(
    from: u64,
    to: u64,
    known: &[&Explored],
    mut draw: impl FnMut(u64, u64) -> Vec<u64>,
) -> Vec<u64> {
    let mut sets: Vec<&Explored> = known
        .iter()
        .copied()
        .filter(|s| s.from < to && s.to > from && s.from < s.to)
        .collect();
    sets.sort_by_key(|s| s.from);
    let mut found = Vec::new();
    // Every exploring test below `done` (and at or above `from`) is found.
    let mut done = from;
    for set in sets {
        if set.to <= done {
            continue;
        }
        if set.from > done {
            found.extend(draw(done, set.from));
            done = set.from;
        }
        let end = set.to.min(to);
        let first = set.tests.partition_point(|&i| i < done);
        found.extend(set.tests[first..].iter().copied().take_while(|&i| i < end));
        done = end;
    }
    if done < to {
        found.extend(draw(done, to));
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// A made-up campaign: test `i` explores when `i % 7 == 3`.
    fn explores(i: u64) -> bool {
        i % 7 == 3
    }

    fn set(from: u64, to: u64) -> Explored {
        Explored {
            from,
            to,
            tests: (from..to).filter(|&i| explores(i)).collect(),
        }
    }

    /// Whatever sets are known (none, gaps, overlaps, sets reaching past
    /// either end, empty ranges), the tests found are exactly the
    /// exploring ones of the range, each once, in order; and what is
    /// drawn is only what no set covers.
    #[test]
    fn the_tests_found_are_the_exploring_ones_whatever_sets_are_known() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        for _ in 0..2_000 {
            let from = rng.random_range(0..200);
            let to = from + rng.random_range(0..300);
            let known: Vec<Explored> = (0..rng.random_range(0..6))
                .map(|_| {
                    let start = rng.random_range(0..500);
                    set(start, start + rng.random_range(0..120))
                })
                .collect();
            let refs: Vec<&Explored> = known.iter().collect();
            let mut drawn = 0;
            let found = exploring_in(from, to, &refs, |a, b| {
                assert!(
                    from <= a && a < b && b <= to,
                    "{a}..{b} outside {from}..{to}"
                );
                assert!(
                    !known.iter().any(|s| s.from <= a && b <= s.to),
                    "{a}..{b} is known"
                );
                drawn += b - a;
                set(a, b).tests
            });
            let exact: Vec<u64> = (from..to).filter(|&i| explores(i)).collect();
            assert_eq!(found, exact, "{from}..{to} with {known:?}");
            let covered = (from..to)
                .filter(|&i| known.iter().any(|s| s.from <= i && i < s.to))
                .count() as u64;
            assert_eq!(drawn, to - from - covered, "{from}..{to} with {known:?}");
        }
    }

    /// Sets are kept until the fold passes them, the memory cap turns
    /// away what would pass it, and a stopped campaign's sets go.
    #[test]
    fn sets_are_kept_until_passed_and_within_the_cap() {
        let kept = ExploredRanges::default();
        kept.remember(1, Arc::new(set(0, 100)));
        kept.remember(1, Arc::new(set(100, 200)));
        kept.remember(2, Arc::new(set(0, 70)));
        let starts = |c, from, to| -> Vec<u64> {
            kept.meeting(c, from, to).iter().map(|s| s.from).collect()
        };
        assert_eq!(starts(1, 0, 200), [0, 100]);
        assert_eq!(starts(1, 100, 101), [100]);
        assert_eq!(starts(1, 99, 100), [0]);
        assert_eq!(starts(1, 200, 300), Vec::<u64>::new());
        kept.passed(1, 150);
        assert_eq!(starts(1, 0, 200), [100]);
        kept.passed(1, 200);
        assert_eq!(starts(1, 0, 200), Vec::<u64>::new());
        assert_eq!(starts(2, 0, 70), [0]);
        kept.forget(2);
        assert_eq!(starts(2, 0, 70), Vec::<u64>::new());
        assert_eq!(kept.lock().indices, 0);
        // Past the cap a set is not kept (the fold draws it again).
        let huge = Explored {
            from: 0,
            to: MAX_KEPT as u64 + 1,
            tests: (0..MAX_KEPT as u64 + 1).collect(),
        };
        kept.remember(3, Arc::new(huge));
        assert_eq!(starts(3, 0, 10), Vec::<u64>::new());
        assert_eq!(kept.lock().indices, 0);
        // A set from the same start replaces a shorter one, not a longer.
        kept.remember(4, Arc::new(set(0, 50)));
        kept.remember(4, Arc::new(set(0, 100)));
        kept.remember(4, Arc::new(set(0, 30)));
        let sets = kept.meeting(4, 0, 100);
        assert_eq!((sets.len(), sets[0].to), (1, 100));
        assert_eq!(kept.lock().indices, weight(&set(0, 100)));
        kept.passed(4, 100);
        assert_eq!(kept.lock().indices, 0);
    }
}
