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
    let mut run = RunInProgress::new(world, x);
    loop {
        if let Some(done) = run.step(world, driver)? {
            return Ok(done);
        }
    }
}

/// A run between steps: what [`run_with`] keeps from one step to the next,
/// so that a batch ([`super::batch`]) can advance several runs side by side
/// with exactly the scalar run's operations.
#[derive(Debug, Clone, Copy)]
pub struct RunInProgress {
    pub(super) traffic: Traffic,
    /// The VUT's position (m) and speed (m/s).
    pub(super) p: f64,
    pub(super) v: f64,
    lane: Lane,
    pub(super) lane_change: Option<(f64, f64)>,
    /// Steps taken, and the time cap in steps.
    pub(super) k: usize,
    pub(super) steps: usize,
}

impl RunInProgress {
    /// The VUT at `p = 0`, `v₀`, in the left lane, and the BVs of scenario `x`.
    pub fn new(world: &ExitWorld, x: [f64; 4]) -> Self {
        Self {
            traffic: Traffic::new(x),
            p: 0.0,
            v: world.start_speed,
            lane: Lane::Left,
            lane_change: None,
            k: 0,
            steps: (world.max_time / world.dt).round() as usize,
        }
    }

    fn end(&self, outcome: ExitOutcome, k: usize, world: &ExitWorld) -> ExitRun {
        ExitRun {
            outcome,
            time: k as f64 * world.dt,
            lane_change: self.lane_change,
        }
    }

    /// Whether the VUT is in the right lane.
    pub fn in_right_lane(&self) -> bool {
        self.lane == Lane::Right
    }

    /// The VUT's and the BVs' motion over one step, the VUT with `accel`
    /// cut to the physical bounds and to speeds in `[0, v_max]`. (A
    /// braking cut at `−v/Δt` can leave `v + a Δt` a rounding error below
    /// 0, e.g. −1.1 × 10⁻¹⁶; the speed is then 0, since the IDM's
    /// `(v/v₀)^δ` of a negative speed is NaN for a fractional δ.)
    #[inline]
    fn advance(&mut self, world: &ExitWorld, accel: f64) {
        let v = self.v;
        let a = accel
            .clamp(world.emergency_brake, world.accel.1)
            .clamp(-v / world.dt, (world.speed.1 - v) / world.dt);
        self.p += v * world.dt + 0.5 * a * world.dt * world.dt;
        self.v = (v + a * world.dt).max(0.0);
        self.traffic.step(world);
        self.k += 1;
    }

    /// One step of Δt; the run's record once it has ended.
    #[inline]
    pub fn step<D: ExitDriver>(
        &mut self,
        world: &ExitWorld,
        driver: &mut D,
    ) -> Result<Option<ExitRun>, D::Error> {
        let k = self.k;
        if k >= self.steps {
            return Ok(Some(self.end(ExitOutcome::FailedToExit, self.steps, world)));
        }
        let time = k as f64 * world.dt;
        let action = driver.decide(&DriverView {
            world,
            time,
            position: self.p,
            speed: self.v,
            lane: self.lane,
            traffic: &self.traffic,
        })?;
        if self.lane == Lane::Left && action.change_lane {
            self.lane = Lane::Right;
            self.lane_change = Some((time, self.p));
            if overlaps(world, &self.traffic.bvs, self.p) {
                return Ok(Some(self.end(ExitOutcome::Collision, k, world)));
            }
            if !safe_gaps(world, &self.traffic.bvs, self.p) {
                return Ok(Some(self.end(ExitOutcome::FailedToExit, k, world)));
            }
        }
        self.advance(world, action.accel);
        if self.lane == Lane::Right && overlaps(world, &self.traffic.bvs, self.p) {
            return Ok(Some(self.end(ExitOutcome::Collision, k + 1, world)));
        }
        if self.p >= world.exit {
            let outcome = match self.lane {
                Lane::Right => ExitOutcome::Exited,
                Lane::Left => ExitOutcome::FailedToExit,
            };
            return Ok(Some(self.end(outcome, k + 1, world)));
        }
        Ok(None)
    }
}

#[cfg(test)]
mod tests {
    use super::run;
    use crate::cases::highway::{ExitVehicle, ExitWorld};

    /// The plan's bounds must hold 0: `brake` above 0 or `accelerate`
    /// below it left no plan acceleration and panicked.
    #[test]
    fn plan_bounds_that_miss_zero_are_refused() {
        for (spec, name) in [
            (r#"{"model": "mobil", "brake": 3}"#, "brake"),
            (r#"{"model": "mobil", "accelerate": -5}"#, "accelerate"),
            (
                r#"{"model": "mobil", "brake": -1, "accelerate": -2}"#,
                "accelerate",
            ),
        ] {
            let err = serde_json::from_str::<ExitVehicle>(spec)
                .expect_err(spec)
                .to_string();
            assert!(err.contains(name), "{spec}: {err}");
        }
        let ok: ExitVehicle =
            serde_json::from_str(r#"{"model": "mobil", "brake": 0, "accelerate": 0}"#)
                .expect("a plan of 0 only");
        let world = ExitWorld::paper();
        let run = run(&world, &ok, [100.0, 25.0, 20.0, 30.0]);
        assert!(run.time > 0.0);
    }
}
