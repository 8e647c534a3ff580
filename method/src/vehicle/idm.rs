//! Intelligent Driver Model (Treiber et al. 2000), with the calibration of the
//! paper's Table III (Ro et al. 2018, "A formal characterization of the IDM").

use super::observation::FollowerObservation;
use super::parameters::{check, ParamError};
use serde::{Deserialize, Serialize};

/// IDM parameters. Acceleration
/// `a = α (1 − (v/v₀)^δ − (s*/(R − L))²)`,
/// desired gap `s* = s₀ + vT + v (v − v_lead) / (2 √(α b))`.
///
/// The formula is evaluated as written even when `R < L` (the square makes
/// the interaction term positive, so the model brakes hard), as the authors'
/// code does; two cells of the paper's 184-cell library depend on it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IdmParams {
    /// Maximum acceleration α (m/s²).
    pub alpha: f64,
    /// Desired speed v₀ (m/s). The paper's calibration uses 18 m/s.
    pub v0: f64,
    /// Acceleration exponent δ.
    pub delta: f64,
    /// Jam distance s₀ (m).
    pub s0: f64,
    /// Length L subtracted from the range (m).
    pub length: f64,
    /// Desired time headway T (s).
    pub headway: f64,
    /// Comfortable deceleration b (m/s²).
    pub b: f64,
}

impl Default for IdmParams {
    fn default() -> Self {
        Self {
            alpha: 2.0,
            v0: 18.0,
            delta: 4.0,
            s0: 2.0,
            length: 4.0,
            headway: 1.0,
            b: 3.0,
        }
    }
}

impl IdmParams {
    /// Checks every parameter is finite and in range.
    pub fn validate(&self) -> Result<(), ParamError> {
        check("idm", "alpha", self.alpha, |x| x > 0.0, "must be > 0")?;
        check("idm", "v0", self.v0, |x| x > 0.0, "must be > 0")?;
        check("idm", "delta", self.delta, |x| x > 0.0, "must be > 0")?;
        check("idm", "s0", self.s0, |x| x >= 0.0, "must be ≥ 0")?;
        check("idm", "length", self.length, |x| x >= 0.0, "must be ≥ 0")?;
        check("idm", "headway", self.headway, |x| x >= 0.0, "must be ≥ 0")?;
        check("idm", "b", self.b, |x| x > 0.0, "must be > 0")
    }

    /// The IDM acceleration; `−∞` when the interaction term is undefined
    /// (`R = L` with `s* = 0`), which the simulation clips to its braking bound.
    pub fn acceleration(&self, obs: &FollowerObservation) -> f64 {
        let v = obs.speed;
        let desired_gap = self.s0
            + v * self.headway
            + v * (v - obs.lead_speed) / (2.0 * (self.alpha * self.b).sqrt());
        let interaction = desired_gap / (obs.gap - self.length);
        let free = super::power::pow(v / self.v0, self.delta);
        let a = self.alpha * (1.0 - free - interaction * interaction);
        if a.is_nan() {
            f64::NEG_INFINITY
        } else {
            a
        }
    }
}
