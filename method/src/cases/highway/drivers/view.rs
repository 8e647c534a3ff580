//! What a highway-exit driver sees at a step and what it does: the
//! interface between the simulation and every driver, built-in or a
//! program.

use crate::cases::highway::world::{ExitWorld, Traffic};

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

/// Whatever drives the VUT on the highway: a built-in [`super::Driver`] (which
/// cannot fail) or an external program (see [`crate::cases::highway::external`]).
pub trait ExitDriver {
    /// Why a decision failed (`Infallible` for built-in drivers).
    type Error;
    /// The action at the step `view` describes.
    fn decide(&mut self, view: &DriverView) -> Result<Action, Self::Error>;
}
