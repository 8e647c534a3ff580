//! A campaign's history for plots, kept small at both ends.
//!
//! Storage keeps a fold's point only when its resolved prefix has grown by
//! the factor [`STORE_RATIO`] since the last kept point (and always the
//! point where the campaign stopped), so a campaign of `n` tests keeps about
//! `ln n / ln 1.01` points however small its result batches: about 1,700 for
//! 10⁷ tests. Reads pick at most `points` of those, logarithmically spaced in
//! the number of resolved tests, which is how the plots draw them.

use crate::store::campaigns::{self, CampaignRow};
use crate::store::error::StoreError;
use rusqlite::Connection;
use tslg_api::HistoryPoint;
use tslg_method::estimator::ImportanceEstimator;
use tslg_method::outside::OutsideTally;
use tslg_method::prefix::PrefixFold;

/// A fold's point is stored when `indices ≥ STORE_RATIO · last stored`.
pub const STORE_RATIO: f64 = 1.01;
/// Points a history read returns when it does not say.
pub const DEFAULT_POINTS: usize = 300;
/// The most points a history read may ask for.
pub const MAX_POINTS: usize = 5000;

/// Whether a fold that resolved `indices` is stored after `last_stored`.
pub fn worth_storing(last_stored: Option<u64>, indices: u64) -> bool {
    last_stored.is_none_or(|last| indices as f64 >= last as f64 * STORE_RATIO)
}

/// At most `max` of `points` (in index order), the first and the last among
/// them, the others the first at or after each of the targets
/// `x₀ · (x_last / x₀)^(k / (max − 1))` in resolved indices `x`.
pub fn log_downsample(points: Vec<HistoryPoint>, max: usize) -> Vec<HistoryPoint> {
    let max = max.max(2);
    if points.len() <= max {
        return points;
    }
    let first = points[0].indices.max(1) as f64;
    let last = points[points.len() - 1].indices.max(1) as f64;
    let ratio = (last / first).ln() / (max - 1) as f64;
    let mut kept = Vec::with_capacity(max);
    let mut next = 0usize;
    for k in 0..max {
        let target = first * (ratio * k as f64).exp();
        while next < points.len() - 1 && (points[next].indices as f64) < target * (1.0 - 1e-12) {
            next += 1;
        }
        if kept.last() != Some(&next) {
            kept.push(next);
        }
    }
    if kept.last() != Some(&(points.len() - 1)) {
        kept.push(points.len() - 1);
    }
    let mut chosen = kept.into_iter().peekable();
    points
        .into_iter()
        .enumerate()
        .filter_map(|(i, p)| match chosen.peek() {
            Some(&c) if c == i => {
                chosen.next();
                Some(p)
            }
            _ => None,
        })
        .collect()
}

/// The persisted history of a campaign's prefix estimate (thinned as
/// this module says), ending at the campaign's current prefix: at most
/// `max` points, logarithmically spaced in tests.
pub fn read(
    conn: &Connection,
    row: &CampaignRow,
    max: usize,
) -> Result<Vec<HistoryPoint>, StoreError> {
    let rows = campaigns::history_rows(conn, row.id)?;
    let z = row.rule().z();
    let mut points: Vec<HistoryPoint> = rows
        .into_iter()
        .map(
            |(indices, tests, events, s1, s2, outside_tests, outside_s1, low, high, outside_s2)| {
                let fold = PrefixFold {
                    estimator: ImportanceEstimator::from_sums(tests as u64, events as u64, s1, s2),
                    indices: indices as u64,
                    invalid: (indices - tests) as u64,
                    outside: OutsideTally {
                        tests: outside_tests as u64,
                        s1: outside_s1,
                        s2: outside_s2.unwrap_or(0.0),
                        ..OutsideTally::default()
                    },
                    strata: row.strata_epsilon,
                    within_strata: row.strata_epsilon.is_some()
                        && row.tracks_within_strata()
                        && outside_s2.is_some(),
                };
                point_of(&fold, z, low.zip(high))
            },
        )
        .collect();
    let current = row.fold();
    if current.indices > points.last().map_or(0, |p| p.indices) {
        points.push(point_of(&current, z, row.sequence()));
    }
    Ok(log_downsample(points, max))
}

/// The estimate, interval and relative half-width of a prefix.
pub fn point(fold: &PrefixFold, z: f64) -> HistoryPoint {
    let e = &fold.estimator;
    let (ci_low, ci_high) = fold.interval(z);
    let r = fold.relative_half_width(z);
    HistoryPoint {
        tests: e.tests(),
        indices: fold.indices,
        events: e.events(),
        estimate: fold.estimate(),
        half_width: if e.tests() > 0 {
            fold.half_width(z)
        } else {
            0.0
        },
        relative_half_width: r.is_finite().then_some(r),
        ci_low: if e.tests() > 0 { ci_low } else { 0.0 },
        ci_high: if e.tests() > 0 { ci_high } else { 0.0 },
    }
}

/// [`point`] with the interval of a confidence sequence, `[low, high]`,
/// where the campaign reads one (an anytime campaign): its half-width is
/// `(high − low)/2`.
pub fn point_of(fold: &PrefixFold, z: f64, sequence: Option<(f64, f64)>) -> HistoryPoint {
    let mut point = point(fold, z);
    if let (Some((low, high)), true) = (sequence, fold.estimator.tests() > 0) {
        point.ci_low = low;
        point.ci_high = high;
        point.half_width = (high - low) / 2.0;
        point.relative_half_width =
            (point.estimate > 0.0).then(|| point.half_width / point.estimate);
    }
    point
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(indices: u64) -> HistoryPoint {
        HistoryPoint {
            tests: indices,
            indices,
            events: 0,
            estimate: 0.0,
            half_width: 0.0,
            relative_half_width: None,
            ci_low: 0.0,
            ci_high: 0.0,
        }
    }

    /// What storage keeps of a campaign folded in batches of `batch` up to `n`.
    fn stored(batch: u64, n: u64) -> Vec<HistoryPoint> {
        let mut kept: Vec<HistoryPoint> = Vec::new();
        let mut indices = 0;
        while indices < n {
            indices = (indices + batch).min(n);
            if worth_storing(kept.last().map(|p| p.indices), indices) || indices == n {
                kept.push(at(indices));
            }
        }
        kept
    }

    #[test]
    fn a_ten_million_test_baseline_returns_a_few_hundred_log_spaced_points() {
        // Results of 100 tests at a time: 10⁵ folds.
        let kept = stored(100, 10_000_000);
        // Every fold up to 10⁴ (each grows the prefix by ≥ 1 %), then one
        // per 1 %: 99 + ln(10³) / ln(1.01) ≈ 793 at most.
        assert!((700..800).contains(&kept.len()), "{}", kept.len());
        let read = log_downsample(kept, DEFAULT_POINTS);
        assert!(
            (200..=DEFAULT_POINTS).contains(&read.len()),
            "{}",
            read.len()
        );
        assert_eq!(read.first().unwrap().indices, 100);
        assert_eq!(read.last().unwrap().indices, 10_000_000);
        // Evenly spread on a log axis: every decade holds about its share.
        for decade in 3..7 {
            let (low, high) = (10u64.pow(decade), 10u64.pow(decade + 1));
            let inside = read
                .iter()
                .filter(|p| (low..high).contains(&p.indices))
                .count();
            assert!((50..=80).contains(&inside), "decade 1e{decade}: {inside}");
        }
        assert!(read.windows(2).all(|w| w[0].indices < w[1].indices));
    }

    #[test]
    fn short_histories_are_returned_whole_and_the_stop_is_always_kept() {
        let whole: Vec<_> = (1..=50).map(at).collect();
        assert_eq!(log_downsample(whole.clone(), 300), whole);
        // Storage: every fold while each grows the prefix by 1 %, then sparser.
        let kept = stored(1, 1000);
        assert_eq!(
            kept[..100].iter().map(|p| p.indices).collect::<Vec<_>>(),
            (1..=100).collect::<Vec<_>>()
        );
        assert_eq!(kept.last().unwrap().indices, 1000);
        let two = log_downsample(kept, 2);
        assert_eq!(two.iter().map(|p| p.indices).collect::<Vec<_>>(), [1, 1000]);
    }
}
