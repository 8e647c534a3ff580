//! `GET /api/v1/campaigns/{id}/timeline`: where a campaign's wall time
//! went, read from when each piece of its work was leased and reported
//! (`tslg campaign timeline N`, docs/operations.md "Where the time goes").

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// A campaign's work over time, in buckets of equal length from its first
/// lease to its last report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct CampaignTimeline {
    /// The campaign.
    pub campaign_id: i64,
    /// Seconds from its first lease to its last report (0 before any
    /// report).
    pub seconds: f64,
    /// Workers that ran any of its tests or audit runs.
    pub workers: u32,
    /// Worker-seconds between each piece of work's lease (or its lease's
    /// previous report) and its report: tests and audit runs.
    pub busy_worker_seconds: f64,
    /// The part of them spent on audit runs.
    pub audit_worker_seconds: f64,
    /// `busy_worker_seconds / (workers × seconds)`: the share of the time
    /// its workers held its work (0 before any report). A worker of the
    /// fleet that never got any of it does not count: compare `workers`
    /// with the fleet's size.
    pub busy_share: f64,
    /// Test and audit runs reported.
    pub reports: u64,
    /// The buckets, in time order.
    pub buckets: Vec<TimelineBucket>,
}

/// One slice of a campaign's time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct TimelineBucket {
    /// Its start, seconds after the campaign's first lease.
    pub from_seconds: f64,
    /// Its end.
    pub to_seconds: f64,
    /// Workers holding the campaign's work, on average over the bucket
    /// (audit runs included).
    pub busy_workers: f64,
    /// Of them, on audit runs.
    pub audit_workers: f64,
    /// Tests reported in it (audit runs not counted).
    pub reported_tests: u64,
    /// The resolved prefix at its end: indices the estimate had folded.
    pub folded: u64,
}
