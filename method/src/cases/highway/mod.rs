//! Case 2 of the paper: highway exit (functionality, four dimensions).
//!
//! A scenario is `x = (p₁, v₁, p₂, v₂)`, the initial positions and speeds of
//! two background vehicles in the right lane; the event is a task failure:
//! the VUT did not reach the off-ramp in the right lane (it stayed in the
//! left lane, or collided).

pub mod batch;
#[cfg(test)]
mod batch_tests;
pub mod descriptor;
pub mod drivers;
mod exposure_model;
pub mod external;
mod right_lane;
pub mod simulation;
pub mod table;
pub mod world;
pub mod zone;

pub use drivers::{ExitVehicle, EXIT_MODELS};
pub use exposure_model::{exit_grid, ExitExposureModel};
pub use simulation::{ExitOutcome, ExitRun};
pub use world::ExitWorld;

use crate::case::{Case, SurrogateEvaluation};
use crate::external::{DriverError, ExternalVehicle};
use crate::mass::GridMass;
use crate::objective::BoxDistance;
use std::str::FromStr;

/// The grid resolution of the case.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum HighwayPreset {
    /// The paper's grid: 5 m and 1 m/s steps, 1,640,961 scenarios.
    #[default]
    Paper,
    /// 20 m and 4 m/s steps, 9,216 scenarios: the same world for quick runs
    /// and tests.
    Coarse,
}

impl HighwayPreset {
    /// The preset's name on the wire (`paper`, `coarse`).
    pub fn name(self) -> &'static str {
        match self {
            HighwayPreset::Paper => "paper",
            HighwayPreset::Coarse => "coarse",
        }
    }

    /// (position step, speed step).
    pub fn steps(self) -> (f64, f64) {
        match self {
            HighwayPreset::Paper => (5.0, 1.0),
            HighwayPreset::Coarse => (20.0, 4.0),
        }
    }
}

impl FromStr for HighwayPreset {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "paper" => Ok(HighwayPreset::Paper),
            "coarse" => Ok(HighwayPreset::Coarse),
            other => Err(format!(
                "unknown highway-exit preset `{other}`; presets are paper (61 × 21 × 61 × 21 grid), coarse (16 × 6 × 16 × 6)"
            )),
        }
    }
}

/// The auxiliary objective `J(x) = S(F)/U_S + w d(x, Ω)` (paper Table VI).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExitObjective {
    /// Area normaliser U_S (m·s): the area of the lane-change boundary.
    pub u_s: f64,
    /// Ω, the most frequent scenarios, as a box on `(v₁, R, v₂)`:
    /// speeds within one standard deviation of the exposure's mean speed,
    /// ranges holding the central 80% of headways at that speed; normalised
    /// by the axes' spans (20 m/s, 300 m).
    pub common_set: BoxDistance<3>,
    /// Balance weight w.
    pub weight: f64,
}

impl Default for ExitObjective {
    fn default() -> Self {
        Self {
            u_s: 500.0,
            common_set: BoxDistance {
                lower: [26.0, 25.0, 26.0],
                upper: [33.0, 90.0, 33.0],
                scale: [20.0, 300.0, 20.0],
            },
            weight: 1.0,
        }
    }
}

/// The highway-exit case.
#[derive(Debug, Clone)]
pub struct HighwayExit {
    exposure: GridMass,
    exposure_name: String,
    world: ExitWorld,
    preset: HighwayPreset,
    objective: ExitObjective,
}

impl HighwayExit {
    /// The built-in exposure model on the preset's grid.
    pub fn builtin(preset: HighwayPreset) -> Self {
        let (dp, dv) = preset.steps();
        Self {
            exposure: ExitExposureModel::default().mass_on(exit_grid(dp, dv)),
            exposure_name: "builtin".into(),
            world: ExitWorld::paper(),
            preset,
            objective: ExitObjective::default(),
        }
    }

    /// The case on the preset's grid with the exposure of table `text`
    /// ([`table`]: `P(v₁, R, v₂)` and the range of `p₁`), named `name`, and
    /// the sum of its probabilities as read.
    pub fn from_table(
        text: &str,
        name: String,
        preset: HighwayPreset,
    ) -> Result<(Self, f64), crate::ndd_table::TableError> {
        let (dp, dv) = preset.steps();
        let (exposure, sum) = table::exposure_from_table(text, exit_grid(dp, dv))?;
        Ok((
            Self {
                exposure,
                exposure_name: name,
                ..Self::builtin(preset)
            },
            sum,
        ))
    }

    /// The preset the case was opened with.
    pub fn preset(&self) -> HighwayPreset {
        self.preset
    }

    /// The road, its exit and the simulation constants.
    pub fn world(&self) -> &ExitWorld {
        &self.world
    }

    /// The scenario of a cell: `[p₁, v₁, p₂, v₂]`.
    pub fn scenario(&self, cell: usize) -> [f64; 4] {
        let g = self.exposure.grid();
        [0, 1, 2, 3].map(|axis| g.value(cell, axis))
    }

    /// Simulates built-in `vehicle` on the scenario of grid cell `cell`.
    pub fn run(&self, vehicle: &ExitVehicle, cell: usize) -> ExitRun {
        simulation::run(&self.world, vehicle, self.scenario(cell))
    }

    /// [`Self::run`] on each of `cells`, in batches ([`batch::run_all`]):
    /// the same records.
    pub fn runs(&self, vehicle: &ExitVehicle, cells: &[usize]) -> Vec<ExitRun> {
        let mut runs = vec![None; cells.len()];
        batch::run_all(
            &self.world,
            vehicle,
            cells.iter().map(|&cell| self.scenario(cell)),
            |i, run| runs[i] = Some(run),
        );
        runs.into_iter()
            .map(|run| run.expect("every scenario's run ends"))
            .collect()
    }

    /// A run's criticality ([`Case::criticality`]): 0 for a failure, the
    /// share of the road to the exit still ahead at the lane change
    /// otherwise (1 without one).
    fn run_criticality(&self, run: &ExitRun) -> f64 {
        match (run.outcome.is_failure(), run.lane_change) {
            (true, _) => 0.0,
            (false, Some((_, p))) => ((self.world.exit - p) / self.world.exit).clamp(0.0, 1.0),
            (false, None) => 1.0,
        }
    }

    /// `J(x)` of a scenario.
    pub fn objective(&self, x: [f64; 4]) -> f64 {
        let area = zone::zone_area(&self.world, x);
        let distance = self
            .objective
            .common_set
            .distance(&[x[1], x[0] - x[2], x[3]]);
        area / self.objective.u_s + self.objective.weight * distance
    }
}

impl Case for HighwayExit {
    type Vehicle = ExitVehicle;

    fn name(&self) -> &'static str {
        "highway-exit"
    }

    fn exposure(&self) -> &GridMass {
        &self.exposure
    }

    fn exposure_name(&self) -> &str {
        &self.exposure_name
    }

    /// The two background vehicles' positions `p1, p2`: where they are
    /// decides whether the exit lane change is feasible.
    fn picture_axes(&self) -> (usize, usize) {
        (0, 2)
    }

    fn is_event(&self, vehicle: &ExitVehicle, cell: usize) -> bool {
        self.run(vehicle, cell).outcome.is_failure()
    }

    /// In batches: the right-lane steps side by side ([`batch::run_all`]).
    fn events(&self, vehicle: &ExitVehicle, cells: &[usize], events: &mut [bool]) {
        batch::run_all(
            &self.world,
            vehicle,
            cells.iter().map(|&cell| self.scenario(cell)),
            |i, run| events[i] = run.outcome.is_failure(),
        );
    }

    /// The share of the road to the exit still ahead when the vehicle
    /// changed lanes, `(exit − p)/exit` at the lane change: near 0 when it
    /// made the exit at the last moment; 0 for a failure.
    fn criticality(&self, vehicle: &ExitVehicle, cell: usize) -> f64 {
        self.event_and_criticality(vehicle, cell).1
    }

    fn event_and_criticality(&self, vehicle: &ExitVehicle, cell: usize) -> (bool, f64) {
        let run = self.run(vehicle, cell);
        (run.outcome.is_failure(), self.run_criticality(&run))
    }

    fn external_world(&self) -> serde_json::Value {
        let mut world = external::world_block(&self.world);
        world["preset"] = self.preset.name().into();
        world
    }

    /// The vehicle under test (`Ego`) in the left lane with its front
    /// bumper at `p = 0` and speed `v₀`, the two background vehicles in the
    /// right lane with their fronts at `p1`, `p2` and speeds `v1`, `v2`
    /// (SPEC §5; `p` measured from 200 m into the road). The exit lane
    /// change is the ego's task: written as a lane change to the right lane
    /// starting at `t = 0` over 3 s, which a simulator driving the ego by
    /// its own controller replaces by that controller's decision. The run
    /// ends when the ego reaches the off-ramp at `p = L` or after the
    /// world's time cap.
    fn openscenario(&self, cell: usize) -> Option<crate::openscenario::Scene> {
        use crate::openscenario::{LaneChange, PlacedVehicle, Scene, LEFT_LANE, RIGHT_LANE};
        let [p1, v1, p2, v2] = self.scenario(cell);
        let w = &self.world;
        let origin = 200.0;
        let rear = |front: f64| origin + front - w.length;
        let placed = |name, lane, front, speed| PlacedVehicle {
            name,
            lane,
            s: rear(front),
            speed,
            length: w.length,
        };
        Some(Scene {
            description: format!(
                "tslg highway exit ({}): BV1 at p1 = {p1} m, v1 = {v1} m/s; BV2 at p2 = {p2} m, \
                 v2 = {v2} m/s; the vehicle under test at p = 0, {} m/s, must reach the right \
                 lane before the off-ramp at p = {} m",
                self.preset.name(),
                w.start_speed,
                w.exit
            ),
            vehicles: vec![
                placed("Ego", LEFT_LANE, 0.0, w.start_speed),
                placed("BV1", RIGHT_LANE, p1, v1),
                placed("BV2", RIGHT_LANE, p2, v2),
            ],
            lane_change: Some(LaneChange {
                actor: "Ego",
                target_lane: RIGHT_LANE,
                duration: 3.0,
            }),
            max_time: w.max_time,
            goal: Some(("Ego", rear(w.exit))),
        })
    }

    /// The case's loop sees where the program changes lanes.
    fn external_step_event_and_criticality(
        &self,
        vut: &mut dyn ExternalVehicle,
        cell: usize,
    ) -> Result<(bool, Option<f64>), DriverError> {
        let run = simulation::run_with(
            &self.world,
            &mut external::ExternalExitDriver { vut },
            self.scenario(cell),
        )?;
        Ok((run.outcome.is_failure(), Some(self.run_criticality(&run))))
    }

    fn evaluate_surrogate(&self, surrogate: &ExitVehicle, cell: usize) -> SurrogateEvaluation {
        SurrogateEvaluation {
            challenge: self.surrogate_challenge(surrogate, cell),
            objective: self.objective(self.scenario(cell)),
        }
    }

    fn surrogate_challenge(&self, surrogate: &ExitVehicle, cell: usize) -> f64 {
        if self.is_event(surrogate, cell) {
            1.0
        } else {
            0.0
        }
    }

    /// The runs' failures, in batches ([`Case::events`]).
    fn surrogate_challenges(
        &self,
        surrogate: &ExitVehicle,
        cells: &[usize],
        challenges: &mut [f64],
    ) {
        batch::run_all(
            &self.world,
            surrogate,
            cells.iter().map(|&cell| self.scenario(cell)),
            |i, run| challenges[i] = if run.outcome.is_failure() { 1.0 } else { 0.0 },
        );
    }
}
