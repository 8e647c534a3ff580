//! The built-in car-following exposure (SPEC §6). The paper takes `P(s)` from
//! car-following states and `P(u|v)` from free driving of the IVBSS data,
//! which are not public. This synthetic model has the same structure with
//! magnitudes one can check against highway driving:
//!
//! - **initial states** `P(s)`, `s = (v, R, Ṙ)` with `v` the BV's speed:
//!   `v ~ N(29.5, 3.5²)` m/s (as the highway-exit exposure); `Ṙ | v ~ N(0,
//!   2²)` m/s (range rates of following are small); the time headway
//!   `R / v_VUT` log-normal with median 1.4 s and log-sd 0.6, with `R` here
//!   the bumper gap and `v_VUT = v − Ṙ` (highway studies report mean
//!   headways of 1.3–1.5 s, with about one follower in six below 0.8 s).
//!   States closing with a time to collision `R/(−Ṙ)` below 1 s have
//!   exposure 0: they are conflicts already under way, not car following.
//!   Evaluated at the grid states and normalised.
//! - **BV actions** `P(u|v)`: a two-sided exponential (Laplace) law on the
//!   31 actions, `P(u|v) ∝ exp(−|u|/λ)` with `λ_brake = 0.5 m/s²` for
//!   `u < 0` and `λ_accel(v) = 0.3 · clamp((40 − v)/10, 0.2, 1)` for `u > 0`
//!   (less acceleration near the top speed). Per one-second decision
//!   `P(u ≤ −2)` ≈ 1.3 × 10⁻² and `P(u ≤ −3)` ≈ 1.7 × 10⁻³: a braking harder
//!   than 0.3 g about once per ten minutes of following (≈ 18 km at 30 m/s),
//!   the order naturalistic studies report for hard-braking events.
//!
//! With the highway IDM surrogate this gives an accident rate on the grid
//! chain of `μ_S ≈ 1.7 × 10⁻⁶` per test and library estimates near
//! 1.1 × 10⁻⁶ for the simulated tests, the order of the paper's (its NDD
//! baseline needed 1.9 × 10⁷ tests at β = 0.2, i.e. `P(A) ≈ 3.6 × 10⁻⁶`).

use super::states::StateGrid;
use super::world::FollowWorld;
use crate::density::normal;

/// Parameters of the synthetic car-following exposure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowExposureModel {
    /// Mean BV speed (m/s).
    pub speed_mean: f64,
    /// Standard deviation of the BV speed (m/s).
    pub speed_sd: f64,
    /// Standard deviation of the range rate `Ṙ` (m/s).
    pub range_rate_sd: f64,
    /// Median time headway `R / v_VUT` (s).
    pub headway_median: f64,
    /// Log-standard deviation of the time headway.
    pub headway_log_sd: f64,
    /// Laplace scale λ_brake of the BV's braking actions (m/s²).
    pub brake_scale: f64,
    /// Laplace scale of the BV's accelerating actions at low speed (m/s²), shrunk near the top speed.
    pub accel_scale: f64,
    /// States closing faster than this time to collision have exposure 0 (s).
    pub min_ttc: f64,
}

impl Default for FollowExposureModel {
    fn default() -> Self {
        Self {
            speed_mean: 29.5,
            speed_sd: 3.5,
            range_rate_sd: 2.0,
            headway_median: 1.4,
            headway_log_sd: 0.6,
            brake_scale: 0.5,
            accel_scale: 0.3,
            min_ttc: 1.0,
        }
    }
}

impl FollowExposureModel {
    /// `P(s)` on the state grid, normalised; states at or below the
    /// accident range have exposure 0.
    pub fn initial_states(&self, world: &FollowWorld, grid: &StateGrid) -> Vec<f64> {
        let weights: Vec<f64> = (0..grid.len())
            .map(|s| {
                let x = grid.state(s);
                let own = x.vut_speed();
                if x.range <= world.accident_range || own <= 0.0 {
                    return 0.0;
                }
                if x.range_rate < 0.0 && x.range / -x.range_rate < self.min_ttc {
                    return 0.0;
                }
                let h = x.range / own;
                let headway =
                    normal((h / self.headway_median).ln(), 0.0, self.headway_log_sd) / h / own;
                normal(x.bv_speed, self.speed_mean, self.speed_sd)
                    * normal(x.range_rate, 0.0, self.range_rate_sd)
                    * headway
            })
            .collect();
        let total: f64 = weights.iter().sum();
        weights.into_iter().map(|w| w / total).collect()
    }

    /// `P(u|v)` at every grid speed, `speeds × actions` (row `i` for the
    /// speed `v_min + i · step`).
    pub fn actions_by_speed(&self, world: &FollowWorld, grid: &StateGrid) -> Vec<f64> {
        (0..grid.speed.1)
            .flat_map(|i| self.actions(world, grid.speed.0 + i as f64 * grid.step))
            .collect()
    }

    /// `P(u|v)` over the world's actions.
    pub fn actions(&self, world: &FollowWorld, speed: f64) -> Vec<f64> {
        let accel_scale = self.accel_scale * ((40.0 - speed) / 10.0).clamp(0.2, 1.0);
        let weights: Vec<f64> = (0..world.actions)
            .map(|k| {
                let u = world.action(k);
                let scale = if u < 0.0 {
                    self.brake_scale
                } else {
                    accel_scale
                };
                (-u.abs() / scale).exp()
            })
            .collect();
        let total: f64 = weights.iter().sum();
        weights.into_iter().map(|w| w / total).collect()
    }
}
