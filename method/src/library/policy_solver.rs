//! How a policy library's Q-values are learned (the car-following case,
//! `crate::cases::carfollow`): named here, beside the grid cases' search
//! methods, so a build request can name either without knowing the case.

use serde::{Deserialize, Serialize};

/// How the Q-values are computed (SPEC §6): both reach the same fixed point.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "method", rename_all = "kebab-case", deny_unknown_fields)]
pub enum PolicySolver {
    /// Backward dynamic programming to a largest change below 10⁻¹³.
    DynamicProgramming,
    /// The paper's TD(0) with learning rate `alpha`, until every `|δ|` of a
    /// sweep is below 10⁻¹⁰.
    TemporalDifference {
        /// Learning rate α ∈ [10⁻³, 1].
        alpha: f64,
        /// Seed of the sampled episodes.
        seed: u64,
    },
}

impl PolicySolver {
    /// Checks the solver's parameters (α in [10⁻³, 1]).
    pub fn validate(&self) -> Result<(), String> {
        match *self {
            // Below 10⁻³ the TD iteration would need thousands of sweeps
            // per digit of its tolerance.
            PolicySolver::TemporalDifference { alpha, .. } if !(1e-3..=1.0).contains(&alpha) => {
                Err(format!(
                    "TD learning rate alpha = {} must be in [0.001, 1]",
                    crate::number::Num(alpha)
                ))
            }
            _ => Ok(()),
        }
    }
}
