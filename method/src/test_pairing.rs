//! Every test is evidence: each worker's tests paired with the rest of the
//! fleet's tests of the same campaign and scenario cell (or stratum).
//!
//! Audits ([`crate::discordance`]) compare two runs of one test, so they
//! see only the audited share (1 % by default): a program that brakes a
//! little harder, or drops a share of its events, needs thousands of
//! compared audits. Yet every test a worker runs is a draw from the
//! campaign's proposal, and a worker cannot choose its tests (leases hand
//! out the next indices). Two tests of one grid cell are two runs of one
//! scenario, whoever runs them; two tests of one stratum (a library's
//! inside or outside, the NDD's one stratum) are two independent draws of
//! its scenarios. So if worker `W` runs the same program as the others, a
//! test of `W`'s and one of another worker's with the same [key](ResolvedRun::key)
//! are two independent draws of the same (scenario, outcome) distribution,
//! and when the two differ, `W`'s is the one closer to the event with
//! probability ½, whatever the cell and however noisy the program. That is
//! the audit's discordant pair, and the same Krichevsky–Trofimov e-value
//! ([`crate::discordance::kt_e_value`]) weighs it.
//!
//! **How close** is a test's [`score`]: 0 for the event, else 1 + its
//! criticality in thousandths (the program's own measure of how near it
//! came, in `[0, 1]`, where it reported one at most [`CRITICALITY_BELOW`]),
//! so that a pair counts whenever two runs differ in how close they came,
//! not only when exactly one found the event; where either criticality is
//! unknown ([`closer`]), by the event alone. Events alone are weak where they are rare: a
//! program that brakes 3 m/s² harder than the noisy IDM's three other
//! workers (β 0.05 library campaign, guard on, 168,000 tests, pairs by
//! stratum) was in 51 pairs of differing events, 11 its own, an e-value of
//! 20, far from 10⁴: it differs from the others outside the library,
//! where two tests in 10⁴ have an event, but there it stays further from
//! the event in every scenario where it brakes. Pairs by cell keep that
//! difference from drowning in the spread between scenarios.
//!
//! **The pairing must not look at outcomes.** [`Walk`] runs over a
//! campaign's resolved tests in index order (the prefix, which does not
//! depend on who reported when) and pairs each test with the oldest
//! waiting test of another worker with the same key; a test with none
//! waits. The waiting tests of a key are then all one worker's (a test of
//! anyone else would have paired), at most [`WAIT_CAP`] of them, the
//! oldest dropped, and at most [`MAX_KEYS`] keys and [`MAX_WAITING`]
//! tests in all wait, the keys waiting longest dropped. Which tests pair depends on indices, keys and who ran
//! them only, and each test is in at most one pair, so the pairs are
//! independent and each counts for both its workers: the e-value of a
//! worker's discordant pairs in a campaign is a test martingale under
//! "same program", and Ville's inequality bounds the chance that it ever
//! reaches 10⁴ by 10⁻⁴ (one e-value a campaign: campaigns that reuse a
//! seed draw the same tests again, so their pairs would repeat). Audit pairs are counted apart (an
//! audited test's first run may also be in a test pair, and two pairs
//! sharing a run are not independent).
//!
//! What it assumes: which worker runs a test does not depend on that
//! test's outcome. Leases are handed out before any of their tests run, so
//! it holds, except where a lease expires mid-way and its rest goes to
//! another worker (a program whose slow tests are the eventless ones would
//! pass the others a share of eventless tests); a careful liar can use
//! this only by giving up tests, which the audits' dodging rule watches.

use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, VecDeque};

/// The most tests that wait under one key; past it the oldest are dropped
/// (by index, so the rule still looks at no outcome). Only one worker's
/// tests wait, so this costs a worker that runs far more than the rest of
/// the fleet some of its pairs, never validity.
pub const WAIT_CAP: u64 = 4096;

/// The most tests waiting under all keys together; past it the keys
/// waiting longest are dropped. With [`MAX_KEYS`] it bounds what the walk
/// stores at every fold, whatever the fleet (one principal's tests
/// waiting in every cell, each of its own score).
pub const MAX_WAITING: u64 = 16_384;

/// The most keys with waiting tests; past it the key waiting longest (by
/// the index its wait began at) is dropped. A campaign's cells number in
/// the thousands on the grid cases, but the pairs come from the cells its
/// tests visit often; a key rarely visited waits long and is dropped
/// first. The walk is stored at every fold, so this bounds what is
/// written (about 60 bytes a key).
pub const MAX_KEYS: usize = 1024;

/// The criticality at or below which workers report it for every test of
/// a library or NDD campaign of an external program (`near_misses`): every
/// test that came near the event at all.
pub const CRITICALITY_BELOW: f64 = 0.999;

/// The score of a test without the event whose criticality is not known:
/// none was reported (a program that sends none, a worker that did not
/// ask), or it was above [`CRITICALITY_BELOW`].
pub const UNKNOWN: u16 = 1001;

/// How close a test came to the event, smaller closer: 0 for the event,
/// `1 + round(1000 c)` for a reported criticality `c` ≤
/// [`CRITICALITY_BELOW`], else [`UNKNOWN`].
pub fn score(event: bool, criticality: Option<f64>) -> u16 {
    match (event, criticality) {
        (true, _) => 0,
        (false, Some(c)) if (0.0..=CRITICALITY_BELOW).contains(&c) => {
            1 + (c * 1000.0).round() as u16
        }
        _ => UNKNOWN,
    }
}

/// Which of two scores is closer to the event (`Less`: the first). Where
/// either criticality is unknown, by the event alone: a worker whose
/// program sends no criticality is compared with the others on what it
/// does send, never taken for one that stays far from the event.
pub fn closer(a: u16, b: u16) -> std::cmp::Ordering {
    if a == UNKNOWN || b == UNKNOWN {
        return (a != 0).cmp(&(b != 0));
    }
    a.cmp(&b)
}

/// The key of a test of a grid cell: cells and strata share one space.
pub fn cell_key(cell: u64) -> u64 {
    cell.saturating_add(2)
}

/// The key of a test of stratum 0 or 1 where its cell is not known.
pub fn stratum_key(explores: bool) -> u64 {
    u64::from(explores)
}

/// Consecutive resolved tests of a campaign (in index order) that one
/// worker ran, of one key and one [`score`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ResolvedRun<'a> {
    /// The worker that reported them.
    pub worker: &'a str,
    /// What they are draws of: their grid cell ([`cell_key`]), else their
    /// stratum ([`stratum_key`]).
    pub key: u64,
    /// Their [`score`] (an invalid test counts as one that never came
    /// near, as in the audits: otherwise a worker could hide events by
    /// failing them).
    pub score: u16,
    /// The first one's index.
    pub index: u64,
    /// How many tests.
    pub tests: u64,
}

/// Pairs of two workers' tests: how many, and in how many each was the
/// closer to the event.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PairTally {
    /// Pairs of the two workers' tests.
    pub compared: u64,
    /// Of them, those where the first's test scored lower (closer).
    pub first_closer: u64,
    /// Of them, those where the second's test scored lower.
    pub second_closer: u64,
}

/// The pairs closed, by `(first, second)` worker (first: the one whose
/// test waited).
pub type PairCounts = BTreeMap<(String, String), PairTally>;

/// The tests of one key waiting for a partner: all one worker's, as runs
/// of one score, oldest first, since test `since`.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
struct Waiting {
    worker: String,
    since: u64,
    runs: VecDeque<(u16, u64)>,
    /// Tests in `runs`.
    tests: u64,
}

impl Waiting {
    /// Takes the oldest `n` tests (fewer if fewer wait), as runs.
    fn take(&mut self, mut n: u64) -> Vec<(u16, u64)> {
        let mut taken = Vec::new();
        while n > 0 {
            let Some(front) = self.runs.front_mut() else {
                break;
            };
            let k = front.1.min(n);
            taken.push((front.0, k));
            front.1 -= k;
            n -= k;
            self.tests -= k;
            if front.1 == 0 {
                self.runs.pop_front();
            }
        }
        taken
    }

    /// Adds `tests` of `score`; the number dropped past [`WAIT_CAP`].
    fn push(&mut self, score: u16, tests: u64) -> u64 {
        match self.runs.back_mut() {
            Some(last) if last.0 == score => last.1 += tests,
            _ => self.runs.push_back((score, tests)),
        }
        self.tests += tests;
        let excess = self.tests.saturating_sub(WAIT_CAP);
        self.take(excess);
        excess
    }
}

/// The pairing state of one campaign: each key's waiting tests. Stored
/// between folds (JSON), so a walk continues where it stopped.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Walk {
    keys: BTreeMap<u64, Waiting>,
    /// `(since, key)` of the keys in the order their waits began (the
    /// index order), with stale entries of keys paired since: the next to
    /// drop is found without a scan. Rebuilt from `keys` after a load.
    #[serde(skip)]
    order: VecDeque<(u64, u64)>,
    /// Tests waiting under all keys (kept with `order`).
    #[serde(skip)]
    waiting: u64,
    /// Whether `order` and `waiting` are built (not after a load).
    #[serde(skip)]
    ready: bool,
}

impl PartialEq for Walk {
    fn eq(&self, other: &Self) -> bool {
        self.keys == other.keys
    }
}

impl Eq for Walk {}

impl Walk {
    /// Walks `run` (the next tests in index order), adding the pairs it
    /// closes to `pairs`: its tests pair with the oldest waiting tests of
    /// their key when another worker's wait, and wait otherwise.
    pub fn step(&mut self, run: ResolvedRun<'_>, pairs: &mut PairCounts) {
        if !self.ready {
            self.rebuild();
        }
        let mut left = run.tests;
        if let Some(waiting) = self.keys.get_mut(&run.key) {
            if waiting.worker != run.worker {
                for (score, n) in waiting.take(left) {
                    let key = (waiting.worker.clone(), run.worker.to_owned());
                    let tally = pairs.entry(key).or_default();
                    tally.compared += n;
                    match closer(score, run.score) {
                        std::cmp::Ordering::Less => tally.first_closer += n,
                        std::cmp::Ordering::Greater => tally.second_closer += n,
                        std::cmp::Ordering::Equal => {}
                    }
                    left -= n;
                    self.waiting -= n;
                }
                if waiting.runs.is_empty() {
                    self.keys.remove(&run.key);
                }
            }
        }
        if left == 0 {
            return;
        }
        let since = run.index + (run.tests - left);
        let waiting = self.keys.entry(run.key).or_insert_with(|| Waiting {
            worker: run.worker.to_owned(),
            since,
            runs: VecDeque::new(),
            tests: 0,
        });
        if waiting.runs.is_empty() {
            self.order.push_back((since, run.key));
        }
        let dropped = waiting.push(run.score, left);
        self.waiting += left - dropped;
        while self.keys.len() > MAX_KEYS || self.waiting > MAX_WAITING {
            self.drop_oldest();
        }
        if self.order.len() > 4 * MAX_KEYS {
            self.rebuild();
        }
    }

    /// Drops the key waiting longest: the first entry of `order` that is
    /// still a key's wait.
    fn drop_oldest(&mut self) {
        while let Some((since, key)) = self.order.pop_front() {
            if self.keys.get(&key).is_some_and(|w| w.since == since) {
                if let Some(dropped) = self.keys.remove(&key) {
                    self.waiting -= dropped.tests;
                }
                return;
            }
        }
    }

    /// `order` and `waiting` from `keys` (after a load, or to shed stale
    /// entries of `order`).
    fn rebuild(&mut self) {
        let mut order: Vec<(u64, u64)> = self.keys.iter().map(|(k, w)| (w.since, *k)).collect();
        order.sort_unstable();
        self.order = order.into();
        self.waiting = self.keys.values().map(|w| w.tests).sum();
        self.ready = true;
    }

    /// Forgets the waiting tests of `worker` (flagged: its tests were
    /// taken back).
    pub fn forget(&mut self, worker: &str) {
        self.keys.retain(|_, waiting| waiting.worker != worker);
        self.rebuild();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::discordance::{worker_evidence, Discordant, FLAG_AT};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A walk that numbers the tests it is given.
    #[derive(Default)]
    struct Walker {
        walk: Walk,
        index: u64,
        pairs: PairCounts,
    }

    impl Walker {
        fn step(&mut self, worker: &str, key: u64, score: u16, tests: u64) {
            let run = ResolvedRun {
                worker,
                key,
                score,
                index: self.index,
                tests,
            };
            self.walk.step(run, &mut self.pairs);
            self.index += tests;
        }
    }

    fn tally(compared: u64, first_closer: u64, second_closer: u64) -> PairTally {
        PairTally {
            compared,
            first_closer,
            second_closer,
        }
    }

    fn key(a: &str, b: &str) -> (String, String) {
        (a.into(), b.into())
    }

    #[test]
    fn scores_order_the_event_first_then_by_criticality() {
        assert_eq!(score(true, Some(0.5)), 0);
        assert_eq!(score(false, Some(0.0)), 1);
        assert_eq!(score(false, Some(0.0314)), 32);
        assert_eq!(score(false, Some(0.999)), 1000);
        assert_eq!(score(false, None), UNKNOWN);
        assert_eq!(score(false, Some(1.0)), UNKNOWN);
        assert_eq!(score(false, Some(7.0)), UNKNOWN);
        // Unknown against a criticality: a tie; against the event: farther.
        use std::cmp::Ordering::*;
        assert_eq!(closer(32, UNKNOWN), Equal);
        assert_eq!(closer(0, UNKNOWN), Less);
        assert_eq!(closer(UNKNOWN, 0), Greater);
        assert_eq!(closer(32, 500), Less);
        assert_ne!(cell_key(0), stratum_key(true));
    }

    #[test]
    fn tests_pair_in_index_order_within_a_key_and_each_test_once() {
        let mut w = Walker::default();
        w.step("a", 0, 0, 1);
        w.step("a", 1, 1001, 1);
        w.step("a", 0, 500, 3);
        assert!(w.pairs.is_empty());
        // b's two key-0 tests (score 500) pair with a's oldest two (an
        // event, then a tie); a's key-1 test and two more wait.
        w.step("b", 0, 500, 2);
        assert_eq!(w.pairs, PairCounts::from([(key("a", "b"), tally(2, 1, 0))]));
        w.pairs.clear();
        // c's five pair with a's last two (c closer), then three wait.
        w.step("c", 0, 20, 5);
        assert_eq!(w.pairs, PairCounts::from([(key("a", "c"), tally(2, 0, 2))]));
        w.pairs.clear();
        w.step("a", 0, 0, 1);
        assert_eq!(w.pairs, PairCounts::from([(key("c", "a"), tally(1, 0, 1))]));
        // c's wait began at its first unpaired test, index 9.
        assert_eq!(w.walk.keys[&0].since, 9);
        // The state round-trips through its stored form.
        let stored = serde_json::to_string(&w.walk).unwrap();
        assert_eq!(serde_json::from_str::<Walk>(&stored).unwrap(), w.walk);
    }

    #[test]
    fn at_most_the_caps_wait_and_a_forgotten_worker_leaves_nothing_waiting() {
        let mut w = Walker::default();
        for k in 0..10_000u64 {
            w.step("a", 0, (k % 3) as u16, 1);
        }
        assert_eq!(w.walk.keys[&0].tests, WAIT_CAP);
        // The oldest were dropped: the next partner test pairs with test
        // 10,000 − 4,096 = 5,904, of score 5,904 mod 3 = 0.
        w.step("b", 0, 1, 1);
        assert_eq!(w.pairs, PairCounts::from([(key("a", "b"), tally(1, 1, 0))]));
        // Past MAX_KEYS keys the one waiting longest goes: key 0 (since
        // test 5,905), not key 7 (since 10,001).
        w.step("a", 7, 1, 1);
        for cell in 0..MAX_KEYS as u64 - 1 {
            w.step("a", cell_key(cell + 100), 1, 1);
        }
        assert_eq!(w.walk.keys.len(), MAX_KEYS);
        assert!(!w.walk.keys.contains_key(&0) && w.walk.keys.contains_key(&7));
        w.walk.forget("a");
        assert!(w.walk.keys.is_empty());
    }

    #[test]
    fn what_waits_stays_bounded_when_one_worker_runs_everything() {
        // One worker, each test of its own score, 1,000 cells: nothing
        // ever pairs. At most MAX_WAITING tests wait, the oldest cells
        // dropped first, and a reloaded walk counts them the same.
        let mut w = Walker::default();
        for k in 0..40_000u64 {
            w.step("a", cell_key(k % 1000), (k % 997) as u16 + 1, 1);
        }
        assert!(w.walk.waiting <= MAX_WAITING, "{}", w.walk.waiting);
        assert!(w.walk.waiting > MAX_WAITING - 1000, "{}", w.walk.waiting);
        let stored = serde_json::to_string(&w.walk).unwrap();
        assert!(stored.len() < 400_000, "{}", stored.len());
        let mut reloaded: Walk = serde_json::from_str(&stored).unwrap();
        reloaded.rebuild();
        assert_eq!(reloaded.waiting, w.walk.waiting);
    }

    /// A fleet's campaign: `tests` tests in leases of `lease` consecutive
    /// indices handed to workers at random (worker `shares[k]` for a
    /// uniform `k`), each test's key and score drawn by `draw(rng, liar)`
    /// (`liar` for worker 0). The largest e-value (as flagged) any honest
    /// worker reached, and the liar's.
    fn campaign(
        rng: &mut ChaCha8Rng,
        shares: &[usize],
        (tests, lease): (usize, usize),
        draw: impl Fn(&mut ChaCha8Rng, bool) -> (u64, u16),
    ) -> (f64, f64) {
        let names = ["w0", "w1", "w2", "w3"];
        let mut w = Walker::default();
        let mut counts: BTreeMap<(String, String), Discordant> = BTreeMap::new();
        let (mut honest_max, mut liar_max) = (1.0f64, 1.0f64);
        let mut index = 0;
        while index < tests {
            let worker = shares[rng.random_range(0..shares.len())];
            for _ in 0..lease {
                let (key, score) = draw(rng, worker == 0);
                w.step(names[worker], key, score, 1);
                index += 1;
            }
            for ((a, b), t) in std::mem::take(&mut w.pairs) {
                let ab = counts.entry((a.clone(), b.clone())).or_default();
                ab.own_event += t.first_closer;
                ab.partner_event += t.second_closer;
                let ba = counts.entry((b, a)).or_default();
                ba.own_event += t.second_closer;
                ba.partner_event += t.first_closer;
            }
            for name in names {
                let partners: Vec<Discordant> = counts
                    .iter()
                    .filter(|((w, _), _)| w == name)
                    .map(|(_, c)| *c)
                    .collect();
                let evidence = worker_evidence(&partners);
                if name == "w0" {
                    liar_max = liar_max.max(evidence);
                } else {
                    honest_max = honest_max.max(evidence);
                }
            }
        }
        (honest_max, liar_max)
    }

    /// Fast workers take more leases: an uneven fleet.
    const UNEVEN: [usize; 7] = [0, 1, 1, 2, 3, 3, 3];

    /// An event with probability `rate`, else no event (score 1001).
    fn event(rng: &mut ChaCha8Rng, rate: f64) -> u16 {
        if rng.random_bool(rate) {
            0
        } else {
            1001
        }
    }

    /// A cut-in-like campaign of 50 cells: the vehicle brakes in the first
    /// 25, and a run that brakes ends at a criticality uniform on `b..b +
    /// 0.2` where `b` grows with the cell from 0 to 0.67 (`shift` more for
    /// worker 0), an event with probability 2 in 10⁴ (the outside of a
    /// library); a run that does not brake reports no criticality.
    fn braking(shift: f64, by_cell: bool) -> impl Fn(&mut ChaCha8Rng, bool) -> (u64, u16) {
        move |rng: &mut ChaCha8Rng, liar: bool| {
            let cell = rng.random_range(0..50u64);
            let key = if by_cell {
                cell_key(cell)
            } else {
                stratum_key(true)
            };
            let base = cell as f64 / 25.0 * 0.7 + if liar { shift } else { 0.0 };
            let score = if rng.random_bool(0.0002) {
                0
            } else if cell < 25 {
                score(false, Some(rng.random_range(base..base + 0.2)))
            } else {
                score(false, None)
            };
            (key, score)
        }
    }

    #[test]
    fn honest_fleets_cross_a_level_no_more_often_than_ville_allows() {
        // 400 campaigns of 2,000 tests each way (keys by stratum with
        // event rates 0.6 and 0.002; keys by cell with criticalities),
        // leases of 20 to uneven workers: every worker honest. Ville
        // bounds the chance that an honest worker's e-value ever reaches
        // 20 by 1/20 per worker.
        let mut rng = ChaCha8Rng::seed_from_u64(66);
        let strata = |rng: &mut ChaCha8Rng, _| {
            let outside = rng.random_bool(0.5);
            let rate = if outside { 0.002 } else { 0.6 };
            (stratum_key(outside), event(rng, rate))
        };
        let runs = 400;
        for (name, draw) in [
            (
                "strata",
                Box::new(strata) as Box<dyn Fn(&mut ChaCha8Rng, bool) -> (u64, u16)>,
            ),
            ("cells", Box::new(braking(0.0, true))),
        ] {
            let mut crossed = 0;
            for _ in 0..runs {
                let (honest, liar) = campaign(&mut rng, &UNEVEN, (2000, 20), &draw);
                crossed += usize::from(honest.max(liar) >= 20.0);
            }
            // Four workers: at most 4/20 of the campaigns in expectation;
            // the e-value of a worker leaving out a partner is smaller still.
            assert!(crossed <= runs / 10, "{name}: {crossed} of {runs}");
        }
    }

    #[test]
    fn a_worker_whose_events_are_rarer_is_flagged_and_the_honest_ones_are_not() {
        // Worker 0 finds the library's event in 35 % of its tests against
        // the others' 60 %, each of four workers on a quarter of the leases:
        // within 5,000 tests it is flagged in every one of 20 campaigns,
        // and no honest worker is (Ville: at most 60 in 10⁴ of such runs
        // would flag one). Its evidence leaves out its largest partner, so
        // a liar with a small share of a fleet that one worker dominates
        // needs more tests.
        let mut rng = ChaCha8Rng::seed_from_u64(67);
        let draw = |rng: &mut ChaCha8Rng, liar: bool| {
            let outside = rng.random_bool(0.5);
            let rate = match (outside, liar) {
                (true, _) => 0.002,
                (false, false) => 0.6,
                (false, true) => 0.35,
            };
            (stratum_key(outside), event(rng, rate))
        };
        for _ in 0..20 {
            let (honest, liar) = campaign(&mut rng, &[0, 1, 2, 3], (5000, 20), draw);
            assert!(liar >= FLAG_AT, "{liar}");
            assert!(honest < FLAG_AT, "{honest}");
        }
    }

    #[test]
    fn pairs_by_cell_convict_a_program_that_stays_further_where_it_brakes() {
        // Worker 0 brakes harder: where it brakes, its criticality is 0.06
        // higher than the others' in the same cell (on a spread of 0.2),
        // and its events are as rare. Paired by cell, it is flagged within
        // 8,000 tests in every one of 20 campaigns; paired across the cells
        // of a stratum, where the spread between cells (0.7) drowns the
        // shift, the same tests leave it unflagged in most.
        let mut rng = ChaCha8Rng::seed_from_u64(68);
        let mut by_stratum_flagged = 0;
        for _ in 0..20 {
            let (honest, liar) = campaign(&mut rng, &[0, 1, 2, 3], (8000, 20), braking(0.06, true));
            assert!(liar >= FLAG_AT, "{liar}");
            assert!(honest < FLAG_AT, "{honest}");
            let (_, liar) = campaign(&mut rng, &[0, 1, 2, 3], (8000, 20), braking(0.06, false));
            by_stratum_flagged += usize::from(liar >= FLAG_AT);
        }
        assert!(by_stratum_flagged < 10, "{by_stratum_flagged}");
    }
}
