//! Every test is evidence: each worker's tests paired with the rest of the
//! fleet's tests of the same campaign and stratum.
//!
//! Audits ([`crate::discordance`]) compare two runs of one test, so they
//! see only the audited share (1 % by default): a program that brakes a
//! little harder, or drops a share of its events, needs thousands of
//! compared audits. Yet every test a worker runs is a draw from the
//! campaign's proposal: within one stratum (library, outside, one
//! estimate's single stratum) the scenarios of the tests are independent
//! and identically distributed, whoever runs them, and a worker cannot
//! choose its tests (leases hand out the next indices). So if worker `W`
//! runs the same program as the others, a test of `W`'s and a test of
//! another worker's in the same stratum are two independent draws of the
//! same (scenario, outcome) distribution, and when the two differ, `W`'s
//! is the one closer to the event with probability ½, whatever the
//! stratum's event rate and however noisy the program. That is the audit's
//! discordant pair, and the same Krichevsky–Trofimov e-value
//! ([`crate::discordance::kt_e_value`]) weighs it.
//!
//! **How close** is a test's [`score`]: 0 for the event, else 1 + its
//! criticality in thousandths (1,001 when none is known), so that a pair
//! could count whenever two runs differ in how close they came, not only
//! when exactly one found the event. Workers report a criticality only for
//! an adaptive campaign's near misses, so today every other test scores 0
//! or 1,001: the event alone. That is weak where events are rare. A
//! program that brakes 3 m/s² harder than the noisy IDM's three other
//! workers (β 0.05 library campaign, guard on, 168,000 tests) was in 51
//! pairs of differing events, 11 its own: an e-value of 20, far from 10⁴,
//! because its events differ only outside the library, where two tests
//! in 10⁴ have one (docs/statistics.md, "Every test as evidence").
//!
//! **The pairing must not look at outcomes.** [`Walk`] runs over a
//! campaign's resolved tests in index order (the prefix, which does not
//! depend on who reported when) and, in each stratum, pairs each test with
//! the oldest waiting test of another worker; a test with none waits. The
//! waiting tests of a stratum are then all one worker's (a test of anyone
//! else would have paired), at most [`WAIT_CAP`] of them, the oldest
//! dropped. Which tests pair depends on indices and on who ran them only,
//! and each test is in at most one pair, so the pairs are independent and
//! each counts for both its workers: the e-value of a worker's discordant
//! pairs is a test martingale under "same program", and Ville's
//! inequality bounds the chance that it ever reaches 10⁴ by 10⁻⁴, over
//! the worker's whole life. Audit pairs are counted apart (an audited
//! test's first run may also be in a test pair, and two pairs sharing a
//! run are not independent).
//!
//! What it assumes: which worker runs a test does not depend on that
//! test's outcome. Leases are handed out before any of their tests run, so
//! it holds, except where a lease expires mid-way and its rest goes to
//! another worker (a program whose slow tests are the eventless ones would
//! pass the others a share of eventless tests); a careful liar can use
//! this only by giving up tests, which the audits' dodging rule watches.

use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, VecDeque};

/// The most tests that wait in a stratum; past it the oldest are dropped
/// (by index, so the rule still looks at no outcome). Only one worker's
/// tests wait, so this costs a worker that runs far more than the rest of
/// the fleet some of its pairs, never validity.
pub const WAIT_CAP: u64 = 4096;

/// How close a test came to the event, smaller closer: 0 for the event,
/// `1 + round(1000 c)` for criticality `c` (not reported: `c` = 1).
pub fn score(event: bool, criticality: Option<f64>) -> u16 {
    if event {
        return 0;
    }
    1 + (criticality.unwrap_or(1.0).clamp(0.0, 1.0) * 1000.0).round() as u16
}

/// Consecutive resolved tests of a campaign (in index order) that one
/// worker ran, of one stratum and one [`score`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ResolvedRun<'a> {
    /// The worker that reported them.
    pub worker: &'a str,
    /// Their stratum: tests of one stratum are draws of one distribution.
    pub stratum: u8,
    /// Their [`score`] (an invalid test counts as one that never came
    /// near, as in the audits: otherwise a worker could hide events by
    /// failing them).
    pub score: u16,
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

/// The tests of one stratum waiting for a partner: all one worker's, as
/// runs of one score, oldest first.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
struct Waiting {
    worker: String,
    runs: VecDeque<(u16, u64)>,
}

impl Waiting {
    fn tests(&self) -> u64 {
        self.runs.iter().map(|r| r.1).sum()
    }

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
            if front.1 == 0 {
                self.runs.pop_front();
            }
        }
        taken
    }

    fn push(&mut self, score: u16, tests: u64) {
        match self.runs.back_mut() {
            Some(last) if last.0 == score => last.1 += tests,
            _ => self.runs.push_back((score, tests)),
        }
        let excess = self.tests().saturating_sub(WAIT_CAP);
        self.take(excess);
    }
}

/// The pairing state of one campaign: each stratum's waiting tests.
/// Stored between folds (JSON), so a walk continues where it stopped.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Walk {
    strata: BTreeMap<u8, Waiting>,
}

impl Walk {
    /// Walks `run` (the next tests in index order), adding the pairs it
    /// closes to `pairs`: its tests pair with the oldest waiting tests of
    /// their stratum when another worker's wait, and wait otherwise.
    pub fn step(&mut self, run: ResolvedRun<'_>, pairs: &mut PairCounts) {
        let waiting = self.strata.entry(run.stratum).or_default();
        let mut left = run.tests;
        if waiting.worker != run.worker {
            for (score, n) in waiting.take(left) {
                let key = (waiting.worker.clone(), run.worker.to_owned());
                let tally = pairs.entry(key).or_default();
                tally.compared += n;
                match score.cmp(&run.score) {
                    std::cmp::Ordering::Less => tally.first_closer += n,
                    std::cmp::Ordering::Greater => tally.second_closer += n,
                    std::cmp::Ordering::Equal => {}
                }
                left -= n;
            }
            if left == 0 {
                return;
            }
            waiting.worker = run.worker.to_owned();
        }
        waiting.push(run.score, left);
    }

    /// Forgets the waiting tests of `worker` (flagged: its tests were
    /// taken back).
    pub fn forget(&mut self, worker: &str) {
        self.strata.retain(|_, waiting| waiting.worker != worker);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::discordance::{worker_evidence, Discordant, FLAG_AT};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn run(worker: &str, stratum: u8, score: u16, tests: u64) -> ResolvedRun<'_> {
        ResolvedRun {
            worker,
            stratum,
            score,
            tests,
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
        assert_eq!(score(false, None), 1001);
        assert_eq!(score(false, Some(1.0)), 1001);
        assert_eq!(score(false, Some(7.0)), 1001);
    }

    #[test]
    fn tests_pair_in_index_order_within_a_stratum_and_each_test_once() {
        let mut walk = Walk::default();
        let mut pairs = PairCounts::new();
        walk.step(run("a", 0, 0, 1), &mut pairs);
        walk.step(run("a", 1, 1001, 1), &mut pairs);
        walk.step(run("a", 0, 500, 3), &mut pairs);
        assert!(pairs.is_empty());
        // b's two stratum-0 tests (score 500) pair with a's oldest two (an
        // event, then a tie); a's stratum-1 test and two more wait.
        walk.step(run("b", 0, 500, 2), &mut pairs);
        assert_eq!(pairs, PairCounts::from([(key("a", "b"), tally(2, 1, 0))]));
        pairs.clear();
        // c's five pair with a's last two (c closer), then three wait.
        walk.step(run("c", 0, 20, 5), &mut pairs);
        assert_eq!(pairs, PairCounts::from([(key("a", "c"), tally(2, 0, 2))]));
        pairs.clear();
        walk.step(run("a", 0, 0, 1), &mut pairs);
        assert_eq!(pairs, PairCounts::from([(key("c", "a"), tally(1, 0, 1))]));
        // The state round-trips through its stored form.
        let stored = serde_json::to_string(&walk).unwrap();
        assert_eq!(serde_json::from_str::<Walk>(&stored).unwrap(), walk);
    }

    #[test]
    fn at_most_the_cap_waits_and_a_forgotten_worker_leaves_nothing_waiting() {
        let mut walk = Walk::default();
        let mut pairs = PairCounts::new();
        for k in 0..10_000u64 {
            walk.step(run("a", 0, (k % 3) as u16, 1), &mut pairs);
        }
        assert_eq!(walk.strata[&0].tests(), WAIT_CAP);
        // The oldest were dropped: the next partner test pairs with test
        // 10,000 − 4,096 = 5,904, of score 5,904 mod 3 = 0.
        walk.step(run("b", 0, 1, 1), &mut pairs);
        assert_eq!(pairs, PairCounts::from([(key("a", "b"), tally(1, 1, 0))]));
        walk.forget("a");
        assert!(walk.strata.is_empty());
    }

    /// A fleet's campaign: `tests` tests in leases of `lease` consecutive
    /// indices handed to workers at random (worker `shares[k]` for a
    /// uniform `k`), each test in stratum 1 with probability `outside`,
    /// its score drawn by `draw(stratum, liar)` (`liar` for worker 0).
    /// The largest e-value (as flagged) any honest worker reached, and the
    /// liar's.
    fn campaign(
        rng: &mut ChaCha8Rng,
        shares: &[usize],
        (tests, lease, outside): (usize, usize, f64),
        draw: impl Fn(&mut ChaCha8Rng, u8, bool) -> u16,
    ) -> (f64, f64) {
        let names = ["w0", "w1", "w2", "w3"];
        let mut walk = Walk::default();
        let mut counts: BTreeMap<(String, String), Discordant> = BTreeMap::new();
        let mut pairs = PairCounts::new();
        let (mut honest_max, mut liar_max) = (1.0f64, 1.0f64);
        let mut index = 0;
        while index < tests {
            let worker = shares[rng.random_range(0..shares.len())];
            for _ in 0..lease {
                let stratum = u8::from(rng.random_bool(outside));
                let score = draw(rng, stratum, worker == 0);
                walk.step(run(names[worker], stratum, score, 1), &mut pairs);
                index += 1;
            }
            for ((a, b), t) in std::mem::take(&mut pairs) {
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

    #[test]
    fn honest_fleets_cross_a_level_no_more_often_than_ville_allows() {
        // 400 campaigns of 2,000 tests, strata of very different event
        // rates (0.6 in the library, 0.002 outside, half the rest with a
        // criticality) mixed unevenly, leases of 20 to uneven workers:
        // every worker honest. Ville bounds the chance that an honest
        // worker's e-value ever reaches 20 by 1/20 per worker.
        let mut rng = ChaCha8Rng::seed_from_u64(66);
        let runs = 400;
        let mut crossed = 0;
        let draw = |rng: &mut ChaCha8Rng, stratum: u8, _| match stratum {
            0 => event(rng, 0.6),
            _ if rng.random_bool(0.5) => rng.random_range(1..1001),
            _ => event(rng, 0.002),
        };
        for _ in 0..runs {
            let (honest, liar) = campaign(&mut rng, &UNEVEN, (2000, 20, 0.5), draw);
            crossed += usize::from(honest.max(liar) >= 20.0);
        }
        // Four workers: at most 4/20 of the campaigns in expectation; the
        // e-value of a worker leaving out a partner is smaller still.
        assert!(crossed <= runs / 10, "{crossed} of {runs}");
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
        let draw = |rng: &mut ChaCha8Rng, stratum: u8, liar: bool| match (stratum, liar) {
            (0, false) => event(rng, 0.6),
            (0, true) => event(rng, 0.35),
            _ => event(rng, 0.002),
        };
        for _ in 0..20 {
            let (honest, liar) = campaign(&mut rng, &[0, 1, 2, 3], (5000, 20, 0.5), draw);
            assert!(liar >= FLAG_AT, "{liar}");
            assert!(honest < FLAG_AT, "{honest}");
        }
    }
}
