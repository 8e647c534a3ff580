//! How many tests a new lease gets.
//!
//! A lease should keep a worker busy for about `target` seconds: long enough
//! that the round trip is negligible, short enough that a lost worker costs
//! little and the campaign does not overshoot its stop. With `c` the
//! smoothed cost of one test on one thread and `T` the worker's threads,
//! `size_time = target · T / c`. Near the goal the lease shrinks further:
//! from the current prefix, `n_needed ≈ n (rₙ/β)²` tests reach `rₙ = β`
//! (the half-width shrinks as `1/√n`), so no lease takes more than half of
//! the tests predicted to be still unleased. Before the prefix allows a
//! prediction (too few events), a lease holds at most half as many tests
//! as the prefix has resolved (and at least a first lease): the leases
//! grow geometrically with the prefix, so a campaign that turns out to
//! need `N` tests is leased about `N` plus the leases in flight when it
//! stops (each at most `N/2`), not a few seconds of work of a cheap test
//! (millions) after a few thousand. Growth is tied to what is resolved,
//! not to what was leased: workers that finish quickly and claim again
//! while an earlier lease is still out would otherwise double the leased
//! total at every claim (measured: 131,072 leased for a stop at 25,138).

/// Fewest tests in a lease.
pub const MIN_LEASE: u64 = 16;
/// Most tests in a lease: far above what the time target gives a test of
/// the fastest kernels (2 s on 2 threads at 40 ns a test is 10⁸), so the
/// target decides; the cap only bounds a cost measured absurdly low.
/// (It was 2²², which at today's 40–80 ns a cut-in test cut leases to a
/// fifth of a second, every lease a round trip and a ramp of chunks.)
pub const MAX_LEASE: u64 = 1 << 27;
/// Most tests in a lease of a library campaign: the old bound, kept where
/// the fold may draw again every test between its prefix and the frontier
/// to find the exploring ones (`store/fold.rs`, when a lagging lease's
/// last report clears the frontier: about one lease per other worker, at
/// about 10⁷ draws a second while the writer waits). For a built-in
/// vehicle the sets the coordinator's replay found are kept for that fold
/// (`explored_ranges.rs`); an external program's tests are always drawn.
pub const LIBRARY_MAX_LEASE: u64 = 1 << 22;
/// Tests per thread of a campaign's first leases, before any cost is known.
pub const FIRST_LEASE_PER_THREAD: u64 = 256;
/// Leases carrying their tests inline are capped (response size).
pub const MAX_INLINE_LEASE: u64 = 10_000;

/// What the size depends on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SizingInput {
    pub threads: u32,
    /// Seconds per test on one thread, once measured.
    pub cost_per_test: Option<f64>,
    pub target_seconds: f64,
    /// Indices left in the budget: `max_tests − next_index`.
    pub budget_left: u64,
    /// `n_needed − next_index`, when the prefix allows a prediction.
    pub predicted_unleased: Option<u64>,
    /// Tests of the campaign's resolved prefix (every outcome below is
    /// recorded and folded).
    pub resolved: u64,
    /// The bound of the campaign's kind: [`MAX_LEASE`], or
    /// [`LIBRARY_MAX_LEASE`].
    pub max_lease: u64,
}

pub fn lease_size(input: &SizingInput) -> u64 {
    let threads = f64::from(input.threads.max(1));
    let by_time = match input.cost_per_test {
        Some(c) if c > 0.0 => {
            (input.target_seconds * threads / c).min(input.max_lease as f64) as u64
        }
        _ => FIRST_LEASE_PER_THREAD * u64::from(input.threads.max(1)),
    };
    let first = FIRST_LEASE_PER_THREAD * u64::from(input.threads.max(1));
    let by_goal = input
        .predicted_unleased
        .map_or((input.resolved / 2).max(first), |left| {
            (left / 2).max(MIN_LEASE)
        });
    by_time
        .min(by_goal)
        .clamp(MIN_LEASE, input.max_lease.max(MIN_LEASE))
        .min(input.budget_left)
}

/// Tests still needed beyond `next_index`, predicted from a prefix of `n`
/// valid tests with `events` events and relative half-width `r`.
pub fn predicted_unleased(
    n: u64,
    events: u64,
    min_events: u64,
    r: f64,
    beta: f64,
    next_index: u64,
) -> Option<u64> {
    if events < min_events.max(2) || !r.is_finite() {
        return None;
    }
    let needed = (n as f64 * (r / beta).powi(2)).min(1e15) as u64;
    Some(needed.saturating_sub(next_index))
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
            cost_per_test: None,
            target_seconds: 2.0,
            budget_left: u64::MAX,
            predicted_unleased: None,
            resolved: u64::MAX,
            max_lease: MAX_LEASE,
        }
    }

    #[test]
    fn cheap_tests_get_large_leases_and_slow_tests_small_ones() {
        assert_eq!(lease_size(&input()), 1024);
        // 0.5 µs per test: 2 s on 4 threads is 16 million.
        let cheap = SizingInput {
            cost_per_test: Some(5e-7),
            ..input()
        };
        assert_eq!(lease_size(&cheap), 16_000_000);
        // 40 ns per test on 2 threads: 10⁸, under the cap.
        let cheapest = SizingInput {
            threads: 2,
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
        // A library campaign's bound.
        let library = SizingInput {
            max_lease: LIBRARY_MAX_LEASE,
            ..cheap
        };
        assert_eq!(lease_size(&library), LIBRARY_MAX_LEASE);
        // 1 ms per test: 8000 tests.
        let slow = SizingInput {
            cost_per_test: Some(1e-3),
            ..input()
        };
        assert_eq!(lease_size(&slow), 8000);
        // 10 s per test: the minimum.
        let very_slow = SizingInput {
            cost_per_test: Some(10.0),
            ..input()
        };
        assert_eq!(lease_size(&very_slow), MIN_LEASE);
    }

    #[test]
    fn before_a_prediction_leases_hold_at_most_half_the_resolved_prefix() {
        let cheap = SizingInput {
            cost_per_test: Some(5e-7),
            resolved: 0,
            ..input()
        };
        // The first leases: 256 a thread.
        assert_eq!(lease_size(&cheap), 1024);
        let grown = SizingInput {
            resolved: 100_000,
            ..cheap
        };
        assert_eq!(lease_size(&grown), 50_000);
        // A prediction decides once there is one.
        let predicted = SizingInput {
            predicted_unleased: Some(1_000_000),
            ..grown
        };
        assert_eq!(lease_size(&predicted), 500_000);
    }

    #[test]
    fn leases_shrink_near_the_goal_and_respect_the_budget() {
        let near = SizingInput {
            cost_per_test: Some(1e-6),
            predicted_unleased: Some(1000),
            ..input()
        };
        assert_eq!(lease_size(&near), 500);
        let past = SizingInput {
            predicted_unleased: Some(0),
            ..near
        };
        assert_eq!(lease_size(&past), MIN_LEASE);
        let budget = SizingInput {
            budget_left: 7,
            ..near
        };
        assert_eq!(lease_size(&budget), 7);
    }

    #[test]
    fn the_prediction_scales_with_the_squared_precision_ratio() {
        // n = 100 at r = 0.4 with β = 0.2 needs 400; 150 are leased.
        assert_eq!(predicted_unleased(100, 12, 10, 0.4, 0.2, 150), Some(250));
        assert_eq!(predicted_unleased(100, 1, 10, 0.4, 0.2, 150), None);
        assert_eq!(
            predicted_unleased(100, 12, 10, f64::INFINITY, 0.2, 150),
            None
        );
        let c = update_cost(None, 1000, 0.5, 2).unwrap();
        assert!((c - 1e-3).abs() < 1e-15);
        let c2 = update_cost(Some(c), 1000, 1.0, 2).unwrap();
        assert!((c2 - (0.7e-3 + 0.3 * 2e-3)).abs() < 1e-15);
        assert_eq!(update_cost(Some(c), 0, 1.0, 2), Some(c));
    }
}
