//! What kind of campaign besides its method (api/src/method.rs): how an
//! adaptive one searches, how tests are split and spread outside the
//! library, the interval it reads, and the states it goes through.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// How an adaptive campaign searches around the failures and near misses
/// it meets (docs/adaptive-design.md, "Fine grids").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "kebab-case")]
pub enum AdaptiveSearch {
    /// Every untested neighbour of a seed is tested once: the search costs
    /// the failure region's volume in cells, and finds every connected
    /// failure it touches.
    #[default]
    Grid,
    /// The search walks the grid's coarser lattice (every s-th index, `s`
    /// the smallest power of two leaving at most 16,384 points) and a seed
    /// puts its whole block in the support untested: the cost is the
    /// region's volume in blocks. It rests on every failing region holding
    /// failing or near-miss lattice points, which fails for failures in
    /// thin sheets between them. On a grid that small it is the grid
    /// search.
    Lattice,
}

impl AdaptiveSearch {
    /// Every search.
    pub const ALL: [AdaptiveSearch; 2] = [AdaptiveSearch::Grid, AdaptiveSearch::Lattice];

    /// Its name on the wire (`grid`, `lattice`).
    pub fn as_str(self) -> &'static str {
        match self {
            AdaptiveSearch::Grid => "grid",
            AdaptiveSearch::Lattice => "lattice",
        }
    }

    /// The search named `name`, if one is.
    pub fn parse(name: &str) -> Option<Self> {
        AdaptiveSearch::ALL.into_iter().find(|s| s.as_str() == name)
    }
}

/// How a library campaign of a grid case splits its tests between the
/// library and the scenarios outside it (docs/statistics.md, "Strata").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Split {
    /// Test `i` explores exactly when `⌊(i + 1)ε⌋ > ⌊iε⌋`, and the estimate
    /// weights the two strata by their shares `1 − ε` and `ε`: no noise from
    /// how many tests happened to explore.
    Stratified,
    /// Each test explores with probability ε, as in the paper. The default
    /// of a plan that does not say (campaigns created before the
    /// stratified split).
    #[default]
    Random,
}

impl Split {
    /// The split's name on the wire (`stratified`, `random`).
    pub fn as_str(self) -> &'static str {
        match self {
            Split::Stratified => "stratified",
            Split::Random => "random",
        }
    }
}

/// How a library campaign spreads its exploration share ε outside the library.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Outside {
    /// `q(x) = ε / (N(X) − N(Φ))`, the paper's form (car-following: ε
    /// uniform over the states and over the 31 actions).
    #[default]
    Uniform,
    /// `q(x) = ε P(x) / P(X \ Φ)`: weights outside the library stay below
    /// `P(X \ Φ)/ε`, so a vehicle that fails outside the library costs tests
    /// but never an unbounded weight.
    Ndd,
}

impl Outside {
    /// The spread's name on the wire (`uniform`, `ndd`).
    pub fn as_str(self) -> &'static str {
        match self {
            Outside::Uniform => "uniform",
            Outside::Ndd => "ndd",
        }
    }
}

/// The interval a campaign stops on and reports (docs/statistics.md,
/// "What each interval promises").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "kebab-case")]
pub enum IntervalKind {
    /// The normal interval `μ̂ ± z σ̂/√n`: valid at the campaign's stop,
    /// not when acted on along the way.
    #[default]
    Wald,
    /// A confidence sequence: it holds at every number of tests at once,
    /// so watching, stopping early, extending and gating at any time keep
    /// its promise (about three times the tests). Library and NDD
    /// campaigns of grid cases.
    Anytime,
}

impl IntervalKind {
    /// The interval's name on the wire (`wald`, `anytime`).
    pub fn as_str(self) -> &'static str {
        match self {
            IntervalKind::Wald => "wald",
            IntervalKind::Anytime => "anytime",
        }
    }
}

/// A campaign's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "kebab-case")]
pub enum CampaignStatus {
    /// Waiting for its library to finish building.
    Pending,
    /// Handing out tests and folding results until the stopping rule holds.
    Running,
    /// Stopped by the rule: relative half-width ≤ β.
    Converged,
    /// Stopped at `max_tests` without the precision asked for.
    Exhausted,
    /// Stopped by a user; the estimate is that of the resolved prefix.
    Cancelled,
    /// Could not run (e.g. its library failed to build).
    Failed,
}

impl CampaignStatus {
    /// Every status, in the order a campaign goes through them.
    pub const ALL: [CampaignStatus; 6] = [
        CampaignStatus::Pending,
        CampaignStatus::Running,
        CampaignStatus::Converged,
        CampaignStatus::Exhausted,
        CampaignStatus::Cancelled,
        CampaignStatus::Failed,
    ];

    /// The status's name on the wire and in the database.
    pub fn as_str(self) -> &'static str {
        match self {
            CampaignStatus::Pending => "pending",
            CampaignStatus::Running => "running",
            CampaignStatus::Converged => "converged",
            CampaignStatus::Exhausted => "exhausted",
            CampaignStatus::Cancelled => "cancelled",
            CampaignStatus::Failed => "failed",
        }
    }

    /// The status named `s`, if it is one.
    pub fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "pending" => CampaignStatus::Pending,
            "running" => CampaignStatus::Running,
            "converged" => CampaignStatus::Converged,
            "exhausted" => CampaignStatus::Exhausted,
            "cancelled" => CampaignStatus::Cancelled,
            "failed" => CampaignStatus::Failed,
            _ => return None,
        })
    }

    /// Whether the campaign has stopped for good.
    pub fn is_final(self) -> bool {
        !matches!(self, CampaignStatus::Pending | CampaignStatus::Running)
    }
}
