//! A noisy external vehicle under test for tslg, written after the rule
//! for noisy vehicles was fixed and held back from its design (issue 66):
//! an adaptive cruise control on a radar that is miscalibrated, jittery
//! and drops its target. Its runs of one scenario differ (fresh entropy
//! each run), so its hello says `"deterministic": false`. Episode mode.
//!
//! ```sh
//! cargo build --release --example radar_acc_vut
//! tslg-worker --vut-exec radar-acc=target/release/examples/radar_acc_vut
//! ```
//!
//! The controller is a constant-time-gap ACC, `a = k_s (ŝ − s₀ − h v) +
//! k_v (v̂_l − v)` (`k_s` 0.25 /s², `k_v` 0.6 /s, `s₀` 3 m, `h` 1.2 s), with
//! an emergency brake of −6 m/s² while its measured time to collision is
//! under 3 s. The radar measures the range as `s (1 + b)(1 + σ_r Z)`,
//! `b` a calibration error drawn once a run, uniform on ±`b̄`, `Z` standard
//! normal each step, and the leader's speed with `σ_v Z'` m/s; each step
//! it loses the target with chance `p`, and the controller then holds the
//! last measurement. At `--noise 1`: `b̄` 0.15, `σ_r` 0.03, `σ_v` 0.3,
//! `p` 0.1; `--noise k` scales all four (`k` ≤ 2), 0 makes it
//! deterministic. The protocol is docs/vut-protocol.md.

#[path = "common/cutin_episode.rs"]
#[allow(dead_code)] // the controller reads the state, not the clock
mod cutin_episode;

use cutin_episode::{Driver, State};
use rand::rngs::ThreadRng;
use rand::Rng;
use rand_distr::StandardNormal;

const GAP_GAIN: f64 = 0.25;
const SPEED_GAIN: f64 = 0.6;
const STANDSTILL_GAP: f64 = 3.0;
const TIME_GAP: f64 = 1.2;
const EMERGENCY_BRAKE: f64 = -6.0;
const EMERGENCY_TTC: f64 = 3.0;

struct RadarAcc {
    /// The noise scale `k`.
    scale: f64,
    /// This run's calibration error `b`.
    bias: f64,
    /// The last measured range and leader speed.
    range: f64,
    lead_speed: f64,
    measured: bool,
    entropy: ThreadRng,
}

impl Driver for RadarAcc {
    fn name(&self) -> &'static str {
        "radar-acc"
    }

    fn deterministic(&self) -> bool {
        self.scale == 0.0
    }

    fn begin(&mut self) {
        self.bias = 0.15 * self.scale * (2.0 * self.entropy.random::<f64>() - 1.0);
        self.measured = false;
    }

    fn acceleration(&mut self, s: State) -> f64 {
        let k = self.scale;
        let lost = self.measured && self.entropy.random::<f64>() < 0.1 * k;
        if !lost {
            let z: f64 = self.entropy.sample(StandardNormal);
            let z_speed: f64 = self.entropy.sample(StandardNormal);
            self.range = (s.gap * (1.0 + self.bias) * (1.0 + 0.03 * k * z)).max(0.0);
            self.lead_speed = s.lead_speed + 0.3 * k * z_speed;
            self.measured = true;
        }
        let closing = s.speed - self.lead_speed;
        if closing > 0.0 && self.range / closing < EMERGENCY_TTC {
            return EMERGENCY_BRAKE;
        }
        GAP_GAIN * (self.range - STANDSTILL_GAP - TIME_GAP * s.speed)
            + SPEED_GAIN * (self.lead_speed - s.speed)
    }
}

fn main() {
    let mut acc = RadarAcc {
        scale: 1.0,
        bias: 0.0,
        range: 0.0,
        lead_speed: 0.0,
        measured: false,
        entropy: rand::rng(),
    };
    let criticality = cutin_episode::parse_options("radar_acc_vut", |flag, number| {
        match flag {
            "--noise" if number <= 2.0 => acc.scale = number,
            other => {
                return Err(format!(
                    "unknown option {other} (or --noise above 2); options: --noise SCALE \
                     (0 to 2), --criticality"
                ))
            }
        }
        Ok(())
    });
    cutin_episode::serve(&mut acc, criticality);
}
