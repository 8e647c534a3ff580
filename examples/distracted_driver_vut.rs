//! A noisy external vehicle under test for tslg, written after the rule
//! for noisy vehicles was fixed and held back from its design (issue 66):
//! a driver who glances away. Attentive, it follows the leader with a
//! linear time-gap law (Helly 1959); now and then it looks away for a
//! while and holds its last command, blind to the cut-in. Its runs of one
//! scenario differ by when and how long it looks away (fresh entropy each
//! run), so its hello says `"deterministic": false`. Episode mode.
//!
//! ```sh
//! cargo build --release --example distracted_driver_vut
//! tslg-worker --vut-exec distracted=target/release/examples/distracted_driver_vut
//! ```
//!
//! Attentive, it commands `a = C₁ (v_l − v) + C₂ (s − s₀ − h v)`
//! (`C₁` 0.5 /s, `C₂` 0.15 /s², `s₀` 2 m, `h` 1 s) every step. Glances
//! start at rate `λ` (0.05/s × `--noise`; the run may begin in one, with
//! the stationary chance `λ D̄/(1 + λ D̄)`) and last `D̄ ·` LogNormal
//! (median `D̄` 0.5 s, log-spread 0.5): its failures are scattered over
//! scenarios the attentive law handles, with a probability that depends
//! on how long a glance must be to matter. `--noise 0` never glances
//! (deterministic); `--criticality` reports the smallest time to
//! collision over 10 s, capped at 1. The protocol is docs/vut-protocol.md.

#[path = "common/cutin_episode.rs"]
mod cutin_episode;

use cutin_episode::{Driver, State};
use rand::rngs::ThreadRng;
use rand::Rng;
use rand_distr::{Distribution, LogNormal};

const SPEED_GAIN: f64 = 0.5;
const GAP_GAIN: f64 = 0.15;
const STANDSTILL_GAP: f64 = 2.0;
const TIME_GAP: f64 = 1.0;
/// Glances a second, at `--noise 1`.
const GLANCE_RATE: f64 = 0.05;
/// A glance's median length (s).
const GLANCE_MEDIAN: f64 = 0.5;

struct Distracted {
    /// Glances a second.
    rate: f64,
    /// The last command, and when the glance under way ends (s).
    held: f64,
    looking_away_until: f64,
    entropy: ThreadRng,
}

impl Distracted {
    fn glance(&mut self) -> f64 {
        LogNormal::new(GLANCE_MEDIAN.ln(), 0.5)
            .expect("finite parameters")
            .sample(&mut self.entropy)
    }
}

impl Driver for Distracted {
    fn name(&self) -> &'static str {
        "distracted-driver"
    }

    fn deterministic(&self) -> bool {
        self.rate == 0.0
    }

    fn begin(&mut self) {
        self.held = 0.0;
        self.looking_away_until = f64::NEG_INFINITY;
        if self.rate > 0.0 {
            // In a glance at the cut-in with the stationary chance; its
            // remaining length then is (about) a whole glance's.
            let mean = GLANCE_MEDIAN * (0.5f64 * 0.5 / 2.0).exp();
            let busy = self.rate * mean / (1.0 + self.rate * mean);
            if self.entropy.random::<f64>() < busy {
                self.looking_away_until = self.glance();
            }
        }
    }

    fn acceleration(&mut self, s: State) -> f64 {
        if s.time < self.looking_away_until {
            return self.held;
        }
        if self.rate > 0.0 && self.entropy.random::<f64>() < self.rate * s.dt {
            self.looking_away_until = s.time + self.glance();
            return self.held;
        }
        self.held = SPEED_GAIN * (s.lead_speed - s.speed)
            + GAP_GAIN * (s.gap - STANDSTILL_GAP - TIME_GAP * s.speed);
        self.held
    }
}

fn main() {
    let mut driver = Distracted {
        rate: GLANCE_RATE,
        held: 0.0,
        looking_away_until: f64::NEG_INFINITY,
        entropy: rand::rng(),
    };
    let criticality = cutin_episode::parse_options("distracted_driver_vut", |flag, number| {
        match flag {
            "--noise" => driver.rate = GLANCE_RATE * number,
            other => {
                return Err(format!(
                    "unknown option {other}; options: --noise SCALE (of the glance rate), \
                     --criticality"
                ))
            }
        }
        Ok(())
    });
    cutin_episode::serve(&mut driver, criticality);
}
