//! `GET /api/v1/campaigns/{id}/stages`: an adaptive campaign's resolved
//! stages, which its page and `tslg campaign report` draw.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// One resolved stage of an adaptive campaign.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct AdaptiveStage {
    /// `library`, `search` or `estimate`.
    pub kind: String,
    /// Its first test index among all the campaign's tests.
    pub start: u64,
    /// One past its last test used (where the rule stopped the campaign,
    /// when it stopped inside this stage).
    pub end: u64,
    /// Its tests where the vehicle had the event.
    pub events: u64,
    /// Scenarios its tests found failing for the first time (0 for the
    /// stage where the campaign stopped: it plans nothing more).
    pub new_failures: u64,
    /// Its tests without a valid outcome.
    pub invalid: u64,
    /// Cells the next estimation stage samples besides its exploring share
    /// (the failures found and the library's cells untested), after it.
    pub support: u64,
    /// A guarded campaign's estimate starts again after this stage, with
    /// the stages that explore the guard's share: the estimate, its
    /// events and its history are those of the stages after it.
    #[serde(default)]
    pub restarts_estimate: bool,
}

/// `GET /api/v1/campaigns/{id}/stages`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct AdaptiveStages {
    /// The campaign the stages belong to.
    pub campaign_id: i64,
    /// Its resolved stages in test order; empty for a campaign that is not
    /// adaptive, and missing the stages a coordinator before this list
    /// resolved.
    pub stages: Vec<AdaptiveStage>,
}
