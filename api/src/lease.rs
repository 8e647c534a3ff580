//! Leases and results: how workers take tests and report outcomes.

use crate::campaign::CampaignStatus;
use serde::{Deserialize, Serialize};
use std::fmt;
use utoipa::ToSchema;

/// A lease attempt's secret key (32 hex digits). Its `Debug` hides the
/// value, so a lease, fence or report that ends up in a log or a panic
/// message does not carry it.
#[derive(Clone, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(transparent)]
pub struct LeaseKey(pub String);

impl LeaseKey {
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl fmt::Debug for LeaseKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("LeaseKey(…)")
    }
}

/// `POST /api/v1/leases`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct LeaseRequest {
    /// The worker's name, unique among live workers.
    pub worker: String,
    /// Threads the worker runs tests on; leases are sized for them.
    pub threads: u32,
    /// Include each test's scenario and weight in the lease (for clients
    /// that cannot sample them from the plan); limits the lease size.
    #[serde(default)]
    pub include_tests: bool,
    /// The external vehicles this worker runs, as `NAME:case:mode` (from
    /// each program's handshake). Campaigns of an external vehicle are
    /// leased only to workers offering it; built-in vehicles to any.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub offers: Vec<String>,
    /// Programs this worker stopped running after repeated failures.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unhealthy: Vec<UnhealthyProgram>,
}

/// An external program a worker has stopped offering: it failed
/// `failures` tests in a row; it is tried again after a rest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct UnhealthyProgram {
    pub name: String,
    /// The last failure.
    pub reason: String,
    pub failures: u32,
}

/// `GET /api/v1/workers`: the workers seen since the coordinator started.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct WorkerList {
    pub workers: Vec<WorkerView>,
}

/// A worker as its lease requests describe it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct WorkerView {
    pub name: String,
    pub threads: u32,
    /// Seconds since its last lease request.
    pub last_seen_seconds: f64,
    /// Whether it asked for work within the last minute.
    pub live: bool,
    pub offers: Vec<String>,
    /// Empty when every program it runs is healthy.
    pub unhealthy: Vec<UnhealthyProgram>,
    /// Tests of its reports accepted since the coordinator started.
    #[serde(default)]
    pub tests: u64,
    /// How many of those were invalid.
    #[serde(default)]
    pub invalid: u64,
}

/// One test of a lease.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct TestCase {
    pub index: u64,
    /// The scenario's grid cell.
    pub cell: u64,
    /// The scenario's parameters (for cut-in: range, range rate).
    pub scenario: Vec<f64>,
    /// Importance weight `P(x)/q(x)`.
    pub weight: f64,
}

/// A contiguous range `start..end` of test indices of one campaign, held
/// by one worker until it expires. `attempt` counts how often the range
/// was handed out; heartbeats and results must name it together with
/// `key`, a secret drawn for this attempt, so only the worker the lease was
/// handed to can report on it (every worker shares the worker token).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Lease {
    pub id: i64,
    pub attempt: i64,
    /// The holder's secret for this attempt (32 hex digits).
    pub key: LeaseKey,
    pub campaign_id: i64,
    pub start: u64,
    pub end: u64,
    /// The first index not yet reported; results continue from here.
    pub resume_at: u64,
    /// Seconds until the lease expires without a heartbeat or result.
    pub ttl_seconds: f64,
    /// How often to heartbeat while working on it.
    pub heartbeat_seconds: f64,
    /// Present when asked for with `include_tests`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tests: Option<Vec<TestCase>>,
}

/// `POST /api/v1/leases/{id}/heartbeat` and `/release`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct LeaseFence {
    pub worker: String,
    pub attempt: i64,
    /// The lease's `key`, as handed out with this attempt.
    pub key: LeaseKey,
}

/// The answer to a heartbeat: whether to go on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct HeartbeatAck {
    /// False when the campaign stopped or was cancelled: drop the lease.
    #[serde(rename = "continue")]
    pub proceed: bool,
    pub campaign_status: CampaignStatus,
    pub ttl_seconds: f64,
}

/// A test with the event.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct EventResult {
    pub index: u64,
    /// The test's importance weight as the worker computed it; the
    /// coordinator checks it against its own.
    pub weight: f64,
}

/// A test that could not be run (the vehicle or simulator failed).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct InvalidResult {
    pub index: u64,
    pub reason: String,
}

/// `POST /api/v1/leases/{id}/results`: the outcomes of the tests
/// `from..to` of the lease. Listed tests are events or invalid; every
/// other index in the range had no event. Reports continue where the last
/// one ended (`from` ≤ the lease's `resume_at`); a repeated report is
/// acknowledged once.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ResultReport {
    pub worker: String,
    pub attempt: i64,
    /// The lease's `key`, as handed out with this attempt.
    pub key: LeaseKey,
    pub from: u64,
    pub to: u64,
    #[serde(default)]
    pub events: Vec<EventResult>,
    #[serde(default)]
    pub invalid: Vec<InvalidResult>,
    /// Wall-clock seconds the worker spent on these tests, and on how many
    /// threads; used to size later leases.
    #[serde(default)]
    pub compute_seconds: f64,
    #[serde(default = "one")]
    pub threads: u32,
}

fn one() -> u32 {
    1
}

/// The answer to a result report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ResultAck {
    /// Tests newly recorded by this report.
    pub accepted: u64,
    /// Tests of this report already recorded with the same outcome.
    pub duplicate: u64,
    /// Tests ignored because the campaign had already stopped.
    pub ignored: u64,
    /// The lease's next index to report.
    pub resume_at: u64,
    /// Whether the lease is fully reported.
    pub lease_done: bool,
    /// False when the campaign stopped: drop the rest of the lease.
    #[serde(rename = "continue")]
    pub proceed: bool,
    pub campaign_status: CampaignStatus,
}
