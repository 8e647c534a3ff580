//! Lane-change controllers of the highway-exit case: the surrogate model
//! (`mobil`: MOBIL gap acceptance with a predictive speed plan and IDM) and
//! a different controller of our own design (`gap-seeker`). See
//! `docs/models.md` for both.
//!
//! A vehicle is written as `{"model": "mobil", …}` with every parameter
//! optional; deserialising validates it. A run asks a fresh [`Driver`] for
//! an [`Action`] at every step.

mod gap_seeker;
mod merge;
mod mobil;

pub use gap_seeker::GapSeekerParams;
pub use mobil::MobilParams;

use super::world::{Bv, ExitWorld, Traffic};
use super::zone::blocked;
use crate::vehicle::{check, ParamError};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// The lane the VUT is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lane {
    /// The left (through) lane, where every run starts.
    Left,
    /// The right lane, which leads to the exit.
    Right,
}

/// What a driver sees at one step.
#[derive(Debug, Clone, Copy)]
pub struct DriverView<'a> {
    /// The road and its constants.
    pub world: &'a ExitWorld,
    /// Time since the run started (s).
    pub time: f64,
    /// The VUT's position along the road (m).
    pub position: f64,
    /// The VUT's speed (m/s).
    pub speed: f64,
    /// The lane the VUT is in.
    pub lane: Lane,
    /// The two background vehicles in the right lane, at this step.
    pub traffic: &'a Traffic,
}

/// What a driver does at one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Action {
    /// Longitudinal acceleration over the next step (m/s²), clipped to the world's bounds.
    pub accel: f64,
    /// Change into the right lane now (ignored once there).
    pub change_lane: bool,
}

/// A highway-exit vehicle as written, before validation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ExitVehicleSpec {
    /// MOBIL lane changing with an IDM speed plan (the paper's surrogate).
    Mobil(MobilParams),
    /// A gap seeker: accepts time gaps that shrink near the exit.
    GapSeeker(GapSeekerParams),
}

/// A validated highway-exit vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "ExitVehicleSpec", into = "ExitVehicleSpec")]
pub struct ExitVehicle(ExitVehicleSpec);

/// Built-in highway-exit vehicles.
pub const EXIT_MODELS: [&str; 2] = ["mobil", "gap-seeker"];

/// An unknown built-in name.
#[derive(Debug, Error, PartialEq)]
#[error("unknown highway-exit vehicle `{0}`; built-in models are mobil, gap-seeker")]
pub struct UnknownExitModel(pub String);

impl TryFrom<ExitVehicleSpec> for ExitVehicle {
    type Error = ParamError;
    fn try_from(spec: ExitVehicleSpec) -> Result<Self, ParamError> {
        match &spec {
            ExitVehicleSpec::Mobil(p) => p.validate(),
            ExitVehicleSpec::GapSeeker(p) => p.validate(),
        }?;
        Ok(Self(spec))
    }
}

impl From<ExitVehicle> for ExitVehicleSpec {
    fn from(vehicle: ExitVehicle) -> Self {
        vehicle.0
    }
}

impl ExitVehicle {
    /// The built-in vehicle `name` (`mobil`, `gap-seeker`) with its default parameters.
    pub fn builtin(name: &str) -> Result<Self, UnknownExitModel> {
        match name {
            "mobil" => Ok(Self(ExitVehicleSpec::Mobil(MobilParams::default()))),
            "gap-seeker" => Ok(Self(ExitVehicleSpec::GapSeeker(GapSeekerParams::default()))),
            other => Err(UnknownExitModel(other.to_owned())),
        }
    }

    /// The model's name on the wire.
    pub fn name(&self) -> &'static str {
        match self.0 {
            ExitVehicleSpec::Mobil(_) => "mobil",
            ExitVehicleSpec::GapSeeker(_) => "gap-seeker",
        }
    }

    /// A fresh driver for one run.
    pub fn driver(&self) -> Driver {
        match self.0 {
            ExitVehicleSpec::Mobil(p) => Driver::Mobil(mobil::MobilDriver::new(p)),
            ExitVehicleSpec::GapSeeker(p) => Driver::GapSeeker(gap_seeker::GapSeekerDriver::new(p)),
        }
    }
}

/// A driver with its memory for one run.
#[derive(Debug, Clone)]
pub enum Driver {
    /// The MOBIL driver and its plan.
    Mobil(mobil::MobilDriver),
    /// The gap seeker and its state.
    GapSeeker(gap_seeker::GapSeekerDriver),
}

impl Driver {
    /// The IDM both built-in drivers follow with once in the right lane:
    /// there a run's steps no longer depend on the driver's memory, only
    /// on this ([`follow_in_right_lane`]).
    pub fn right_lane_idm(&self) -> &IdmSteps {
        match self {
            Driver::Mobil(d) => d.right_lane_idm(),
            Driver::GapSeeker(d) => d.right_lane_idm(),
        }
    }

    /// The driver's action at one step.
    pub fn act(&mut self, view: &DriverView) -> Action {
        match self {
            Driver::Mobil(d) => d.act(view),
            Driver::GapSeeker(d) => d.act(view),
        }
    }
}

/// Whatever drives the VUT on the highway: a built-in [`Driver`] (which
/// cannot fail) or an external program (see [`super::external`]).
pub trait ExitDriver {
    /// Why a decision failed (`Infallible` for built-in drivers).
    type Error;
    /// The action at the step `view` describes.
    fn decide(&mut self, view: &DriverView) -> Result<Action, Self::Error>;
}

impl ExitDriver for Driver {
    type Error = std::convert::Infallible;
    fn decide(&mut self, view: &DriverView) -> Result<Action, Self::Error> {
        Ok(self.act(view))
    }
}

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

/// The right-lane neighbours of a point `p`: the nearest BV at or ahead of
/// it and the nearest behind it. Of two BVs at the same position the slower
/// is the one ahead and the faster the one behind (the more constraining
/// either way), so nothing depends on the BVs' labels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Neighbours {
    /// The nearest BV at or ahead of the point, if any.
    pub ahead: Option<Bv>,
    /// The nearest BV behind the point, if any.
    pub behind: Option<Bv>,
}

/// The right-lane neighbours of `position` among `bvs` (see [`Neighbours`]).
pub fn neighbours(bvs: &[Bv; 2], position: f64) -> Neighbours {
    let (ahead, behind) = neighbour_indices(bvs, position);
    Neighbours {
        ahead: ahead.map(|i| bvs[i]),
        behind: behind.map(|i| bvs[i]),
    }
}

/// [`neighbours`] as indices into `bvs`: `(ahead, behind)`.
#[inline]
pub fn neighbour_indices(bvs: &[Bv; 2], position: f64) -> (Option<usize>, Option<usize>) {
    let (mut ahead, mut behind): (Option<usize>, Option<usize>) = (None, None);
    for (i, bv) in bvs.iter().enumerate() {
        if bv.position >= position {
            if ahead.is_none_or(|a| (bv.position, bv.speed) < (bvs[a].position, bvs[a].speed)) {
                ahead = Some(i);
            }
        } else if behind.is_none_or(|b| (bv.position, bv.speed) > (bvs[b].position, bvs[b].speed)) {
            behind = Some(i);
        }
    }
    (ahead, behind)
}

/// Whether a lane change at `position` keeps every BV at least its safe
/// time gap away, `|p − b| − ℓ ≥ t_min u`: the task's definition of a safe
/// lane change (the feasible zone's), which both controllers respect.
pub fn safe_gaps(world: &ExitWorld, bvs: &[Bv; 2], position: f64) -> bool {
    bvs.iter().all(|bv| {
        let (low, high) = blocked(world, bv.position, bv.speed);
        !(low < position && position < high)
    })
}

/// Whether a vehicle at `position` overlaps a BV (bumper gap < 0 either way).
pub fn overlaps(world: &ExitWorld, bvs: &[Bv; 2], position: f64) -> bool {
    bvs.iter()
        .any(|bv| (bv.position - position).abs() < world.length)
}

/// Right-lane car following: IDM behind the nearest BV ahead, within the
/// physical acceleration bounds.
pub fn follow_in_right_lane(idm: &IdmSteps, view: &DriverView) -> f64 {
    let ahead = neighbours(&view.traffic.bvs, view.position)
        .ahead
        .map(|bv| (bv.position - view.position - view.world.length, bv.speed));
    idm.accel(view.speed, ahead)
        .clamp(view.world.emergency_brake, view.world.accel.1)
}

/// `accel` cut so that the speed after one step stays in `[v_min, v_max]`:
/// both controllers keep to the lane-change boundary's speeds in the left
/// lane.
pub fn within_speed_bounds(world: &ExitWorld, speed: f64, accel: f64) -> f64 {
    accel.clamp(
        (world.speed.0 - speed) / world.dt,
        (world.speed.1 - speed) / world.dt,
    )
}
