//! Highway-exit runs of a built-in vehicle in batches: each run's steps in
//! the left lane one by one (the drivers' plan search and MOBIL's
//! criterion branch too much for vector lanes), then the runs that reached
//! the right lane side by side in vector lanes ([`right_lane::finish`]),
//! where about four fifths of the steps are.
//!
//! The left lane runs [`RunInProgress::step`], the very code of the scalar
//! [`super::simulation::run_with`], and the right lane its operations lane
//! by lane, so every record is the scalar one bit for bit (tested on every
//! coarse cell and an eighth of the paper grid per vehicle; the highway
//! benchmark checks every paper cell).

use super::drivers::ExitVehicle;
use super::right_lane::{self, Tail};
use super::simulation::{ExitRun, RunInProgress};
use super::world::ExitWorld;

/// Scenarios whose right-lane tails are gathered before they run: enough
/// to keep the lanes full, few enough to stay in cache.
const GATHER: usize = 512;

/// Runs `vehicle` on every scenario of `scenarios`, calling
/// `record(i, run)` once for scenario `i` when its run ends (in the order
/// runs end, not the order of `scenarios`).
pub fn run_all(
    world: &ExitWorld,
    vehicle: &ExitVehicle,
    scenarios: impl Iterator<Item = [f64; 4]>,
    mut record: impl FnMut(usize, ExitRun),
) {
    let mut tails = Vec::with_capacity(GATHER);
    let mut driver = vehicle.driver();
    let idm = *driver.right_lane_idm();
    let mut scenarios = scenarios.enumerate().peekable();
    while scenarios.peek().is_some() {
        tails.clear();
        for (index, x) in scenarios.by_ref().take(GATHER) {
            driver = vehicle.driver();
            let mut run = RunInProgress::new(world, x);
            loop {
                let Ok(step) = run.step(world, &mut driver);
                if let Some(done) = step {
                    record(index, done);
                    break;
                }
                if run.in_right_lane() {
                    tails.push(Tail { index, run });
                    break;
                }
            }
        }
        right_lane::finish(world, &idm, &tails, &mut record);
    }
}
