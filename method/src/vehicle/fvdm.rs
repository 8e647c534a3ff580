//! Full velocity difference model in the optimal-velocity form the project
//! specification gives (Jiang et al. 2001 without the velocity-difference
//! term): the vehicle relaxes toward an optimal speed that depends on the gap.

use super::observation::FollowerObservation;
use super::parameters::{check, ParamError};
use super::tanh::tanh;
use serde::{Deserialize, Serialize};

/// FVDM parameters. Acceleration `a = k (V₁ + V₂ tanh(C₁ (R − L) − C₂) − v)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FvdmParams {
    /// Sensitivity k (1/s).
    pub k: f64,
    /// V₁ (m/s).
    pub v1: f64,
    /// V₂ (m/s).
    pub v2: f64,
    /// C₁ (1/m).
    pub c1: f64,
    /// C₂ (dimensionless).
    pub c2: f64,
    /// Length L subtracted from the range (m).
    pub length: f64,
}

impl Default for FvdmParams {
    fn default() -> Self {
        Self {
            k: 0.85,
            v1: 6.75,
            v2: 7.91,
            c1: 0.13,
            c2: 1.57,
            length: 5.0,
        }
    }
}

impl FvdmParams {
    /// Checks every parameter is finite and in range.
    pub fn validate(&self) -> Result<(), ParamError> {
        check("fvdm", "k", self.k, |x| x > 0.0, "must be > 0")?;
        check("fvdm", "v1", self.v1, |x| x.is_finite(), "must be finite")?;
        check("fvdm", "v2", self.v2, |x| x >= 0.0, "must be ≥ 0")?;
        check("fvdm", "c1", self.c1, |x| x > 0.0, "must be > 0")?;
        check("fvdm", "c2", self.c2, |x| x.is_finite(), "must be finite")?;
        check("fvdm", "length", self.length, |x| x >= 0.0, "must be ≥ 0")
    }

    /// `a = k(V₁ + V₂ tanh(C₁(R − L) − C₂) − v)` (m/s²), before clipping;
    /// `tanh` is [`super::tanh::tanh`], the batch's too.
    pub fn acceleration(&self, obs: &FollowerObservation) -> f64 {
        let optimal_speed = self.v1 + self.v2 * tanh(self.c1 * (obs.gap - self.length) - self.c2);
        self.k * (optimal_speed - obs.speed)
    }
}
