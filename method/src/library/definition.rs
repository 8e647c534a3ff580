//! What a library is: its cells with their criticality, the threshold γ
//! that chose them, the exposure and grid they index, and how they were
//! found.

use crate::grid::Grid;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// How the threshold γ is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Threshold {
    /// `γ = m μ_S / N(X)` (Part I, Corollary 2; the default is m = 1).
    Relative {
        /// The multiple m of the mean criticality per scenario.
        m: f64,
    },
    /// A fixed γ.
    Absolute {
        /// γ itself, in units of the criticality `V(x) = P(S|x) P(x)`.
        gamma: f64,
    },
}

impl Default for Threshold {
    fn default() -> Self {
        Threshold::Relative { m: 1.0 }
    }
}

/// A threshold parameter outside its range.
#[derive(Debug, Error, PartialEq)]
pub enum ThresholdError {
    /// The multiplier m is outside [1e-6, 1e6].
    #[error("threshold multiplier m = {} must be in [1e-6, 1e6]", crate::number::Num(*.0))]
    BadMultiplier(f64),
    /// The absolute γ is outside [0, 1].
    #[error("absolute threshold γ = {} must be in [0, 1] (a criticality P(S|x) P(x) is at most 1)", crate::number::Num(*.0))]
    BadAbsolute(f64),
}

impl Threshold {
    /// Checks the parameter: `m` in `[10⁻⁶, 10⁶]` (γ from a millionth to a
    /// million times the mean criticality), `γ` in `[0, 1]`.
    pub fn validate(&self) -> Result<(), ThresholdError> {
        match *self {
            Threshold::Relative { m } if !(1e-6..=1e6).contains(&m) => {
                Err(ThresholdError::BadMultiplier(m))
            }
            Threshold::Absolute { gamma } if !(0.0..=1.0).contains(&gamma) => {
                Err(ThresholdError::BadAbsolute(gamma))
            }
            _ => Ok(()),
        }
    }

    /// γ for an SM event rate `mu_s` on a grid of `cells` scenarios.
    pub fn gamma(&self, mu_s: f64, cells: usize) -> f64 {
        match *self {
            Threshold::Relative { m } => m * mu_s / cells as f64,
            Threshold::Absolute { gamma } => gamma,
        }
    }
}

/// The search strategy.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "method", rename_all = "kebab-case", deny_unknown_fields)]
pub enum SearchMethod {
    /// Evaluate the surrogate on every cell with positive exposure.
    Exhaustive,
    /// Local searches of the auxiliary objective from `starts` uniform random
    /// cells, then a flood fill from every critical optimum.
    Multistart {
        /// Random starting cells of the local searches.
        starts: usize,
        /// Seed of the starting cells.
        seed: u64,
    },
}

/// What a search did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SearchReport {
    /// The search that built the library.
    pub method: SearchMethod,
    /// Distinct cells on which the surrogate was simulated.
    pub sm_evaluations: usize,
    /// Share of a reference (exhaustive) library's criticality mass found,
    /// when one was computed.
    pub recall: Option<f64>,
}

/// One library scenario.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LibraryCell {
    /// The cell's index in the case's grid (row-major over the axes).
    pub cell: usize,
    /// `V(x) = P(S|x) P(x)`.
    pub criticality: f64,
}

/// The exposure a library was built on.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExposureRef {
    /// The exposure's name (`builtin` or the table's name).
    pub name: String,
    /// The exposure's fingerprint; campaigns sampling the library must use the same.
    pub fingerprint: String,
}

/// A scenario library. See `docs/library-format.md` for the file format.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Library {
    /// The case the library is for (`cut-in`, `highway-exit`).
    pub case: String,
    /// The case's simulation preset (e.g. `paper-code`).
    pub preset: String,
    /// The surrogate model, as its specification.
    pub surrogate: serde_json::Value,
    /// The exposure `P(x)` the library was built on.
    pub exposure: ExposureRef,
    /// The scenario grid `X` the cells index.
    pub grid: Grid,
    /// How γ was chosen.
    pub threshold: Threshold,
    /// The γ used.
    pub gamma: f64,
    /// `μ_S = Σ_x V(x)` over the evaluated cells (exact for exhaustive, a
    /// lower bound for multistart).
    pub mu_s: f64,
    /// `W = Σ_{x∈Φ} V(x)`.
    pub w: f64,
    /// How the cells were found.
    pub search: SearchReport,
    /// Library cells in increasing cell order.
    pub cells: Vec<LibraryCell>,
}

/// A library request: threshold and search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LibraryRequest {
    /// How γ is chosen.
    pub threshold: Threshold,
    /// How the critical cells are searched.
    pub search: SearchMethod,
}

/// Criticality of every evaluated cell; the raw result of a search.
pub(crate) struct Evaluated {
    /// `(cell, V(x))` for every cell with `V > 0`, any order.
    pub critical: Vec<(usize, f64)>,
    pub sm_evaluations: usize,
}

impl Library {
    /// `N(Φ)`.
    pub fn size(&self) -> usize {
        self.cells.len()
    }

    /// `N(X)`.
    pub fn total_scenarios(&self) -> usize {
        self.grid.len()
    }

    /// The share of `reference`'s criticality mass `W` that this library
    /// contains: `Σ_{x∈Φ∩Φ_ref} V_ref(x) / W_ref`.
    pub fn recall_against(&self, reference: &Library) -> f64 {
        let mine: std::collections::HashSet<usize> = self.cells.iter().map(|c| c.cell).collect();
        let found: f64 = reference
            .cells
            .iter()
            .filter(|c| mine.contains(&c.cell))
            .map(|c| c.criticality)
            .sum();
        found / reference.w
    }
}
