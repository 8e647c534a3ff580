//! A noisy external vehicle under test for tslg, in Rust and linking
//! nothing of tslg: Gipps' car-following model (Gipps 1981) with a
//! reaction time of 1 s and Gaussian noise on its actuator, on the cut-in
//! case in episode mode. It runs the whole cut-in itself from the scenario
//! and the world's settings, as a test track or a heavy simulator would,
//! and reports whether it crashed. Its runs of one scenario differ (fresh
//! entropy each run), so its hello says `"deterministic": false`.
//!
//! It is the vehicle of issue 66 ("Noisy vehicles nobody tuned for"): the
//! adaptive campaigns' rule for noisy vehicles was fixed on other models,
//! and this one shows whether it holds on a vehicle noisy in its own way
//! (docs/statistics.md, "Noisy vehicles").
//!
//! ```sh
//! cargo build --release --example noisy_gipps_vut
//! tslg-worker --vut-exec gipps=target/release/examples/noisy_gipps_vut
//! tslg campaign start --library-id 1 --vehicle-noise \
//!     --vut '{"external": "gipps", "mode": "episode"}' --wait
//! ```
//!
//! Gipps' speed one reaction time `τ` ahead is the smaller of a free-road
//! and a safe-braking speed,
//!
//! ```text
//! v_free = v + 2.5 a τ (1 − v/V) √(0.025 + v/V)
//! v_safe = b τ + √(b² τ² − b (2 (s − s₀) − v τ − v_l²/b̂))
//! ```
//!
//! (`b < 0` the driver's braking, `b̂ < 0` what it expects of the leader);
//! the driver commands `(min(v_free, v_safe) − v)/τ` and holds it for `τ`.
//! The actuator delivers the command plus `σ Z` at every simulation step,
//! `Z` standard normal. Options: `--tau SECONDS` (1), `--noise SIGMA`
//! (m/s², 1; 0 makes it deterministic), `--criticality` (also report how
//! close a run came: its smallest time to collision over 10 s, capped at 1).
//!
//! The protocol (one JSON object per line) is docs/vut-protocol.md; the
//! cut-in's stepping and the protocol loop are examples/common/cutin_episode.rs.

#[path = "common/cutin_episode.rs"]
#[allow(dead_code)] // Gipps decides every τ and does not read the step
mod cutin_episode;

use cutin_episode::{Driver, State};
use rand::rngs::ThreadRng;
use rand_distr::{Distribution, Normal};

/// The driver's parameters (Gipps 1981, the cut-in IDM's desired speed).
const MAX_ACCELERATION: f64 = 2.0;
const BRAKING: f64 = -3.0;
const EXPECTED_LEADER_BRAKING: f64 = -3.5;
const DESIRED_SPEED: f64 = 18.0;
const STANDSTILL_GAP: f64 = 2.0;

/// Gipps' driver with a noisy actuator.
struct Gipps {
    /// Reaction time τ (s).
    tau: f64,
    /// σ of the actuator's noise (m/s²).
    noise: f64,
    /// The command held and until when (s).
    held: f64,
    until: f64,
    entropy: ThreadRng,
}

impl Gipps {
    /// Gipps' command at `speed` behind a leader at `lead_speed`, `gap` ahead.
    fn command(&self, speed: f64, lead_speed: f64, gap: f64) -> f64 {
        let tau = self.tau;
        let free = speed
            + 2.5
                * MAX_ACCELERATION
                * tau
                * (1.0 - speed / DESIRED_SPEED)
                * (0.025 + speed / DESIRED_SPEED).max(0.0).sqrt();
        let b = BRAKING;
        let inside = b * b * tau * tau
            - b * (2.0 * (gap - STANDSTILL_GAP)
                - speed * tau
                - lead_speed * lead_speed / EXPECTED_LEADER_BRAKING);
        let safe = if inside > 0.0 {
            b * tau + inside.sqrt()
        } else {
            0.0
        };
        (free.min(safe).max(0.0) - speed) / tau
    }
}

impl Driver for Gipps {
    fn name(&self) -> &'static str {
        "noisy-gipps"
    }

    fn deterministic(&self) -> bool {
        self.noise == 0.0
    }

    fn begin(&mut self) {
        self.until = f64::NEG_INFINITY;
    }

    /// The driver decides every τ; the actuator adds its noise every step.
    fn acceleration(&mut self, s: State) -> f64 {
        if s.time >= self.until - 1e-9 {
            self.held = self.command(s.speed, s.lead_speed, s.gap);
            self.until = s.time + self.tau;
        }
        if self.noise > 0.0 {
            let noise = Normal::new(0.0, self.noise).expect("σ finite");
            self.held + noise.sample(&mut self.entropy)
        } else {
            self.held
        }
    }
}

fn main() {
    let mut gipps = Gipps {
        tau: 1.0,
        noise: 1.0,
        held: 0.0,
        until: f64::NEG_INFINITY,
        entropy: rand::rng(),
    };
    let criticality = cutin_episode::parse_options("noisy_gipps_vut", |flag, number| {
        match flag {
            "--tau" if number > 0.0 => gipps.tau = number,
            "--noise" => gipps.noise = number,
            other => {
                return Err(format!(
                    "unknown option {other} (or --tau 0); options: --tau SECONDS (> 0), \
                     --noise SIGMA, --criticality"
                ))
            }
        }
        Ok(())
    });
    cutin_episode::serve(&mut gipps, criticality);
}
