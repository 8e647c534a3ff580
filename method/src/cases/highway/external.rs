//! The highway-exit world as an external program sees it: lane 0 is the
//! right lane (the exit lane, where the two BVs drive), lane 1 the left lane
//! where the VUT starts; positions are front bumpers with the VUT starting
//! at 0 and the off-ramp at `exit`.

use super::drivers::{neighbours, Action, DriverView, ExitDriver, Lane};
use super::world::ExitWorld;
use crate::external::{checked_control, DriverError, Ego, ExternalVehicle, Observation, Other};

/// The lane numbers of the protocol.
pub const RIGHT_LANE: u32 = 0;
/// The protocol's number of the left (through) lane.
pub const LEFT_LANE: u32 = 1;

/// The constants a program is told at each reset.
pub fn world_block(world: &ExitWorld) -> serde_json::Value {
    serde_json::json!({
        "dt": world.dt,
        "lanes": 2,
        "start_lane": LEFT_LANE,
        "exit_lane": RIGHT_LANE,
        "exit": world.exit,
        "start_speed": world.start_speed,
        "vehicle_length": world.length,
        "speed": [world.speed.0, world.speed.1],
        "acceleration": [world.accel.0, world.accel.1],
        "emergency_brake": world.emergency_brake,
        "safe_time_gap": world.t_min,
        "bv_following_gap": world.d_cf,
        "zone_horizon": world.horizon,
        "max_time": world.max_time,
    })
}

/// The observation of one step.
pub fn observation(view: &DriverView) -> Observation {
    let world = view.world;
    let lane = match view.lane {
        Lane::Left => LEFT_LANE,
        Lane::Right => RIGHT_LANE,
    };
    // The vehicle directly ahead in the VUT's lane (only in the right lane).
    let ahead = (view.lane == Lane::Right)
        .then(|| neighbours(&view.traffic.bvs, view.position).ahead)
        .flatten();
    let vehicles = view
        .traffic
        .bvs
        .iter()
        .enumerate()
        .map(|(i, bv)| Other {
            id: i as u32 + 1,
            position: bv.position,
            speed: bv.speed,
            lane: RIGHT_LANE,
            gap: (ahead == Some(*bv)).then_some(bv.position - view.position - world.length),
        })
        .collect();
    Observation {
        step: (view.time / world.dt).round() as u32,
        time: view.time,
        ego: Ego {
            position: view.position,
            speed: view.speed,
            lane,
        },
        vehicles,
    }
}

/// A program driving the VUT in step mode.
pub struct ExternalExitDriver<'a> {
    /// The program, reset for this test.
    pub vut: &'a mut dyn ExternalVehicle,
}

impl ExitDriver for ExternalExitDriver<'_> {
    type Error = DriverError;

    fn decide(&mut self, view: &DriverView) -> Result<Action, DriverError> {
        let control = checked_control(self.vut.step(&observation(view))?)?;
        Ok(Action {
            accel: control.acceleration,
            change_lane: control.change_lane,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cases::highway::world::Traffic;

    #[test]
    fn the_gap_is_given_for_the_bv_ahead_in_the_right_lane_only() {
        let world = ExitWorld::paper();
        let traffic = Traffic::new([40.0, 30.0, -20.0, 28.0]);
        let mut view = DriverView {
            world: &world,
            time: 1.2,
            position: 10.0,
            speed: 29.0,
            lane: Lane::Left,
            traffic: &traffic,
        };
        let o = observation(&view);
        assert_eq!(o.step, 12);
        assert_eq!(o.ego.lane, LEFT_LANE);
        assert!(o.vehicles.iter().all(|v| v.gap.is_none()));
        view.lane = Lane::Right;
        let o = observation(&view);
        assert_eq!(o.vehicles[0].gap, Some(40.0 - 10.0 - 5.0));
        assert_eq!(o.vehicles[1].gap, None);
        assert_eq!(world_block(&world)["exit"], 200.0);
    }
}
