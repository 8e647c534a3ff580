//! How many tests a new lease gets, and how far a campaign's leases may
//! reach: sized in seconds of work from what a test costs, and never much
//! more than the campaign can use (docs/operations.md, "Slow vehicles").
//!
//! **How far** ([`lease_limit`]): a campaign's `next_index` stays within
//! what its stop can still need. Before the prefix allows a prediction
//! (too few events), that is `max(n_min, 2 × resolved)`: the leased total
//! grows geometrically with what is resolved, not with what was leased
//! (workers that finish quickly and claim again while an earlier lease is
//! out would otherwise double it at every claim: 131,072 leased for a stop
//! at 25,138, measured). After, it is halfway from the prefix to the
//! prediction `n (rₙ/β)²` (the half-width shrinks as `1/√n`), in indices:
//! a prediction from few events is off by about `1/√events`, and the
//! workers take all the window at once (to the prediction itself, 16
//! workers of a 0.01 s program leased 3,008 tests for a stop at 1,938;
//! halfway, 1,973), and never less than `n_min`, before which no campaign
//! stops. It is always a step past the
//! resolved prefix while the campaign runs (a sixteenth of it, at least
//! one test), so a campaign whose rule waits on more than the prediction
//! (the outside guard) is never stalled; near the stop that step is what
//! workers may run for nothing (a quarter, as first, had 16 workers run
//! 3,191 tests of a program for an NDD campaign that used 1,938). An
//! adaptive campaign's leases reach the end of its running stage (its
//! results plan the next), an estimation stage's only what its estimate
//! can still need ([`stage_limit`]). A library build's reach its budget.
//!
//! **How many** ([`lease_size`]): `size_time = target · T / c` with `c`
//! the cost of one test on one thread and `T` the worker's threads: long
//! enough that the round trip is negligible, short enough that a lost
//! worker costs little. While nobody knows the cost (a program never run
//! here), one test per thread: its report sets `c`. And no more than the
//! worker's share of the window up to the limit, `⌈(limit − resolved) ·
//! T / W⌉` with `W` the threads of the live workers that can run the
//! campaign: a campaign that needs 100 tests, with 8 one-thread workers,
//! gives each about 13, not 256.

use crate::store::campaign_row::CampaignRow;
use tslg_api::{LeaseReach, Method};

/// Most tests in a lease: far above what the time target gives a test of
/// the fastest kernels (2 s on 2 threads at 40 ns a test is 10⁸), so the
/// target decides; the cap only bounds a cost measured absurdly low.
/// (It was 2²², which at today's 40–80 ns a cut-in test cut leases to a
/// fifth of a second, every lease a round trip and a ramp of chunks.)
pub const MAX_LEASE: u64 = 1 << 27;
/// Most tests in a lease of a library campaign: the old bound, kept where
/// the fold may draw again every test between its prefix and the frontier
/// to find the exploring ones (`report/fold.rs`, when a lagging lease's
/// last report clears the frontier: about one lease per other worker, at
/// about 10⁷ draws a second while the writer waits). For a built-in
/// vehicle the sets the coordinator's replay found are kept for that fold
/// (`report/explored.rs`); an external program's tests are always drawn.
pub const LIBRARY_MAX_LEASE: u64 = 1 << 22;
/// Leases carrying their tests inline are capped (response size).
pub const MAX_INLINE_LEASE: u64 = 10_000;

/// What a lease's size depends on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SizingInput {
    /// The asking worker's threads.
    pub threads: u32,
    /// Threads of the live workers that can run the campaign (the asking
    /// one among them).
    pub serving_threads: u32,
    /// Seconds per test on one thread, once measured.
    pub cost_per_test: Option<f64>,
    pub target_seconds: f64,
    /// The campaign's first index not yet leased.
    pub next_index: u64,
    /// Indices of the campaign's resolved prefix.
    pub resolved: u64,
    /// How far its leases may reach ([`lease_limit`]).
    pub limit: u64,
    /// The bound of the campaign's kind: [`MAX_LEASE`], or
    /// [`LIBRARY_MAX_LEASE`].
    pub max_lease: u64,
}

/// The size of a new lease; 0 when the campaign has leased all it may.
pub fn lease_size(input: &SizingInput) -> u64 {
    let left = input.limit.saturating_sub(input.next_index);
    if left == 0 {
        return 0;
    }
    let threads = u64::from(input.threads.max(1));
    let serving = u64::from(input.serving_threads.max(input.threads).max(1));
    let window = input.limit.saturating_sub(input.resolved);
    let share = (u128::from(window) * u128::from(threads)).div_ceil(u128::from(serving));
    let share = share.min(u128::from(u64::MAX)) as u64;
    let by_time = match input.cost_per_test {
        Some(c) if c > 0.0 && c.is_finite() => {
            (input.target_seconds * threads as f64 / c).min(input.max_lease as f64) as u64
        }
        _ => threads,
    };
    by_time.min(share).min(input.max_lease).max(1).min(left)
}

/// How far campaign `row`'s leases may reach: the most its `next_index`
/// may be (see the module's documentation). `frontier` is where its
/// recorded results end (`store::prefix::frontier`), read only for an
/// adaptive campaign's estimation stage; without it, the stage's start.
pub fn lease_limit(row: &CampaignRow, frontier: Option<u64>) -> u64 {
    let rule = row.fold_rule();
    let fold = row.fold();
    let stage = match (row.stage_start, row.stage_end) {
        (Some(start), Some(end)) => {
            let start = start.max(0) as u64;
            Some(RunningStage {
                start,
                end: end.max(0) as u64,
                estimation: row.stage_kind.as_deref() == Some("estimate"),
                frontier: frontier.unwrap_or(start).max(start),
            })
        }
        _ => None,
    };
    limit(&LimitInput {
        method: row.method,
        guard_outside: rule.guard_outside,
        max_tests: row.max_tests.max(0) as u64,
        stage,
        n_min: rule.n_min,
        min_events: rule.min_events,
        beta: rule.beta,
        // An adaptive campaign's row counts every index it resolved, its
        // estimate only the estimation tests' (valid and invalid).
        resolved: if row.method.in_stages() {
            fold.estimator.tests() + fold.invalid
        } else {
            fold.indices
        },
        tests: fold.estimator.tests(),
        events: fold.estimator.events(),
        relative_half_width: fold.relative_half_width(rule.z()),
    })
}

/// What [`lease_limit`] reads of a campaign.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LimitInput {
    pub method: Method,
    /// The campaign runs under the guard: an adaptive one reads its rule
    /// and guard at a stage's end only.
    pub guard_outside: bool,
    pub max_tests: u64,
    /// An adaptive campaign's running stage.
    pub stage: Option<RunningStage>,
    pub n_min: u64,
    pub min_events: u64,
    pub beta: f64,
    /// Indices of the resolved prefix (an adaptive campaign's: of its
    /// estimation tests), its valid tests and their events.
    pub resolved: u64,
    pub tests: u64,
    pub events: u64,
    /// `rₙ` of the prefix (infinite before it has an estimate).
    pub relative_half_width: f64,
}

/// An adaptive campaign's running stage `start..end`, and where its
/// recorded results end.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunningStage {
    pub start: u64,
    pub end: u64,
    /// An estimation stage, whose rule may stop the campaign inside it.
    pub estimation: bool,
    /// The first test (at least `start`) without a recorded result, or
    /// before an open audit.
    pub frontier: u64,
}

/// [`lease_limit`] of what a campaign's row says.
pub fn limit(input: &LimitInput) -> u64 {
    let max = input.max_tests;
    match input.method.spec().lease_reach {
        LeaseReach::All => return max,
        LeaseReach::Stage => return stage_limit(input),
        LeaseReach::Predicted => {}
    }
    let resolved = input.resolved;
    let wanted = match input.predicted() {
        // Valid tests to indices, at the prefix's share of valid tests;
        // halfway there: the prediction rests on few events at first
        // (`1/p̂` is off by about `1/√events`: a third at 10), and workers
        // take the whole window at once.
        // The stop is never before `n_min` tests: that part of the window
        // is certain, and leased whole (halving it cost a slow program's
        // campaign a round of the fleet per halving: 14, 7, 5, 3, 1 workers
        // busy over the last 27 of 100 tests, issue 68).
        Some(needed) => {
            let stop = in_indices(needed.max(input.n_min), resolved, input.tests).min(max);
            (resolved + stop.saturating_sub(resolved).div_ceil(2)).max(input.n_min)
        }
        None => input.n_min.max(resolved.saturating_mul(2)),
    };
    let step = (resolved / 16).max(1);
    wanted.max(resolved.saturating_add(step)).min(max)
}

/// An adaptive campaign's limit: the end of its running stage, whose
/// tests all plan the next (`report/stages.rs`); nothing while the next is
/// planned. An estimation stage's rule may stop the campaign inside it,
/// and `report/stages.rs` resolves the stage as soon as the recorded
/// results decide, so its leases reach what the estimate can still need,
/// in estimation indices as a library campaign's: the prediction of the
/// estimate before the stage, `n (rₙ/β)²`, else `max(n_min, 2 × resolved)`
/// counting the stage's recorded results (a campaign's first estimation
/// stage, often its last: one stopped 30 tests into a stage of 100, the
/// other 70 run for nothing, measured). Always a step past the recorded
/// results, an eighth of the stage, so the campaign goes on when the
/// prediction fell short.
fn stage_limit(input: &LimitInput) -> u64 {
    let Some(stage) = input.stage else {
        return 0;
    };
    let end = stage.end.min(input.max_tests);
    // A guarded campaign's stage is run whole (its rule and guard are read
    // at the stage's end), so it is leased whole: leased an eighth at a
    // time, a stage of 640 tests of 1 s kept 80 of 128 workers busy.
    if !stage.estimation || input.guard_outside {
        return end;
    }
    let before = input.resolved;
    let recorded = stage.frontier.saturating_sub(stage.start);
    let wanted = match input.predicted() {
        Some(needed) => in_indices(needed.max(input.n_min), before, input.tests),
        None => input
            .n_min
            .max(before.saturating_add(recorded).saturating_mul(2)),
    };
    let step = stage.end.saturating_sub(stage.start).div_ceil(8).max(1);
    stage
        .start
        .saturating_add(wanted.saturating_sub(before))
        .max(stage.frontier.saturating_add(step))
        .min(end)
}

/// `valid` tests in indices, at the share of valid tests a prefix of
/// `indices` indices and `tests` valid tests had.
fn in_indices(valid: u64, indices: u64, tests: u64) -> u64 {
    match tests {
        0 => valid,
        tests => (u128::from(valid) * u128::from(indices))
            .div_ceil(u128::from(tests))
            .min(u128::from(u64::MAX)) as u64,
    }
}

/// The valid tests that reach `β`, `n (r/β)²`, predicted from a prefix of
/// `n` valid tests with `events` events and relative half-width `r` (the
/// half-width shrinks as `1/√n`); none before `min_events` events (and
/// at least 2).
pub fn tests_to_beta(n: u64, events: u64, min_events: u64, r: f64, beta: f64) -> Option<u64> {
    if events < min_events.max(2) || !r.is_finite() {
        return None;
    }
    Some((n as f64 * (r / beta).powi(2)).min(1e15) as u64)
}

impl LimitInput {
    /// [`tests_to_beta`] of the prefix.
    fn predicted(&self) -> Option<u64> {
        tests_to_beta(
            self.tests,
            self.events,
            self.min_events,
            self.relative_half_width,
            self.beta,
        )
    }
}

/// The smoothed per-thread cost after a report of `tests` tests that took
/// `seconds` on `threads` threads: an exponential average with weight 0.3.
pub fn update_cost(previous: Option<f64>, tests: u64, seconds: f64, threads: u32) -> Option<f64> {
    if tests == 0 || !(seconds.is_finite() && seconds > 0.0) {
        return previous;
    }
    let sample = seconds * f64::from(threads.max(1)) / tests as f64;
    Some(match previous {
        Some(p) => 0.7 * p + 0.3 * sample,
        None => sample,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn input() -> SizingInput {
        SizingInput {
            threads: 4,
            serving_threads: 4,
            cost_per_test: None,
            target_seconds: 2.0,
            next_index: 0,
            resolved: 0,
            limit: u64::MAX,
            max_lease: MAX_LEASE,
        }
    }

    #[test]
    fn leases_hold_the_target_s_seconds_of_work_and_one_test_a_thread_before_a_cost() {
        // Nobody knows the cost: one test per thread.
        assert_eq!(lease_size(&input()), 4);
        // 0.5 µs per test: 2 s on 4 threads is 16 million.
        let cheap = SizingInput {
            cost_per_test: Some(5e-7),
            ..input()
        };
        assert_eq!(lease_size(&cheap), 16_000_000);
        // 40 ns per test on 2 threads: 10⁸, under the cap.
        let cheapest = SizingInput {
            threads: 2,
            serving_threads: 2,
            cost_per_test: Some(4e-8),
            ..input()
        };
        assert_eq!(lease_size(&cheapest), 100_000_000);
        // A cost measured absurdly low: the cap.
        let absurd = SizingInput {
            cost_per_test: Some(1e-12),
            ..input()
        };
        assert_eq!(lease_size(&absurd), MAX_LEASE);
        let library = SizingInput {
            max_lease: LIBRARY_MAX_LEASE,
            ..cheap
        };
        assert_eq!(lease_size(&library), LIBRARY_MAX_LEASE);
        // 1 ms per test: 8000 tests; 10 s: one a thread, not 16.
        let slow = SizingInput {
            cost_per_test: Some(1e-3),
            ..input()
        };
        assert_eq!(lease_size(&slow), 8000);
        let very_slow = SizingInput {
            cost_per_test: Some(10.0),
            ..input()
        };
        assert_eq!(lease_size(&very_slow), 1);
    }

    #[test]
    fn a_worker_takes_its_share_of_what_the_campaign_can_use() {
        // 100 tests wanted, 8 one-thread workers, 50 ms a test (40 tests
        // in 2 s): 13 each, not 40 (nor 2,048).
        let share = SizingInput {
            threads: 1,
            serving_threads: 8,
            cost_per_test: Some(0.05),
            limit: 100,
            ..input()
        };
        assert_eq!(lease_size(&share), 13);
        // Later: the share of what is not resolved, within what is left.
        let later = SizingInput {
            next_index: 91,
            resolved: 26,
            ..share
        };
        assert_eq!(lease_size(&later), 9);
        assert_eq!(
            lease_size(&SizingInput {
                next_index: 100,
                ..later
            }),
            0,
            "all leased: nothing"
        );
        // A worker of 4 threads takes 4 shares; one alone, everything.
        let big = SizingInput {
            threads: 4,
            serving_threads: 11,
            ..share
        };
        assert_eq!(lease_size(&big), 37);
        let alone = SizingInput {
            serving_threads: 0,
            cost_per_test: Some(1e-6),
            ..share
        };
        assert_eq!(lease_size(&alone), 100);
    }

    fn campaign() -> LimitInput {
        LimitInput {
            method: Method::Ndd,
            guard_outside: false,
            max_tests: 10_000_000,
            stage: None,
            n_min: 100,
            min_events: 10,
            beta: 0.2,
            resolved: 0,
            tests: 0,
            events: 0,
            relative_half_width: f64::INFINITY,
        }
    }

    #[test]
    fn a_campaign_leases_what_its_stop_can_still_need() {
        // Before any result: n_min.
        assert_eq!(limit(&campaign()), 100);
        // Before a prediction: twice what is resolved.
        let growing = LimitInput {
            resolved: 1000,
            tests: 990,
            events: 3,
            ..campaign()
        };
        assert_eq!(limit(&growing), 2000);
        // After: halfway to n (r/β)² valid tests, in indices (1 %
        // invalid): 3960 valid tests, 4000 indices, 2500.
        let predicted = LimitInput {
            resolved: 1000,
            tests: 990,
            events: 30,
            relative_half_width: 0.4,
            ..campaign()
        };
        assert_eq!(limit(&predicted), 1000 + (3960 * 1000 / 990 - 1000) / 2);
        // A prediction below n_min: the window to n_min is certain and
        // leased whole, not halved (73 resolved of a stop at 100).
        let short = LimitInput {
            resolved: 73,
            tests: 73,
            events: 12,
            relative_half_width: 0.1,
            ..campaign()
        };
        assert_eq!(limit(&short), 100);
        let nearer = LimitInput {
            resolved: 3000,
            tests: 2970,
            relative_half_width: 0.2 * (3960.0f64 / 2970.0).sqrt(),
            ..predicted
        };
        assert_eq!(limit(&nearer), 3500, "halfway to 4,000");
        // A rule that waits on more than the prediction (the outside
        // guard) is never stalled: a sixteenth past the prefix.
        let waiting = LimitInput {
            relative_half_width: 0.1,
            ..predicted
        };
        assert_eq!(limit(&waiting), 1062);
        // The budget bounds it, and so does an adaptive campaign's running
        // stage; a build's budget decides alone.
        assert_eq!(
            limit(&LimitInput {
                max_tests: 150,
                ..predicted
            }),
            150
        );
        // An adaptive campaign's library or search stage: all of it (its
        // results plan the next), whatever the estimate predicts.
        let running = RunningStage {
            start: 2000,
            end: 2400,
            estimation: false,
            frontier: 2000,
        };
        let stage = LimitInput {
            method: Method::Adaptive,
            stage: Some(running),
            ..predicted
        };
        assert_eq!(limit(&stage), 2400, "a search stage");
        assert_eq!(
            limit(&LimitInput {
                stage: None,
                ..stage
            }),
            0,
            "no stage runs while the next is planned"
        );
        // An estimation stage: what the estimate before it predicts,
        // 990 (0.22/0.2)² = 1197 valid tests, 1210 indices, 210 more, then
        // a step past the recorded results (an eighth of the stage, 50).
        let estimation = |frontier| LimitInput {
            stage: Some(RunningStage {
                estimation: true,
                frontier,
                ..running
            }),
            relative_half_width: 0.22,
            ..stage
        };
        assert_eq!(limit(&estimation(2000)), 2210);
        assert_eq!(limit(&estimation(2210)), 2260, "the prediction fell short");
        assert_eq!(limit(&estimation(2390)), 2400, "within the stage");
        assert_eq!(
            limit(&LimitInput {
                max_tests: 2100,
                ..estimation(2000)
            }),
            2100
        );
        // The first estimation stage (no estimate before it, n_min 30, a
        // stage of 100 from 667): n_min, then twice what is recorded.
        let first = |frontier| LimitInput {
            stage: Some(RunningStage {
                start: 667,
                end: 767,
                estimation: true,
                frontier,
            }),
            n_min: 30,
            resolved: 0,
            tests: 0,
            events: 0,
            relative_half_width: f64::INFINITY,
            ..stage
        };
        assert_eq!(limit(&first(667)), 697);
        assert_eq!(limit(&first(697)), 727);
        assert_eq!(limit(&first(727)), 767);
        assert_eq!(limit(&first(760)), 767);
        // Under the guard the stage runs whole, and is leased whole.
        let guarded = LimitInput {
            guard_outside: true,
            ..first(667)
        };
        assert_eq!(limit(&guarded), 767);
        assert_eq!(
            limit(&LimitInput {
                method: Method::Enumerate,
                ..predicted
            }),
            10_000_000
        );
    }

    #[test]
    fn the_prediction_scales_with_the_squared_precision_ratio() {
        // n = 100 at r = 0.4 with β = 0.2 needs 400.
        assert_eq!(tests_to_beta(100, 12, 10, 0.4, 0.2), Some(400));
        assert_eq!(tests_to_beta(100, 1, 10, 0.4, 0.2), None);
        assert_eq!(tests_to_beta(100, 12, 10, f64::INFINITY, 0.2), None);
        let c = update_cost(None, 1000, 0.5, 2).unwrap();
        assert!((c - 1e-3).abs() < 1e-15);
        let c2 = update_cost(Some(c), 1000, 1.0, 2).unwrap();
        assert!((c2 - (0.7e-3 + 0.3 * 2e-3)).abs() < 1e-15);
        assert_eq!(update_cost(Some(c), 0, 1.0, 2), Some(c));
    }
}
