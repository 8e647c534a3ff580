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
//!
//! Built-in vehicles have four kinds of noise ([`Noise`]): additive and
//! multiplicative noise on the actuator, a range sensor's relative error,
//! and a random reaction time. They exist so that a rule for noisy vehicles
//! can be checked on noise it was not designed on (docs/statistics.md,
//! "Noisy vehicles").

use rand::{Rng, RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

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
/// on its runs: `"noise"` a number above 0, or a kind of noise whose σ is
/// above 0.
pub fn spec_is_noisy(spec: &serde_json::Value) -> bool {
    match spec.get("noise") {
        Some(serde_json::Value::Number(n)) => n.as_f64().is_some_and(|n| n > 0.0),
        Some(serde_json::Value::Object(kind)) => kind
            .get("sigma")
            .and_then(|n| n.as_f64())
            .is_some_and(|n| n > 0.0),
        _ => false,
    }
}

/// Whether a campaign whose request does not say runs under the outside
/// guard: when its vehicle is `noisy` and it has an outside to guard
/// (`guardable`: a library or adaptive campaign of a grid case, neither
/// paired nor read on an anytime interval, whose sequence bounds the
/// outside already). A noisy vehicle's scenarios fail with a probability,
/// so whether its library or support holds every one that can fail is
/// never checkable from a few runs: the guard is what makes its answer,
/// the guarded interval, narrow enough to use (docs/statistics.md, "Noisy
/// vehicles").
pub fn guards_by_default(noisy: bool, guardable: bool) -> bool {
    noisy && guardable
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

/// How a noisy built-in vehicle's runs of one scenario differ: what its
/// `"noise"` says. A number is σ of additive noise (the first kind, and
/// the written form it keeps); an object names another kind, `{"kind":
/// "perception", "sigma": 0.1}`. Each kind draws from the test's noise
/// stream only, so every run of one test is the same computation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Noise {
    /// `σ Z` (m/s²) added to every command, before the world's bounds:
    /// an actuator that misses its command by a constant spread.
    Additive(f64),
    /// A kind named by an object.
    Kind(NoiseKind),
}

/// The kinds of noise written as objects (`{"kind": …, "sigma": …}`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum NoiseKind {
    /// Every command times `1 + σ Z`: an actuator whose error grows with
    /// what it is asked (σ relative, in (0, 2]).
    Multiplicative {
        /// The relative spread.
        sigma: f64,
    },
    /// The gap the driver acts on is the true one times `1 + σ Z` (at
    /// least 0), drawn afresh at every step: a range sensor's relative
    /// error (σ in (0, 1]).
    Perception {
        /// The relative spread of the perceived gap.
        sigma: f64,
    },
    /// The driver reacts to the cut-in only after a reaction time
    /// `T = σ E`, `E` standard exponential (mean σ seconds, in (0, 10]):
    /// until then it holds its speed (acceleration 0, as it cruised before
    /// the cut-in), and the step `T` falls in applies its command for the
    /// share of the step after `T`. Its tail of long reactions spreads
    /// rare failures far from the boundary of the vehicle's own.
    Reaction {
        /// The mean reaction time (s).
        sigma: f64,
    },
}

impl Noise {
    /// Its σ, in its kind's unit.
    pub fn sigma(&self) -> f64 {
        match *self {
            Noise::Additive(sigma)
            | Noise::Kind(NoiseKind::Multiplicative { sigma })
            | Noise::Kind(NoiseKind::Perception { sigma })
            | Noise::Kind(NoiseKind::Reaction { sigma }) => sigma,
        }
    }

    /// The kind's name: `additive`, `multiplicative`, `perception`,
    /// `reaction`.
    pub fn kind(&self) -> &'static str {
        match self {
            Noise::Additive(_) => "additive",
            Noise::Kind(NoiseKind::Multiplicative { .. }) => "multiplicative",
            Noise::Kind(NoiseKind::Perception { .. }) => "perception",
            Noise::Kind(NoiseKind::Reaction { .. }) => "reaction",
        }
    }

    /// Whether σ is in the kind's range, and the range in words. Additive
    /// noise takes 0 for none, as it always has; a kind named by an object
    /// is there to be noisy.
    pub fn check(&self) -> Result<(), &'static str> {
        let sigma = self.sigma();
        let (ok, requirement) = match self {
            Noise::Additive(_) => (
                (0.0..=MAX_ADDITIVE).contains(&sigma),
                "must be in [0, 10] (m/s²)",
            ),
            Noise::Kind(NoiseKind::Multiplicative { .. }) => (
                sigma > 0.0 && sigma <= 2.0,
                "must be in (0, 2] (the command's relative spread)",
            ),
            Noise::Kind(NoiseKind::Perception { .. }) => (
                sigma > 0.0 && sigma <= 1.0,
                "must be in (0, 1] (the perceived gap's relative spread)",
            ),
            Noise::Kind(NoiseKind::Reaction { .. }) => (
                sigma > 0.0 && sigma <= 10.0,
                "must be in (0, 10] (the mean reaction time, s)",
            ),
        };
        if ok {
            Ok(())
        } else {
            Err(requirement)
        }
    }

    /// A noise as the command line writes it: `σ` (additive, m/s²) or
    /// `KIND:σ` (`multiplicative:0.3`, `perception:0.1`, `reaction:1.5`,
    /// `additive:1.5`), checked against its kind's range.
    pub fn parse_short(text: &str) -> Result<Self, String> {
        let (kind, sigma) = text.split_once(':').unwrap_or(("additive", text));
        let sigma: f64 = sigma
            .trim()
            .parse()
            .map_err(|_| format!("σ `{sigma}` is not a number"))?;
        let noise = match kind.trim() {
            "additive" => Noise::Additive(sigma),
            "multiplicative" => Noise::Kind(NoiseKind::Multiplicative { sigma }),
            "perception" => Noise::Kind(NoiseKind::Perception { sigma }),
            "reaction" => Noise::Kind(NoiseKind::Reaction { sigma }),
            other => {
                return Err(format!(
                    "unknown kind of noise `{other}`; kinds are additive, multiplicative, \
                     perception, reaction"
                ))
            }
        };
        match noise.check() {
            Ok(()) if noise.is_some() => Ok(noise),
            Ok(()) => Err("σ must be above 0".into()),
            Err(requirement) => Err(format!("σ {} {requirement}", crate::number::Num(sigma))),
        }
    }

    /// Whether it moves anything (σ above 0).
    pub fn is_some(&self) -> bool {
        self.sigma() > 0.0
    }

    /// How a label names it: `noise 1.5` (additive, as written), `perception
    /// noise 0.1`.
    pub fn label(&self) -> String {
        let sigma = crate::number::Num(self.sigma());
        match self {
            Noise::Additive(_) => format!("noise {sigma}"),
            other => format!("{} noise {sigma}", other.kind()),
        }
    }
}

/// The largest σ of additive noise (m/s²): beyond any actuator, and far
/// beyond what keeps a cut-in's outcome tied to its scenario.
pub const MAX_ADDITIVE: f64 = 10.0;

/// A noisy vehicle's noise during one test: its kind, the test's stream,
/// and what it remembers (the steps so far, a reaction time once drawn).
#[derive(Debug, Clone)]
pub struct RunNoise {
    noise: Noise,
    rng: NoiseRng,
    step: usize,
    reaction: Option<f64>,
}

impl RunNoise {
    /// Noise of kind `noise` drawn from `rng`, the test's stream.
    pub fn new(noise: Noise, rng: NoiseRng) -> Self {
        Self {
            noise,
            rng,
            step: 0,
            reaction: None,
        }
    }

    fn normal(&mut self) -> f64 {
        self.rng.sample(StandardNormal)
    }

    /// The gap the driver acts on at this step, for the true `gap`.
    pub fn perceived_gap(&mut self, gap: f64) -> f64 {
        match self.noise {
            Noise::Kind(NoiseKind::Perception { sigma }) => {
                (gap * (1.0 + sigma * self.normal())).max(0.0)
            }
            _ => gap,
        }
    }

    /// What the actuator makes of `command` over this step of `dt`
    /// seconds (before the world's bounds); one call a step.
    pub fn deliver(&mut self, command: f64, dt: f64) -> f64 {
        let step = self.step;
        self.step += 1;
        match self.noise {
            Noise::Additive(sigma) => command + sigma * self.normal(),
            Noise::Kind(NoiseKind::Multiplicative { sigma }) => {
                command * (1.0 + sigma * self.normal())
            }
            Noise::Kind(NoiseKind::Perception { .. }) => command,
            Noise::Kind(NoiseKind::Reaction { sigma }) => {
                let reaction = match self.reaction {
                    Some(t) => t,
                    None => {
                        let e: f64 = self.rng.sample(rand_distr::Exp1);
                        *self.reaction.insert(sigma * e)
                    }
                };
                // The share of this step after the reaction.
                let after = (((step + 1) as f64 * dt - reaction) / dt).clamp(0.0, 1.0);
                command * after
            }
        }
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
        let mut noise = RunNoise::new(Noise::Additive(1.5), noise_rng(1, 0));
        let n = 200_000;
        let draws: Vec<f64> = (0..n).map(|_| noise.deliver(0.0, 1.0)).collect();
        let mean = draws.iter().sum::<f64>() / n as f64;
        let var = draws.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        assert!(mean.abs() < 4.5 * 1.5 / (n as f64).sqrt(), "{mean}");
        // The standard error of s² is about σ²√(2/n).
        assert!(
            (var - 2.25).abs() < 4.5 * 2.25 * (2.0 / n as f64).sqrt(),
            "{var}"
        );
    }

    /// Mean and standard deviation of `draws`.
    fn moments(draws: &[f64]) -> (f64, f64) {
        let n = draws.len() as f64;
        let mean = draws.iter().sum::<f64>() / n;
        let var = draws.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (n - 1.0);
        (mean, var.sqrt())
    }

    #[test]
    fn multiplicative_noise_scales_with_the_command() {
        // Command −4 m/s², σ 0.25: delivered −4(1 + 0.25 Z), mean −4 and
        // spread 1; a command of 0 is delivered exactly.
        let mut noise = RunNoise::new(
            Noise::Kind(NoiseKind::Multiplicative { sigma: 0.25 }),
            noise_rng(2, 0),
        );
        let n = 100_000;
        let draws: Vec<f64> = (0..n).map(|_| noise.deliver(-4.0, 0.1)).collect();
        let (mean, sd) = moments(&draws);
        let se = 1.0 / (n as f64).sqrt();
        assert!((mean + 4.0).abs() < 4.5 * se, "{mean}");
        assert!((sd - 1.0).abs() < 4.5 * se * 2f64.sqrt(), "{sd}");
        assert_eq!(noise.deliver(0.0, 0.1), 0.0);
    }

    #[test]
    fn perception_noise_spreads_the_gap_and_leaves_the_command() {
        let mut noise = RunNoise::new(
            Noise::Kind(NoiseKind::Perception { sigma: 0.1 }),
            noise_rng(3, 0),
        );
        let n = 100_000;
        let gaps: Vec<f64> = (0..n).map(|_| noise.perceived_gap(20.0)).collect();
        let (mean, sd) = moments(&gaps);
        // 20(1 + 0.1 Z): mean 20, spread 2.
        let se = 2.0 / (n as f64).sqrt();
        assert!((mean - 20.0).abs() < 4.5 * se, "{mean}");
        assert!((sd - 2.0).abs() < 4.5 * se * 2f64.sqrt(), "{sd}");
        assert_eq!(noise.deliver(-3.0, 0.1), -3.0);
        // At σ 1 a perceived gap is never negative.
        let mut wide = RunNoise::new(
            Noise::Kind(NoiseKind::Perception { sigma: 1.0 }),
            noise_rng(3, 1),
        );
        assert!((0..10_000).all(|_| wide.perceived_gap(5.0) >= 0.0));
    }

    #[test]
    fn a_reaction_time_is_exponential_with_the_stated_mean() {
        // The reaction time of a run, read back from what it delivers: the
        // steps before it deliver 0, the step it falls in the share after
        // it, every later step the command. Over 20,000 runs the mean of
        // T = σ Exp(1), σ 1.5 s, is within 4.5 standard errors (σ/√n).
        let dt = 0.1;
        let n = 20_000u64;
        let times: Vec<f64> = (0..n)
            .map(|index| {
                let mut noise = RunNoise::new(
                    Noise::Kind(NoiseKind::Reaction { sigma: 1.5 }),
                    noise_rng(4, index),
                );
                let mut step = 0usize;
                loop {
                    let delivered = noise.deliver(1.0, dt);
                    if delivered > 0.0 {
                        // delivered = ((step + 1) dt − T)/dt.
                        assert!(delivered <= 1.0);
                        let t = (step as f64 + 1.0 - delivered) * dt;
                        // Every later step delivers the whole command.
                        assert_eq!(noise.deliver(1.0, dt), 1.0);
                        break t;
                    }
                    step += 1;
                }
            })
            .collect();
        let (mean, sd) = moments(&times);
        let se = 1.5 / (n as f64).sqrt();
        assert!((mean - 1.5).abs() < 4.5 * se, "{mean}");
        // An exponential's spread equals its mean.
        assert!((sd - 1.5).abs() < 0.05, "{sd}");
    }

    #[test]
    fn noise_is_written_as_a_number_or_a_kind_and_checked() {
        let additive: Noise = serde_json::from_str("1.5").unwrap();
        assert_eq!(additive, Noise::Additive(1.5));
        let reaction: Noise =
            serde_json::from_str(r#"{"kind": "reaction", "sigma": 0.5}"#).unwrap();
        assert_eq!(reaction, Noise::Kind(NoiseKind::Reaction { sigma: 0.5 }));
        assert_eq!(
            serde_json::to_value(reaction).unwrap(),
            serde_json::json!({"kind": "reaction", "sigma": 0.5})
        );
        assert!(serde_json::from_str::<Noise>(r#"{"kind": "radar", "sigma": 0.5}"#).is_err());
        assert_eq!(
            Noise::parse_short("perception:0.1"),
            Ok(Noise::Kind(NoiseKind::Perception { sigma: 0.1 }))
        );
        assert_eq!(Noise::parse_short("0.5"), Ok(Noise::Additive(0.5)));
        assert!(Noise::parse_short("perception:1.5")
            .unwrap_err()
            .contains("(0, 1]"));
        assert!(Noise::parse_short("0").unwrap_err().contains("above 0"));
        assert!(Noise::parse_short("wobble:1")
            .unwrap_err()
            .contains("kinds are"));
        assert_eq!(reaction.label(), "reaction noise 0.5");
        assert_eq!(additive.label(), "noise 1.5");
        assert!(spec_is_noisy(
            &serde_json::json!({"model": "idm", "noise": {"kind": "multiplicative", "sigma": 0.2}})
        ));
        assert!(!spec_is_noisy(
            &serde_json::json!({"model": "idm", "noise": 0})
        ));
    }
}
