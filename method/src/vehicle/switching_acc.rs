//! Switching adaptive cruise control: incremental PI control of the
//! time-to-collision error, with full braking when the error is negative.

use super::observation::FollowerObservation;
use super::parameters::{check, ParamError};
use serde::{Deserialize, Serialize};

/// Parameters of the switching ACC.
///
/// With `e = R / (v − v_lead + 0.01) − TTC*`:
/// if `e > 0`, `a = a_prev + K_p (e − e_prev) + K_i (e + e_prev) T_s / 2`
/// (the incremental, trapezoidal form of a PI controller); otherwise the
/// controller brakes with `brake` (−3 m/s²). Before the first step, as in
/// the authors' code (`value_function_Switch_ACC.m`, `ttc.m`), `a_prev = 0`
/// and `e_prev = R / (v − v_lead) − TTC*` without the 0.01 guard
/// (`R / 0.01 − TTC*` at equal speeds), so the first command already
/// carries a proportional term. The error is clamped to ±`ERROR_CLAMP` (10⁴ s) so
/// that a closing speed of exactly −0.01 m/s does not produce infinities
/// (on the cut-in grid the initial errors stay below 9,000).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SwitchingAccParams {
    /// Proportional gain K_p.
    pub kp: f64,
    /// Integral gain K_i.
    pub ki: f64,
    /// Controller sample time T_s (s) used in the integral term.
    pub ts: f64,
    /// Target time to collision TTC* (s).
    pub target_ttc: f64,
    /// Deceleration applied when `e ≤ 0` (m/s², negative).
    pub brake: f64,
}

/// Bound on |e| (s); see [`SwitchingAccParams`].
pub const ERROR_CLAMP: f64 = 1e4;

impl Default for SwitchingAccParams {
    fn default() -> Self {
        Self {
            kp: -38.6,
            ki: -1.35,
            ts: 0.1,
            target_ttc: 5.0,
            brake: -3.0,
        }
    }
}

impl SwitchingAccParams {
    /// Checks every parameter is finite and in range.
    pub fn validate(&self) -> Result<(), ParamError> {
        check(
            "switching-acc",
            "kp",
            self.kp,
            f64::is_finite,
            "must be finite",
        )?;
        check(
            "switching-acc",
            "ki",
            self.ki,
            f64::is_finite,
            "must be finite",
        )?;
        check("switching-acc", "ts", self.ts, |x| x > 0.0, "must be > 0")?;
        check(
            "switching-acc",
            "target_ttc",
            self.target_ttc,
            |x| x > 0.0,
            "must be > 0",
        )?;
        check(
            "switching-acc",
            "brake",
            self.brake,
            |x| x < 0.0,
            "must be < 0",
        )
    }
}

/// The controller's memory between steps.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SwitchingAccState {
    previous: Option<(f64, f64)>,
}

impl SwitchingAccState {
    /// One control step; `clip` is the acceleration range of the simulation,
    /// applied before the value is remembered as `a_prev`.
    pub fn acceleration(
        &mut self,
        p: &SwitchingAccParams,
        obs: &FollowerObservation,
        clip: (f64, f64),
    ) -> f64 {
        let error = |ttc: f64| (ttc - p.target_ttc).clamp(-ERROR_CLAMP, ERROR_CLAMP);
        let e = error(obs.gap / (obs.speed - obs.lead_speed + 0.01));
        let (a_prev, e_prev) = self.previous.unwrap_or_else(|| {
            let closing = obs.speed - obs.lead_speed;
            let initial = if closing != 0.0 { closing } else { 0.01 };
            (0.0, error(obs.gap / initial))
        });
        let a = if e > 0.0 {
            a_prev + p.kp * (e - e_prev) + p.ki * (e + e_prev) * p.ts / 2.0
        } else {
            p.brake
        };
        let a = a.clamp(clip.0, clip.1);
        self.previous = Some((a, e));
        a
    }
}
