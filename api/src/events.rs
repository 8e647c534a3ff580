//! A campaign's events as they leave the service: `GET
//! /api/v1/campaigns/{id}/events`, paged by test index.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use utoipa::ToSchema;

/// The most events one page holds.
pub const MAX_EVENTS_PAGE: usize = 10_000;
/// The events a page holds when the request does not say.
pub const DEFAULT_EVENTS_PAGE: usize = 1_000;

/// One test with the event, in the campaign's resolved prefix (the tests
/// its estimate counts).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct CampaignEvent {
    /// The test's index: with the campaign's seed it reproduces the test.
    pub test_index: u64,
    /// The importance weight `P(x)/q(x)` the test entered the estimate with.
    pub weight: f64,
    /// The scenario's grid cell (grid cases).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cell: Option<u64>,
    /// The scenario's parameters by dimension name (grid cases; the order
    /// of the page's `dimensions`). Absent for sequential cases, whose
    /// scenario is drawn decision by decision while the test runs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scenario: Option<BTreeMap<String, f64>>,
    /// The criticality `V(x) = P(S|x) P(x)` the library's surrogate gave
    /// the scenario, for a campaign sampling from a library that holds it;
    /// absent otherwise (NDD campaigns, scenarios outside the library: the
    /// tests the surrogate did not foresee).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub criticality: Option<f64>,
}

/// `GET /api/v1/campaigns/{id}/events?after=&limit=`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct EventPage {
    /// The campaign.
    pub campaign_id: i64,
    /// Its case.
    pub case: String,
    /// The scenario's dimensions, in the case's order (empty for
    /// sequential cases).
    pub dimensions: Vec<String>,
    /// Test indices below this are resolved: the events listed are there.
    pub resolved: u64,
    /// The events after the requested index, in increasing test index.
    pub events: Vec<CampaignEvent>,
    /// `after` for the next page; absent on the last page.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub next_after: Option<u64>,
}
