//! The background IDM both built-in drivers follow with in the right lane.

use crate::vehicle::{check, ParamError};

/// The Intelligent Driver Model in its standard form (Treiber et al. 2000)
/// on bumper gaps `s`:
/// `a = α (1 − (v/v₀)^δ − (s*/s)²)`,
/// `s* = s₀ + max(0, vT + v (v − v_lead) / (2 √(α b)))`.
/// Unlike the cut-in case's IDM (which follows the authors' code and does
/// not clip `s*`), a faster leader never makes this one brake.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Idm {
    /// Maximum acceleration α (m/s²).
    pub alpha: f64,
    /// Comfortable deceleration b (m/s²).
    pub b: f64,
    /// Desired speed v₀ (m/s).
    pub v0: f64,
    /// Desired time headway T (s).
    pub headway: f64,
    /// Jam distance s₀ (m).
    pub s0: f64,
    /// Acceleration exponent δ.
    pub delta: f64,
}

impl Idm {
    /// Highway values: α 1.5 m/s², b 2 m/s², T 1.2 s, s₀ 2 m, δ 4,
    /// v₀ 33 m/s (≈ 120 km/h).
    pub const HIGHWAY: Idm = Idm {
        alpha: 1.5,
        b: 2.0,
        v0: 33.0,
        headway: 1.2,
        s0: 2.0,
        delta: 4.0,
    };

    /// Checks every parameter is finite and in range, naming `model` in the error.
    pub fn validate(&self, model: &'static str) -> Result<(), ParamError> {
        check(model, "alpha", self.alpha, |x| x > 0.0, "must be > 0")?;
        check(model, "b", self.b, |x| x > 0.0, "must be > 0")?;
        check(model, "v0", self.v0, |x| x > 0.0, "must be > 0")?;
        check(model, "headway", self.headway, |x| x >= 0.0, "must be ≥ 0")?;
        check(model, "s0", self.s0, |x| x >= 0.0, "must be ≥ 0")?;
        check(model, "delta", self.delta, |x| x > 0.0, "must be > 0")
    }

    /// The acceleration at `speed` behind `leader` (bumper gap, speed), or on
    /// a free road. A gap ≤ 0 gives `−∞` (the caller's braking bound).
    pub fn accel(&self, speed: f64, leader: Option<(f64, f64)>) -> f64 {
        IdmSteps::new(*self).accel(speed, leader)
    }
}

/// An [`Idm`] prepared for the many evaluations of a run: `2√(αb)`
/// computed once, and the free-road term `α (1 − (v/v₀)^δ)`
/// separate from the interaction term `α (s*/s)²`, so that a caller that
/// needs both `ã` and `a` at one speed (MOBIL) or the free term of a BV's
/// constant speed at every instant computes it once. The operations are
/// [`Idm::accel`]'s in its order, so the values are its values, bit for bit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IdmSteps {
    idm: Idm,
    two_sqrt_ab: f64,
}

impl IdmSteps {
    /// `idm` with `2√(αb)` computed.
    pub fn new(idm: Idm) -> Self {
        Self {
            idm,
            two_sqrt_ab: 2.0 * (idm.alpha * idm.b).sqrt(),
        }
    }

    /// The model's parameters.
    pub fn idm(&self) -> &Idm {
        &self.idm
    }

    /// `2√(αb)`, the divisor of the IDM's dynamic term.
    pub fn two_sqrt_ab(&self) -> f64 {
        self.two_sqrt_ab
    }

    /// The free-road term `α (1 − (v/v₀)^δ)`: the acceleration with no leader.
    #[inline]
    pub fn free(&self, speed: f64) -> f64 {
        self.idm.alpha * (1.0 - crate::vehicle::power::pow(speed / self.idm.v0, self.idm.delta))
    }

    /// The acceleration at `speed` behind a leader `(gap, lead_speed)`,
    /// given `free = self.free(speed)`:
    /// `free − α (s*/s)²`, `s* = s₀ + max(0, vT + v (v − v_lead) / (2 √(α b)))`;
    /// `−∞` for a gap ≤ 0.
    #[inline]
    pub fn behind(&self, free: f64, speed: f64, (gap, lead_speed): (f64, f64)) -> f64 {
        if gap <= 0.0 {
            return f64::NEG_INFINITY;
        }
        let dynamic = speed * self.idm.headway + speed * (speed - lead_speed) / self.two_sqrt_ab;
        let desired = self.idm.s0 + dynamic.max(0.0);
        free - self.idm.alpha * (desired / gap).powi(2)
    }

    /// [`Idm::accel`].
    #[inline]
    pub fn accel(&self, speed: f64, leader: Option<(f64, f64)>) -> f64 {
        let free = self.free(speed);
        match leader {
            None => free,
            Some(leader) => self.behind(free, speed, leader),
        }
    }
}
