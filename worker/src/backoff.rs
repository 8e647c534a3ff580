//! Exponential backoff with full jitter: the k-th consecutive wait is
//! uniform in `[0, min(max, base · 2ᵏ)]`, so many idle or disconnected
//! workers spread their retries instead of arriving together.

use rand::Rng;
use std::time::Duration;

#[derive(Debug, Clone)]
pub struct Backoff {
    base: f64,
    max: f64,
    failures: u32,
}

impl Backoff {
    pub fn new(base_seconds: f64, max_seconds: f64) -> Self {
        Self {
            base: base_seconds,
            max: max_seconds,
            failures: 0,
        }
    }

    /// The ceiling of the next wait.
    pub fn ceiling(&self) -> f64 {
        (self.base * 2f64.powi(self.failures.min(30) as i32)).min(self.max)
    }

    /// The next wait; each call raises the ceiling until [`Self::reset`].
    pub fn next_wait<R: Rng + ?Sized>(&mut self, rng: &mut R) -> Duration {
        let wait = rng.random_range(0.0..=self.ceiling());
        self.failures = self.failures.saturating_add(1);
        Duration::from_secs_f64(wait)
    }

    pub fn reset(&mut self) {
        self.failures = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn waits_grow_to_the_cap_stay_jittered_and_reset() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(1);
        let mut b = Backoff::new(0.05, 2.0);
        let ceilings: Vec<f64> = (0..8)
            .map(|_| {
                let c = b.ceiling();
                let w = b.next_wait(&mut rng).as_secs_f64();
                assert!((0.0..=c).contains(&w));
                c
            })
            .collect();
        assert_eq!(ceilings[..6], [0.05, 0.1, 0.2, 0.4, 0.8, 1.6]);
        assert_eq!(ceilings[6..], [2.0, 2.0]);
        let waits: Vec<f64> = (0..50)
            .map(|_| b.next_wait(&mut rng).as_secs_f64())
            .collect();
        let distinct = waits
            .iter()
            .filter(|&&w| (w - waits[0]).abs() > 1e-9)
            .count();
        assert!(distinct > 40, "waits are jittered");
        b.reset();
        assert_eq!(b.ceiling(), 0.05);
    }
}
