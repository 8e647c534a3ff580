//! Tests per second of each running campaign, from the results accepted in
//! the last minute, and the time left that it predicts. Kept in memory:
//! after a restart the rate is known again after two reports.

use std::collections::{HashMap, VecDeque};
use std::sync::Mutex;
use std::time::{Duration, Instant};
use tslg_api::CampaignView;

/// The window the rate is measured over.
const WINDOW: Duration = Duration::from_secs(60);
/// A rate needs reports spread over at least this many seconds (two
/// reports a moment apart would give an absurd one).
const MIN_SPAN: f64 = 1.0;
/// Reports remembered per campaign at most (older ones go first).
const MAX_SAMPLES: usize = 4096;

#[derive(Default)]
pub struct Throughput {
    /// Per campaign: when each report was accepted and its new tests.
    campaigns: Mutex<HashMap<i64, VecDeque<(Instant, u64)>>>,
}

impl Throughput {
    /// Records `accepted` new tests of `campaign`, now.
    pub fn accepted(&self, campaign: i64, accepted: u64) {
        self.accepted_at(campaign, accepted, Instant::now());
    }

    fn accepted_at(&self, campaign: i64, accepted: u64, at: Instant) {
        let mut campaigns = self.campaigns.lock().unwrap_or_else(|p| p.into_inner());
        let samples = campaigns.entry(campaign).or_default();
        samples.push_back((at, accepted));
        while samples.len() > MAX_SAMPLES
            || samples
                .front()
                .is_some_and(|(t, _)| at.duration_since(*t) > WINDOW)
        {
            samples.pop_front();
        }
    }

    /// Forgets a campaign that stopped.
    pub fn forget(&self, campaign: i64) {
        let mut campaigns = self.campaigns.lock().unwrap_or_else(|p| p.into_inner());
        campaigns.remove(&campaign);
    }

    /// Tests per second: the tests of the reports after the oldest one in
    /// the window, over the time since that one. `None` with fewer than two
    /// reports in the window.
    pub fn per_second(&self, campaign: i64) -> Option<f64> {
        self.per_second_at(campaign, Instant::now())
    }

    fn per_second_at(&self, campaign: i64, now: Instant) -> Option<f64> {
        let campaigns = self.campaigns.lock().unwrap_or_else(|p| p.into_inner());
        let samples = campaigns.get(&campaign)?;
        let mut recent = samples
            .iter()
            .filter(|(t, _)| now.duration_since(*t) <= WINDOW);
        let (first, _) = recent.next()?;
        let (count, tests) = recent.fold((0, 0u64), |(c, n), (_, a)| (c + 1, n + a));
        let seconds = now.duration_since(*first).as_secs_f64();
        (count > 0 && seconds >= MIN_SPAN).then(|| tests as f64 / seconds)
    }

    /// Fills the rate and the time left of a running campaign's view: the
    /// rate measured over the last minute, else (no two reports a second
    /// apart yet: a slow vehicle's first tests) what the workers able to
    /// run it can do, `capacity` (their threads over the cost of a test).
    pub fn fill(&self, view: &mut CampaignView, capacity: Option<f64>) {
        if view.status.is_final() {
            return;
        }
        view.tests_per_second = self
            .per_second(view.id)
            .or(capacity.filter(|c| c.is_finite() && *c > 0.0));
        // The rate counts every accepted test; the prediction valid ones.
        let valid_share = view.tests as f64 / view.indices.max(1) as f64;
        view.seconds_left = match (view.predicted_tests, view.tests_per_second) {
            (Some(needed), Some(rate)) if rate * valid_share > 0.0 => {
                Some(needed.saturating_sub(view.tests) as f64 / (rate * valid_share))
            }
            _ => None,
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rate_is_the_tests_after_the_first_report_over_the_time_since_it() {
        let t = Throughput::default();
        let start = Instant::now();
        let at = |s: f64| start + Duration::from_secs_f64(s);
        assert_eq!(t.per_second_at(1, at(0.0)), None);
        t.accepted_at(1, 500, at(0.0));
        t.accepted_at(3, 500, at(0.0));
        t.accepted_at(3, 500, at(0.001));
        assert_eq!(
            t.per_second_at(3, at(0.002)),
            None,
            "two reports a moment apart give none"
        );
        assert_eq!(
            t.per_second_at(1, at(1.0)),
            None,
            "one report gives no rate"
        );
        t.accepted_at(1, 100, at(1.0));
        t.accepted_at(1, 300, at(2.0));
        assert_eq!(t.per_second_at(1, at(4.0)), Some(100.0));
        // Reports leave the window after a minute; the rate then falls to
        // what the last minute saw, and to nothing without reports.
        t.accepted_at(1, 600, at(61.5));
        assert_eq!(t.per_second_at(1, at(62.0)), Some(600.0 / 60.0));
        assert_eq!(t.per_second_at(1, at(200.0)), None);
        assert_eq!(t.per_second_at(2, at(4.0)), None, "per campaign");
        t.forget(1);
        assert_eq!(t.per_second_at(1, at(62.0)), None);
    }
}
