//! One highway-exit run: a vehicle's driver against the scripted BVs.
//!
//! Each step of Δt: the driver acts on the current state (a lane change is
//! instantaneous, as the paper's lane-change point `(t, p)`). A lane change
//! into an occupied spot is a collision; one that leaves a BV closer than the
//! safe time gap (`|p − b| − ℓ < t_min u`: outside the feasible zone `F`) is
//! not the safe lane change the task asks for, and the run ends as *failed
//! to exit*. Then the VUT moves (`p += v Δt +
//! a Δt²/2`, `v += a Δt`, with `a` cut so that `0 ≤ v ≤ v_max` and within
//! `[emergency_brake, a_max]`) and the BVs move. In the right lane an
//! overlap with a BV is a collision. The run ends when the VUT reaches
//! `p = L`: in the right lane it exits, in the left lane it failed to exit
//! (as after `max_time`).

use super::drivers::{overlaps, safe_gaps, DriverView, ExitDriver, ExitVehicle, Lane};
use super::world::{ExitWorld, Traffic};

/// How a run ended. Failures are the event `A`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ExitOutcome {
    /// The VUT reached the exit in the right lane.
    Exited,
    /// The VUT passed the exit, or ran out of time, without taking it.
    FailedToExit,
    /// The VUT overlapped a background vehicle.
    Collision,
}

impl ExitOutcome {
    /// Whether the run is the event `A` (any outcome but `Exited`).
    pub fn is_failure(self) -> bool {
        self != ExitOutcome::Exited
    }
}

/// The record of a run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExitRun {
    /// How the run ended.
    pub outcome: ExitOutcome,
    /// When the run ended (s).
    pub time: f64,
    /// The lane-change point `(t, p)`, if the VUT changed lanes.
    pub lane_change: Option<(f64, f64)>,
}

/// Runs a built-in vehicle on scenario `x`.
pub fn run(world: &ExitWorld, vehicle: &ExitVehicle, x: [f64; 4]) -> ExitRun {
    let Ok(run) = run_with(world, &mut vehicle.driver(), x);
    run
}

/// Runs a fresh `driver` on scenario `x`; a driver error ends the run with
/// that error.
pub fn run_with<D: ExitDriver>(
    world: &ExitWorld,
    driver: &mut D,
    x: [f64; 4],
) -> Result<ExitRun, D::Error> {
    let mut traffic = Traffic::new(x);
    let (mut p, mut v) = (0.0, world.start_speed);
    let mut lane = Lane::Left;
    let mut lane_change = None;
    let steps = (world.max_time / world.dt).round() as usize;
    let end = |outcome, k: usize, lane_change| ExitRun {
        outcome,
        time: k as f64 * world.dt,
        lane_change,
    };
    for k in 0..steps {
        let time = k as f64 * world.dt;
        let action = driver.decide(&DriverView {
            world,
            time,
            position: p,
            speed: v,
            lane,
            traffic: &traffic,
        })?;
        if lane == Lane::Left && action.change_lane {
            lane = Lane::Right;
            lane_change = Some((time, p));
            if overlaps(world, &traffic.bvs, p) {
                return Ok(end(ExitOutcome::Collision, k, lane_change));
            }
            if !safe_gaps(world, &traffic.bvs, p) {
                return Ok(end(ExitOutcome::FailedToExit, k, lane_change));
            }
        }
        let a = action
            .accel
            .clamp(world.emergency_brake, world.accel.1)
            .clamp(-v / world.dt, (world.speed.1 - v) / world.dt);
        p += v * world.dt + 0.5 * a * world.dt * world.dt;
        v += a * world.dt;
        traffic.step(world);
        if lane == Lane::Right && overlaps(world, &traffic.bvs, p) {
            return Ok(end(ExitOutcome::Collision, k + 1, lane_change));
        }
        if p >= world.exit {
            let outcome = match lane {
                Lane::Right => ExitOutcome::Exited,
                Lane::Left => ExitOutcome::FailedToExit,
            };
            return Ok(end(outcome, k + 1, lane_change));
        }
    }
    Ok(end(ExitOutcome::FailedToExit, steps, lane_change))
}
