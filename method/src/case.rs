//! What a case is: a scenario grid with an exposure model, and a simulation
//! that yields an outcome for a vehicle model. Library search, sampling,
//! estimation and exact answers are written against this trait only.

use crate::grid::Grid;
use crate::mass::GridMass;

/// One surrogate-model run at a scenario, as library search needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurrogateEvaluation {
    /// Maneuver challenge `P(S|x)` (0 or 1 for a deterministic surrogate).
    pub challenge: f64,
    /// Auxiliary objective `J(x)`: smaller is more critical.
    pub objective: f64,
}

pub trait Case: Sync {
    /// The vehicle models this case can simulate.
    type Vehicle: Sync;

    /// The case's name on the command line and in files (`cut-in`, …).
    fn name(&self) -> &'static str;

    /// The exposure `P(x)` on the case's grid.
    fn exposure(&self) -> &GridMass;

    /// A short name for the exposure (`builtin`, or the table's file name).
    fn exposure_name(&self) -> &str;

    fn grid(&self) -> &Grid {
        self.exposure().grid()
    }

    /// Whether `vehicle` has the event `A` in scenario `cell`. Vehicles are
    /// deterministic, so `P(A|x)` is this as 0 or 1.
    fn is_event(&self, vehicle: &Self::Vehicle, cell: usize) -> bool;

    /// One surrogate run at `cell` for library search.
    fn evaluate_surrogate(&self, surrogate: &Self::Vehicle, cell: usize) -> SurrogateEvaluation;

    /// `P(S|x)` alone, for searches that do not need the objective; cases
    /// whose objective is costly override it.
    fn surrogate_challenge(&self, surrogate: &Self::Vehicle, cell: usize) -> f64 {
        self.evaluate_surrogate(surrogate, cell).challenge
    }
}
