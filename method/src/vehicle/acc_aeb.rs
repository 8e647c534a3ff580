//! Our adaptive cruise control with autonomous emergency braking (ACC+AEB).
//!
//! The paper's vehicle under test (Zhao et al. 2017) is not published in a
//! usable form, so this is our own design, built from textbook parts:
//! - **cruise**: `a_c = k_v (v_set − v)`, a proportional speed controller;
//! - **constant time gap**: `a_g = k_s (R − s₀ − h v) + k_r (v_lead − v)`
//!   (Rajamani, *Vehicle Dynamics and Control*, ch. 5), spacing error plus
//!   relative speed;
//! - ACC output `a = clamp(min(a_c, a_g), a_comfort, a_max)`: the more
//!   cautious of the two, limited to comfortable values;
//! - **AEB**: when closing (`v > v_lead`) with `TTC = R/(v − v_lead) < TTC_aeb`,
//!   or when `R < s_aeb`, apply `a_aeb` instead (the simulation clips it to its
//!   own braking bound).
//!
//! - **actuator**: the brake and drive deliver the commanded acceleration
//!   through a first-order lag of time constant `τ` (`actuator_lag`; 0, the
//!   default, is an ideal actuator). Longitudinal ACC models commonly use
//!   τ ≈ 0.3–0.6 s (Rajamani, ch. 5).
//!
//! The gains keep the discrete loop stable at the 1 s step of the `paper-code`
//! preset (`k_r dt < 2`, `k_s dt² < 1`).

use super::observation::FollowerObservation;
use super::parameters::{check, ParamError};
use serde::{Deserialize, Serialize};

/// Parameters of the ACC + AEB vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AccAebParams {
    /// Set speed v_set (m/s).
    pub set_speed: f64,
    /// Speed gain k_v (1/s).
    pub speed_gain: f64,
    /// Standstill distance s₀ (m).
    pub standstill_gap: f64,
    /// Time gap h (s).
    pub time_gap: f64,
    /// Spacing gain k_s (1/s²).
    pub gap_gain: f64,
    /// Relative-speed gain k_r (1/s).
    pub relative_speed_gain: f64,
    /// Strongest comfortable ACC deceleration a_comfort (m/s², negative).
    pub comfort_deceleration: f64,
    /// Largest ACC acceleration a_max (m/s²).
    pub max_acceleration: f64,
    /// AEB trigger: time to collision below this (s).
    pub aeb_ttc: f64,
    /// AEB trigger: range below this (m).
    pub aeb_gap: f64,
    /// AEB deceleration a_aeb (m/s², negative).
    pub aeb_deceleration: f64,
    /// Actuator lag τ (s): 0 delivers every command at once.
    pub actuator_lag: f64,
}

impl Default for AccAebParams {
    fn default() -> Self {
        Self {
            set_speed: 30.0,
            speed_gain: 0.4,
            standstill_gap: 3.0,
            time_gap: 1.5,
            gap_gain: 0.23,
            relative_speed_gain: 0.74,
            comfort_deceleration: -2.0,
            max_acceleration: 1.5,
            aeb_ttc: 3.0,
            aeb_gap: 2.0,
            aeb_deceleration: -8.0,
            actuator_lag: 0.0,
        }
    }
}

impl AccAebParams {
    /// Checks every parameter is finite and in range.
    pub fn validate(&self) -> Result<(), ParamError> {
        const M: &str = "acc-aeb";
        let positive = |x: f64| x > 0.0;
        let non_negative = |x: f64| x >= 0.0;
        let negative = |x: f64| x < 0.0;
        check(M, "set_speed", self.set_speed, positive, "must be > 0")?;
        check(M, "speed_gain", self.speed_gain, positive, "must be > 0")?;
        check(
            M,
            "standstill_gap",
            self.standstill_gap,
            non_negative,
            "must be ≥ 0",
        )?;
        check(M, "time_gap", self.time_gap, non_negative, "must be ≥ 0")?;
        check(M, "gap_gain", self.gap_gain, positive, "must be > 0")?;
        check(
            M,
            "relative_speed_gain",
            self.relative_speed_gain,
            non_negative,
            "must be ≥ 0",
        )?;
        check(
            M,
            "comfort_deceleration",
            self.comfort_deceleration,
            negative,
            "must be < 0",
        )?;
        check(
            M,
            "max_acceleration",
            self.max_acceleration,
            positive,
            "must be > 0",
        )?;
        check(M, "aeb_ttc", self.aeb_ttc, non_negative, "must be ≥ 0")?;
        check(M, "aeb_gap", self.aeb_gap, non_negative, "must be ≥ 0")?;
        check(
            M,
            "aeb_deceleration",
            self.aeb_deceleration,
            negative,
            "must be < 0",
        )?;
        check(
            M,
            "actuator_lag",
            self.actuator_lag,
            non_negative,
            "must be ≥ 0",
        )
    }

    /// The commanded acceleration (m/s²), before the world's clipping.
    pub fn acceleration(&self, obs: &FollowerObservation) -> f64 {
        let closing_speed = obs.speed - obs.lead_speed;
        let emergency = obs.gap < self.aeb_gap
            || (closing_speed > 0.0 && obs.gap / closing_speed < self.aeb_ttc);
        if emergency {
            return self.aeb_deceleration;
        }
        let cruise = self.speed_gain * (self.set_speed - obs.speed);
        let gap = self.gap_gain * (obs.gap - self.standstill_gap - self.time_gap * obs.speed)
            - self.relative_speed_gain * closing_speed;
        cruise
            .min(gap)
            .clamp(self.comfort_deceleration, self.max_acceleration)
    }
}
