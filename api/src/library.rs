//! Scenario libraries: build requests and their state.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// The exposure model `P(x)` a library is built on.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, ToSchema, Default)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ExposureRequest {
    /// The case's built-in exposure model.
    #[default]
    Builtin,
    /// A table uploaded with the request, in the layout of SPEC §4 (for
    /// cut-in: `range,range_rate,probability` rows, or a matrix).
    Table {
        /// A name for the table (e.g. its file name).
        name: String,
        /// The table's text.
        text: String,
    },
}

/// How the library is searched (grid cases) or learned (car-following).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(tag = "method", rename_all = "kebab-case", deny_unknown_fields)]
pub enum SearchRequest {
    /// Grid cases: simulate the surrogate on every cell with positive exposure.
    Exhaustive,
    /// Grid cases: local searches from `starts` random cells, then a flood
    /// fill (the default, with 50 starts).
    Multistart {
        /// Random starting cells of the local searches.
        #[serde(default = "default_starts")]
        starts: usize,
        /// Seed of the starting cells.
        #[serde(default)]
        seed: u64,
    },
    /// Car-following: Q-values by backward dynamic programming (the default).
    DynamicProgramming,
    /// Car-following: Q-values by the paper's TD(0) with learning rate
    /// `alpha` in (0, 1]; the same fixed point as dynamic programming.
    TemporalDifference {
        /// Learning rate α ∈ (0, 1].
        #[serde(default = "default_alpha")]
        alpha: f64,
        /// Seed of the sampled episodes.
        #[serde(default)]
        seed: u64,
    },
}

fn default_starts() -> usize {
    50
}

fn default_alpha() -> f64 {
    0.1
}

/// The criticality threshold γ.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ThresholdRequest {
    /// `γ = m μ_S / N(X)`.
    Relative {
        /// The multiple m of the mean criticality per scenario.
        m: f64,
    },
    /// A fixed γ.
    Absolute {
        /// γ itself, in units of the criticality `V(x) = P(A|x) P(x)`.
        gamma: f64,
    },
}

/// `POST /api/v1/libraries`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CreateLibrary {
    /// `cut-in`, `highway-exit` or `car-following`.
    pub case: String,
    /// The case's simulation preset; the case's default when absent.
    #[serde(default)]
    pub preset: Option<String>,
    /// The surrogate model, e.g. `{"model": "idm"}` or its name alone
    /// (`"idm"`).
    #[schema(value_type = Object)]
    pub surrogate: serde_json::Value,
    /// The exposure `P(x)` the library is built for (the built-in model when absent).
    #[serde(default)]
    pub exposure: ExposureRequest,
    /// The case's default when absent: multistart (50 starts) for grid
    /// cases, dynamic programming for car-following.
    #[serde(default)]
    pub search: Option<SearchRequest>,
    /// Grid cases only; `relative` with m = 1 when absent.
    #[serde(default)]
    pub threshold: Option<ThresholdRequest>,
}

/// A library's build state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "kebab-case")]
pub enum LibraryStatus {
    /// The search is running.
    Building,
    /// Built: campaigns may sample from it.
    Ready,
    /// The build failed; `error` says why.
    Failed,
}

impl LibraryStatus {
    /// Every status, in the order a build goes through them.
    pub const ALL: [LibraryStatus; 3] = [
        LibraryStatus::Building,
        LibraryStatus::Ready,
        LibraryStatus::Failed,
    ];

    /// The status's name on the wire and in the database.
    pub fn as_str(self) -> &'static str {
        match self {
            LibraryStatus::Building => "building",
            LibraryStatus::Ready => "ready",
            LibraryStatus::Failed => "failed",
        }
    }
}

/// How far a library build has come.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct BuildProgress {
    /// Units of the search done (cells, or starts and flood-fill steps).
    pub done: u64,
    /// Units of the search planned.
    pub total: u64,
}

/// `GET /api/v1/libraries/{id}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct LibraryView {
    /// The library's id.
    pub id: i64,
    /// The case the library is for.
    pub case: String,
    /// The case's simulation preset the surrogate ran with.
    pub preset: String,
    /// Where the build stands.
    pub status: LibraryStatus,
    /// The exposure's name (`builtin` or the table's name).
    pub exposure: String,
    /// The exposure's fingerprint; campaigns must use the same exposure.
    pub exposure_fingerprint: String,
    /// For an uploaded table: how far it lies from the case's built-in model
    /// (total variation distance) and whether its sum was renormalised.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exposure_note: Option<String>,
    /// The surrogate model as given at creation.
    #[schema(value_type = Object)]
    pub surrogate: serde_json::Value,
    /// The surrogate named for people, as a campaign's `vut_label`.
    #[serde(default)]
    pub surrogate_label: String,
    /// `N(Φ)`, once ready.
    pub size: Option<u64>,
    /// `N(X)`, the scenarios of the grid.
    pub total_scenarios: u64,
    /// Surrogate simulations the search used, once ready.
    pub sm_evaluations: Option<u64>,
    /// `μ_S` and `W`, once ready.
    pub mu_s: Option<f64>,
    /// `W = Σ_{x∈Φ} V(x)`, the criticality in the library, once ready.
    pub w: Option<f64>,
    /// Seconds the build took, once done.
    pub build_seconds: Option<f64>,
    /// Why the build failed.
    pub error: Option<String>,
    /// While building on workers (a program as surrogate): what the build
    /// waits for or how far it has come.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub status_detail: Option<String>,
    /// While building: the search's work items done of its total (cells
    /// for exhaustive search, starts for multistart, surrogate transitions
    /// for car-following). Absent while queued behind another build.
    pub progress: Option<BuildProgress>,
    /// RFC 3339 time of the request.
    pub created_at: String,
}
