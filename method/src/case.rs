//! What a case is: a scenario grid with an exposure model, and a simulation
//! that yields an outcome for a vehicle model. Library search, sampling,
//! estimation and exact answers are written against this trait only.

use crate::external::{DriverError, ExternalMode, ExternalVehicle};
use crate::grid::Grid;
use crate::mass::GridMass;
use crate::noise::NoiseRng;

/// One surrogate-model run at a scenario, as library search needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurrogateEvaluation {
    /// Maneuver challenge `P(S|x)` (0 or 1 for a deterministic surrogate).
    pub challenge: f64,
    /// Auxiliary objective `J(x)`: smaller is more critical.
    pub objective: f64,
}

/// A grid case as the exact computations see it: an exposure on a grid and a vehicle's outcome per cell.
pub trait Case: Sync {
    /// The vehicle models this case can simulate.
    type Vehicle: Sync;

    /// The case's name on the command line and in files (`cut-in`, …).
    fn name(&self) -> &'static str;

    /// The exposure `P(x)` on the case's grid.
    fn exposure(&self) -> &GridMass;

    /// A short name for the exposure (`builtin`, or the table's file name).
    fn exposure_name(&self) -> &str;

    /// The scenario grid `X` (the exposure's).
    fn grid(&self) -> &Grid {
        self.exposure().grid()
    }

    /// The two grid axes a library's picture is projected onto.
    fn picture_axes(&self) -> (usize, usize) {
        (0, 1)
    }

    /// Whether `vehicle` has the event `A` in scenario `cell`, for a
    /// deterministic vehicle (`P(A|x)` is this as 0 or 1); a noisy one
    /// ([`Case::is_noisy`]) runs here without its noise: its tests go
    /// through [`Case::noisy_run`].
    fn is_event(&self, vehicle: &Self::Vehicle, cell: usize) -> bool;

    /// [`Case::is_event`] for many cells: `events[i]` for `cells[i]` (of
    /// the same length). Cases with a batched simulation override it.
    fn events(&self, vehicle: &Self::Vehicle, cells: &[usize], events: &mut [bool]) {
        for (event, &cell) in events.iter_mut().zip(cells) {
            *event = self.is_event(vehicle, cell);
        }
    }

    /// How close `vehicle` came to the event in scenario `cell`, in
    /// `[0, 1]`: 0 for the event, small for a near miss, 1 for a run that
    /// never came near it. Adaptive campaigns search from the near misses
    /// (docs/adaptive-design.md). The default knows only the outcome.
    fn criticality(&self, vehicle: &Self::Vehicle, cell: usize) -> f64 {
        if self.is_event(vehicle, cell) {
            0.0
        } else {
            1.0
        }
    }

    /// [`Case::is_event`] and [`Case::criticality`] together; cases whose
    /// criticality comes from the same run override it to simulate once.
    fn event_and_criticality(&self, vehicle: &Self::Vehicle, cell: usize) -> (bool, f64) {
        (
            self.is_event(vehicle, cell),
            self.criticality(vehicle, cell),
        )
    }

    /// Whether `vehicle`'s runs of one scenario may differ (a built-in
    /// model with `noise`, [`crate::noise`]). Its outcome is then a draw,
    /// `P(A|x)` is no longer 0 or 1, and every run is of one test: with
    /// the test's noise stream, [`Case::noisy_run`]. Cases that cannot
    /// run noise refuse such a vehicle when a campaign opens.
    fn is_noisy(&self, _vehicle: &Self::Vehicle) -> bool {
        false
    }

    /// [`Case::event_and_criticality`] of one run of `vehicle` in `cell`
    /// whose noise is drawn from `noise` (the test's stream); the same as
    /// it for a deterministic vehicle.
    fn noisy_run(&self, vehicle: &Self::Vehicle, cell: usize, _noise: NoiseRng) -> (bool, f64) {
        self.event_and_criticality(vehicle, cell)
    }

    /// The event and criticality of `vehicle` in `cell` as test `index` of
    /// the campaign seeded `seed`: a noisy vehicle's noise from the test's
    /// own stream ([`crate::noise::noise_rng`]), so every run of the test
    /// is the same.
    fn test_run(&self, vehicle: &Self::Vehicle, cell: usize, seed: u64, index: u64) -> (bool, f64) {
        if self.is_noisy(vehicle) {
            self.noisy_run(vehicle, cell, crate::noise::noise_rng(seed, index))
        } else {
            self.event_and_criticality(vehicle, cell)
        }
    }

    /// The constants an external program is told at each reset (time
    /// step, horizon, bounds, lanes).
    fn external_world(&self) -> serde_json::Value;

    /// Whether an external program driving in step mode has the event in
    /// scenario `cell`: this case's simulation asks it for a control at
    /// every step.
    fn external_step_event(
        &self,
        vut: &mut dyn ExternalVehicle,
        cell: usize,
    ) -> Result<bool, DriverError> {
        Ok(self.external_step_event_and_criticality(vut, cell)?.0)
    }

    /// [`Case::external_step_event`] with the criticality of the run
    /// ([`Case::criticality`]), which the case's loop measures as it drives
    /// the program; `None` where it does not.
    fn external_step_event_and_criticality(
        &self,
        vut: &mut dyn ExternalVehicle,
        cell: usize,
    ) -> Result<(bool, Option<f64>), DriverError>;

    /// [`Case::external_event`] with the run's criticality: measured by the
    /// case in step mode, reported by the program in episode mode
    /// (protocol version 2); `None` when neither says.
    fn external_event_and_criticality(
        &self,
        vut: &mut dyn ExternalVehicle,
        mode: ExternalMode,
        cell: usize,
    ) -> Result<(bool, Option<f64>), DriverError> {
        match mode {
            ExternalMode::Step => self.external_step_event_and_criticality(vut, cell),
            ExternalMode::Episode => {
                let outcome = vut.episode(&self.external_scenario(cell))?;
                Ok((outcome.event, outcome.checked_criticality()?))
            }
        }
    }

    /// Whether an external program has the event in scenario `cell`: in
    /// step mode by [`Case::external_step_event`]; in episode mode it is
    /// handed [`Case::external_scenario`] and reports the outcome. The
    /// caller has sent the test's `reset`.
    fn external_event(
        &self,
        vut: &mut dyn ExternalVehicle,
        mode: ExternalMode,
        cell: usize,
    ) -> Result<bool, DriverError> {
        match mode {
            ExternalMode::Step => self.external_step_event(vut, cell),
            ExternalMode::Episode => Ok(vut.episode(&self.external_scenario(cell))?.event),
        }
    }

    /// Scenario `cell` by its axes' names, as episode mode sends it.
    fn external_scenario(&self, cell: usize) -> serde_json::Value {
        let grid = self.grid();
        grid.axes()
            .iter()
            .enumerate()
            .map(|(axis, a)| (a.name().to_owned(), grid.value(cell, axis).into()))
            .collect::<serde_json::Map<_, _>>()
            .into()
    }

    /// One surrogate run at `cell` for library search.
    fn evaluate_surrogate(&self, surrogate: &Self::Vehicle, cell: usize) -> SurrogateEvaluation;

    /// `P(S|x)` alone, for searches that do not need the objective; cases
    /// whose objective is costly override it.
    fn surrogate_challenge(&self, surrogate: &Self::Vehicle, cell: usize) -> f64 {
        self.evaluate_surrogate(surrogate, cell).challenge
    }

    /// [`Case::surrogate_challenge`] for many cells: `challenges[i]` for
    /// `cells[i]`. Cases with a batched simulation override it.
    fn surrogate_challenges(
        &self,
        surrogate: &Self::Vehicle,
        cells: &[usize],
        challenges: &mut [f64],
    ) {
        for (challenge, &cell) in challenges.iter_mut().zip(cells) {
            *challenge = self.surrogate_challenge(surrogate, cell);
        }
    }

    /// The modes an external program can drive this case in, the default
    /// first (the mode a specification that names none gets).
    fn external_modes(&self) -> &'static [ExternalMode] {
        &[ExternalMode::Step, ExternalMode::Episode]
    }

    /// A vehicle this process runs itself for a specification that would
    /// otherwise name an external program (a user-defined case's programs,
    /// run by the caller's [`crate::external::ProgramHost`]); `None`: none.
    fn resolve_vehicle(&self, _spec: &serde_json::Value) -> Option<Self::Vehicle> {
        None
    }

    /// Scenario `cell` as an OpenSCENARIO scene another simulator can
    /// replay ([`crate::openscenario`]); `None` for cases that have none.
    fn openscenario(&self, _cell: usize) -> Option<crate::openscenario::Scene> {
        None
    }

    /// Why a vehicle this process ran failed (a program that crashed, hung
    /// or answered garbage), if one did: what was computed since is void.
    fn failure(&self) -> Option<String> {
        None
    }
}

/// Cells per parallel chunk when `len` cells run in the case's batches
/// ([`Case::events`], [`Case::surrogate_challenges`]): up to 4,096, large
/// enough for the batches, but at least 16 chunks per thread, so that a
/// small grid (a user case's 3,420 cells, each a conversation with a
/// program) still spreads over the threads and reports progress as it
/// goes.
pub(crate) fn parallel_chunk(len: usize) -> usize {
    len.div_ceil(16 * rayon::current_num_threads())
        .clamp(1, 4096)
}
