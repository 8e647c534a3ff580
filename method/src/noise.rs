//! The noise of a vehicle that is not bit-reproducible.
//!
//! A built-in model with `"noise": σ` adds `σ Z` to every commanded
//! acceleration, `Z` standard normal. Its draws come from a stream of the
//! test's own, so the outcome of a scenario is random while test `i` of a
//! campaign seeded `s` is still one fixed computation: a worker's run, the
//! coordinator's replay and the in-process campaign agree bit for bit, as
//! for a deterministic vehicle.
//!
//! The noise stream of test `i` is ChaCha8 at stream `i` under a key of
//! its own: the first 32 bytes of the campaign key's stream `u64::MAX`,
//! which no test's scenario stream uses ([`crate::test_stream`] keys test
//! `i`'s scenario at stream `i`). So the noise is independent of the
//! scenario, and both vehicles of a paired test (same seed, same index)
//! share it: common random numbers, which make the difference of two
//! noisy vehicles' rates as cheap to estimate as the noise allows.
//! A program gets [`noise_seed`] in its `reset` for the same purpose.

use rand::{Rng, RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// A test's noise stream.
pub type NoiseRng = ChaCha8Rng;

/// The campaign key's stream that keys the noise streams.
const NOISE_KEY_STREAM: u64 = u64::MAX;

/// The noise stream of test `index` of the campaign seeded `seed`.
pub fn noise_rng(seed: u64, index: u64) -> NoiseRng {
    let mut keyer = ChaCha8Rng::seed_from_u64(seed);
    keyer.set_stream(NOISE_KEY_STREAM);
    let mut key = [0u8; 32];
    keyer.fill_bytes(&mut key);
    let mut rng = ChaCha8Rng::from_seed(key);
    rng.set_stream(index);
    rng
}

/// A 64-bit seed for test `index` of the campaign seeded `seed`, from its
/// noise stream: what a program is handed to seed its own noise with, so
/// that paired and repeated runs can share it.
pub fn noise_seed(seed: u64, index: u64) -> u64 {
    noise_rng(seed, index).next_u64()
}

/// Whether a vehicle specification (normalised or as written) has noise
/// on its commands: `"noise"` above 0.
pub fn spec_is_noisy(spec: &serde_json::Value) -> bool {
    spec.get("noise")
        .and_then(|n| n.as_f64())
        .is_some_and(|n| n > 0.0)
}

/// Why a noisy vehicle cannot be a library's surrogate.
pub const NOISY_SURROGATE: &str = "a library's surrogate must be deterministic: its \
    criticality of a scenario is its library's, not a draw; drop the surrogate's noise (the \
    vehicle under test may have some)";

/// The most scenarios on which a coordinator works out a noisy vehicle's
/// Monte Carlo `P(A)` when a campaign starts ([`crate::exact::event_rates`]
/// runs every cell 1,000 times; some 2 s on cut-in's 3,420 cells): beyond
/// it the campaign has no reference value, and `tslg exact` gives one.
pub const NOISY_EXACT_MAX_SCENARIOS: usize = 10_000;

/// The noise on one test's commands: `σ Z` per command.
#[derive(Debug, Clone)]
pub struct CommandNoise {
    sigma: f64,
    rng: NoiseRng,
}

impl CommandNoise {
    /// Noise of σ `sigma` drawn from `rng`.
    pub fn new(sigma: f64, rng: NoiseRng) -> Self {
        Self { sigma, rng }
    }

    /// The next command's noise.
    pub fn draw(&mut self) -> f64 {
        let z: f64 = self.rng.sample(StandardNormal);
        self.sigma * z
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_stream::long_test_rng;

    #[test]
    fn the_noise_stream_is_fixed_per_test_and_apart_from_the_scenario_stream() {
        let mut first = noise_rng(7, 3);
        let mut again = noise_rng(7, 3);
        let words: Vec<u64> = (0..8).map(|_| first.next_u64()).collect();
        assert_eq!(words, (0..8).map(|_| again.next_u64()).collect::<Vec<_>>());
        // Another test, another campaign, and the scenario stream itself
        // all differ from it.
        let mut other_test = noise_rng(7, 4);
        let mut other_seed = noise_rng(8, 3);
        let mut scenario = long_test_rng(7, 3);
        assert_ne!(words[0], other_test.next_u64());
        assert_ne!(words[0], other_seed.next_u64());
        assert_ne!(words[0], scenario.next_u64());
        assert_eq!(noise_seed(7, 3), words[0]);
    }

    #[test]
    fn command_noise_has_the_stated_spread() {
        // σ = 1.5 over 200,000 draws of one stream: the sample mean and
        // standard deviation within 4.5 standard errors.
        let mut noise = CommandNoise::new(1.5, noise_rng(1, 0));
        let n = 200_000;
        let draws: Vec<f64> = (0..n).map(|_| noise.draw()).collect();
        let mean = draws.iter().sum::<f64>() / n as f64;
        let var = draws.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        assert!(mean.abs() < 4.5 * 1.5 / (n as f64).sqrt(), "{mean}");
        // The standard error of s² is about σ²√(2/n).
        assert!(
            (var - 2.25).abs() < 4.5 * 2.25 * (2.0 / n as f64).sqrt(),
            "{var}"
        );
    }
}
