//! Case 1 of the paper: cut-in (safety, two dimensions).
//!
//! A scenario is `x = (R, Ṙ)`, the range and range rate at the moment a
//! background vehicle cuts in; the event is an accident during the run.

pub mod batch;
#[cfg(test)]
mod batch_tests;
pub mod descriptor;
mod exposure_model;
mod simulation;

pub use exposure_model::{default_grid, CutInExposureModel};
pub use simulation::{
    enhanced_ttc, normalised_ettc, CutInPreset, CutInRun, CutInSettings, SpeedBound,
};

use crate::case::{Case, SurrogateEvaluation};
use crate::external::{DriverError, ExternalFollower, ExternalVehicle, NOMINAL_LENGTH};
use crate::mass::GridMass;
use crate::ndd_table::{parse_table, NddTable, TableError};
use crate::noise::NoiseRng;
use crate::objective::BoxDistance;
use crate::vehicle::VehicleModel;
use thiserror::Error;

/// Why a cut-in case could not be set up.
#[derive(Debug, Error, PartialEq)]
pub enum CutInError {
    /// The exposure is not two-dimensional.
    #[error("the cut-in case needs a two-dimensional (range, range rate) exposure, got {0} dimension(s)")]
    Dimensions(usize),
    /// The exposure table was refused.
    #[error(transparent)]
    Table(#[from] TableError),
    /// No probability at a positive range: a cut-in happens ahead of the
    /// vehicle (R > 0), and the exposure model has no density elsewhere.
    #[error(
        "the exposure has no probability at a positive range (R > 0 m): a cut-in happens \
         ahead of the vehicle"
    )]
    NoPositiveRange,
}

/// Parameters of the auxiliary objective `J(x) = mnpETTC(x) + w d(x, Ω)` (paper Table II).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CutInObjective {
    /// ETTC normalisation U_I (s).
    pub u_i: f64,
    /// Ω = [6, 88] m × [−2.4, 1.2] m/s with normalisation U_F = (18, 20).
    pub common_set: BoxDistance<2>,
    /// Balance weight w.
    pub weight: f64,
}

impl Default for CutInObjective {
    fn default() -> Self {
        Self {
            u_i: 100.0,
            common_set: BoxDistance {
                lower: [6.0, -2.4],
                upper: [88.0, 1.2],
                scale: [18.0, 20.0],
            },
            weight: 1.0,
        }
    }
}

/// The cut-in case: an exposure on a (range, range rate) grid, a simulation
/// preset and the auxiliary objective.
#[derive(Debug, Clone)]
pub struct CutIn {
    exposure: GridMass,
    exposure_name: String,
    settings: CutInSettings,
    preset: CutInPreset,
    objective: CutInObjective,
}

impl CutIn {
    /// The case on a given exposure (a table or a model evaluated on a grid).
    pub fn new(
        exposure: GridMass,
        exposure_name: impl Into<String>,
        preset: CutInPreset,
    ) -> Result<Self, CutInError> {
        let d = exposure.grid().dimensions();
        if d != 2 {
            return Err(CutInError::Dimensions(d));
        }
        let grid = exposure.grid();
        if !(0..grid.len()).any(|cell| grid.value(cell, 0) > 0.0 && exposure.p(cell) > 0.0) {
            return Err(CutInError::NoPositiveRange);
        }
        Ok(Self {
            exposure,
            exposure_name: exposure_name.into(),
            settings: preset.settings(),
            preset,
            objective: CutInObjective::default(),
        })
    }

    /// The built-in default: the fitted exposure model on the default grid.
    pub fn builtin(preset: CutInPreset) -> Self {
        let mass = CutInExposureModel::default().mass_on(default_grid());
        Self::new(mass, "builtin", preset).expect("the default grid is two-dimensional")
    }

    /// The case on an exposure table in the authors' layout (see [`crate::ndd_table`]).
    pub fn from_table(
        text: &str,
        exposure_name: impl Into<String>,
        preset: CutInPreset,
    ) -> Result<(Self, NddTable), CutInError> {
        let table = parse_table(text, "range", "range_rate")?;
        let case = Self::new(table.mass.clone(), exposure_name, preset)?;
        Ok((case, table))
    }

    /// The simulation preset in force.
    pub fn preset(&self) -> CutInPreset {
        self.preset
    }

    /// The preset's simulation settings.
    pub fn settings(&self) -> &CutInSettings {
        &self.settings
    }

    /// Runs `vehicle` in `cell` and returns the full run record.
    pub fn run(&self, vehicle: &VehicleModel, cell: usize) -> CutInRun {
        let grid = self.exposure.grid();
        self.settings.run(
            vehicle,
            grid.value(cell, 0),
            grid.value(cell, 1),
            self.objective.u_i,
        )
    }
}

impl Case for CutIn {
    type Vehicle = VehicleModel;

    fn name(&self) -> &'static str {
        "cut-in"
    }

    fn exposure(&self) -> &GridMass {
        &self.exposure
    }

    fn exposure_name(&self) -> &str {
        &self.exposure_name
    }

    fn is_event(&self, vehicle: &VehicleModel, cell: usize) -> bool {
        self.run(vehicle, cell).accident
    }

    /// In batches of [`batch::LANES`] for the IDM and the FVDM (the last
    /// one padded with its first scenario), one by one for the others.
    fn events(&self, vehicle: &VehicleModel, cells: &[usize], events: &mut [bool]) {
        let Some(follower) = batch::BatchFollower::of(vehicle) else {
            for (event, &cell) in events.iter_mut().zip(cells) {
                *event = self.is_event(vehicle, cell);
            }
            return;
        };
        let grid = self.exposure.grid();
        for (cells, events) in cells
            .chunks(batch::LANES)
            .zip(events.chunks_mut(batch::LANES))
        {
            let mut range = [grid.value(cells[0], 0); batch::LANES];
            let mut range_rate = [grid.value(cells[0], 1); batch::LANES];
            for (i, &cell) in cells.iter().enumerate() {
                range[i] = grid.value(cell, 0);
                range_rate[i] = grid.value(cell, 1);
            }
            let crashed = batch::accidents(&self.settings, &follower, &range, &range_rate);
            events.copy_from_slice(&crashed[..cells.len()]);
        }
    }

    /// mnpETTC: the smallest normalised enhanced time to collision over the
    /// run, 0 after an accident ([`CutInRun::mnp_ettc`]).
    fn criticality(&self, vehicle: &VehicleModel, cell: usize) -> f64 {
        self.run(vehicle, cell).mnp_ettc
    }

    fn event_and_criticality(&self, vehicle: &VehicleModel, cell: usize) -> (bool, f64) {
        let run = self.run(vehicle, cell);
        (run.accident, run.mnp_ettc)
    }

    fn is_noisy(&self, vehicle: &VehicleModel) -> bool {
        vehicle.is_noisy()
    }

    fn noisy_run(&self, vehicle: &VehicleModel, cell: usize, noise: NoiseRng) -> (bool, f64) {
        let grid = self.exposure.grid();
        let Ok(run) = self.settings.run_with(
            &mut vehicle.noisy_controller(noise),
            grid.value(cell, 0),
            grid.value(cell, 1),
            self.objective.u_i,
        );
        (run.accident, run.mnp_ettc)
    }

    /// The simulation settings (`initial_speed`, `dt`, `steps`,
    /// `acceleration` and `speed` bounds, `accident_gap` with `inclusive`)
    /// and the one-lane layout.
    fn external_world(&self) -> serde_json::Value {
        let mut world = serde_json::to_value(self.settings).expect("settings serialise");
        world["lanes"] = 1.into();
        world["vehicle_length"] = NOMINAL_LENGTH.into();
        world["preset"] = self.preset.name().into();
        world
    }

    /// The vehicle under test (`Ego`, right lane) at its initial speed `v`
    /// and the background vehicle (`CutIn`) in the left lane, its rear end
    /// `R` ahead of the ego's front at speed `v + Ṙ`, changing into the
    /// ego's lane at once at `t = 0`: the cut-in the simulation starts from
    /// (SPEC §3). The run lasts the preset's `steps · dt`.
    fn openscenario(&self, cell: usize) -> Option<crate::openscenario::Scene> {
        use crate::openscenario::{LaneChange, PlacedVehicle, Scene, LEFT_LANE, RIGHT_LANE};
        let grid = self.exposure.grid();
        let (range, rate) = (grid.value(cell, 0), grid.value(cell, 1));
        let speed = self.settings.initial_speed;
        // The ego's rear end 100 m into the road.
        let ego = 100.0;
        Some(Scene {
            description: format!(
                "tslg cut-in ({}): range R = {range} m, range rate R' = {rate} m/s, \
                 initial speed {speed} m/s",
                self.preset.name()
            ),
            vehicles: vec![
                PlacedVehicle {
                    name: "Ego",
                    lane: RIGHT_LANE,
                    s: ego,
                    speed,
                    length: NOMINAL_LENGTH,
                },
                PlacedVehicle {
                    name: "CutIn",
                    lane: LEFT_LANE,
                    s: ego + NOMINAL_LENGTH + range,
                    speed: (speed + rate).max(0.0),
                    length: NOMINAL_LENGTH,
                },
            ],
            lane_change: Some(LaneChange {
                actor: "CutIn",
                target_lane: RIGHT_LANE,
                duration: 0.0,
            }),
            max_time: self.settings.dt * self.settings.steps as f64,
            goal: None,
        })
    }

    /// The case's loop measures mnpETTC as it drives the program.
    fn external_step_event_and_criticality(
        &self,
        vut: &mut dyn ExternalVehicle,
        cell: usize,
    ) -> Result<(bool, Option<f64>), DriverError> {
        let grid = self.exposure.grid();
        let run = self.settings.run_with(
            &mut ExternalFollower { vut },
            grid.value(cell, 0),
            grid.value(cell, 1),
            self.objective.u_i,
        )?;
        Ok((run.accident, Some(run.mnp_ettc)))
    }

    fn evaluate_surrogate(&self, surrogate: &VehicleModel, cell: usize) -> SurrogateEvaluation {
        let run = self.run(surrogate, cell);
        let values = self.exposure.grid().values(cell);
        let distance = self.objective.common_set.distance(&[values[0], values[1]]);
        SurrogateEvaluation {
            challenge: if run.accident { 1.0 } else { 0.0 },
            objective: run.mnp_ettc + self.objective.weight * distance,
        }
    }
}
