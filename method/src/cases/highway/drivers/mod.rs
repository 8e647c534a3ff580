//! Lane-change controllers of the highway-exit case: the surrogate model
//! (`mobil`: MOBIL gap acceptance with a predictive speed plan and IDM) and
//! a different controller of our own design (`gap-seeker`). See
//! `docs/models.md` for both.
//!
//! A vehicle is written as `{"model": "mobil", …}` with every parameter
//! optional; deserialising validates it. A run asks a fresh [`Driver`] for
//! an [`Action`] at every step.

mod gap_seeker;
mod gaps;
mod idm;
mod merge;
mod mobil;
mod view;

pub use gap_seeker::GapSeekerParams;
pub use gaps::{
    follow_in_right_lane, neighbour_indices, neighbours, overlaps, safe_gaps, within_speed_bounds,
    Neighbours,
};
pub use idm::{Idm, IdmSteps};
pub use mobil::MobilParams;
pub use view::{Action, DriverView, ExitDriver, Lane};

use crate::vehicle::ParamError;
use serde::{Deserialize, Serialize};
use thiserror::Error;

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

impl ExitDriver for Driver {
    type Error = std::convert::Infallible;
    fn decide(&mut self, view: &DriverView) -> Result<Action, Self::Error> {
        Ok(self.act(view))
    }
}
