//! Leases and results: how workers take tests and report outcomes.

use crate::campaign_kind::CampaignStatus;
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
    /// The key's text.
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
    /// The most tests this worker takes in one lease (a slow rig, a load
    /// test); the coordinator's own sizing applies below it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_tests: Option<u64>,
    /// With no work right now, wait up to this many seconds (at most
    /// [`MAX_CLAIM_WAIT_SECONDS`], and the coordinator's
    /// `--max-claim-wait-seconds`) for some before answering 204: a
    /// campaign that starts meanwhile is leased at once, and an idle
    /// worker asks once per wait instead of polling. Absent or 0 answers
    /// at once. Not in a report's `next_lease`, which is answered with the
    /// report.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(minimum = 0.0, maximum = 30.0)]
    pub wait_seconds: Option<f64>,
    /// Only an audit's run (a one-test lease of another worker's test) or
    /// nothing: what a worker of a slow program asks for with its reports
    /// while its lease runs, so that an audit holding a campaign's prefix
    /// runs before its next chunk instead of after its lease.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub audits_only: bool,
    /// Of `offers`, those whose program said in its `hello` that its runs of
    /// one test may differ (`"deterministic": false`). A campaign of the
    /// program without `vehicle_noise` then warns; no audit changes on a
    /// worker's word.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub noisy: Vec<String>,
}

/// The longest a lease request may wait for work (`wait_seconds`), well
/// below the HTTP timeouts of clients and proxies (a minute is common).
pub const MAX_CLAIM_WAIT_SECONDS: f64 = 30.0;

/// An external program a worker has stopped offering: it failed
/// `failures` tests in a row; it is tried again after a rest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct UnhealthyProgram {
    /// The program's name, as the worker offers it.
    pub name: String,
    /// The last failure.
    pub reason: String,
    /// Tests it failed in a row.
    pub failures: u32,
}

/// `GET /api/v1/workers`: the workers seen since the coordinator started.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct WorkerList {
    /// The workers, by name.
    pub workers: Vec<WorkerView>,
    /// What one test of each program costs on one thread, as the
    /// coordinator measured it from reports (kept across campaigns: a
    /// new campaign of the program starts its leases from it).
    #[serde(default)]
    pub costs: Vec<ProgramCost>,
}

/// The measured cost of a program's tests.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ProgramCost {
    /// The program as workers offer it, `NAME:case:mode`.
    pub program: String,
    /// Seconds one test takes on one thread.
    pub seconds_per_test: f64,
}

/// A worker as its lease requests describe it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct WorkerView {
    /// The worker's name, as its credential was issued.
    pub name: String,
    /// Simulation threads it declared in its last lease request.
    pub threads: u32,
    /// Seconds since its last lease request.
    pub last_seen_seconds: f64,
    /// Whether it asked for work within the last minute.
    pub live: bool,
    /// It said it is leaving (a clean stop: `POST
    /// /api/v1/workers/{name}/leave`) and has not asked for work since; the
    /// list drops it ten minutes after it left.
    #[serde(default)]
    pub left: bool,
    /// The external programs it offers (`--vut-exec NAME=…`).
    pub offers: Vec<String>,
    /// Empty when every program it runs is healthy.
    pub unhealthy: Vec<UnhealthyProgram>,
    /// Tests of its reports accepted since the coordinator started.
    #[serde(default)]
    pub tests: u64,
    /// How many of those were invalid.
    #[serde(default)]
    pub invalid: u64,
    /// Why it last gave a lease back unfinished, when it said.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub last_release_reason: Option<String>,
    /// Why it is flagged: it reported what the coordinator's replay or two
    /// other workers contradict. A flagged worker gets no work.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub flagged: Option<String>,
    /// The principal it enrolled under (`POST /api/v1/enrolments`), if any:
    /// audits, quorums and evidence count principals, and a flag sticks to
    /// the principal.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub principal: Option<String>,
    /// When its credential was issued (`POST /api/v1/workers`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub registered_at: Option<String>,
    /// When an operator revoked its credential: it gets no more work.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub revoked_at: Option<String>,
    /// Audit runs it gave back or let expire, in all.
    #[serde(default)]
    pub audits_given_back: u64,
    /// Of those, since it last ran an audit: the share of its own tests
    /// audited doubles with each, and past three all of them are.
    #[serde(default)]
    pub audits_given_back_in_row: u64,
    /// Sampled audits of noisy programs (`vehicle_noise`) it ran with
    /// another worker, flagged partners left out.
    #[serde(default)]
    pub noisy_audits_compared: u64,
    /// Of those, the ones where it found an event and its partner none.
    #[serde(default)]
    pub noisy_own_events: u64,
    /// Of those, the ones where its partner found an event and it none.
    #[serde(default)]
    pub noisy_partner_events: u64,
    /// The evidence that its program behaves unlike the others' (an
    /// e-value, 1 when nothing leans either way); it is flagged at 10⁴
    /// (docs/statistics.md, "Noisy vehicles").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noisy_evidence: Option<f64>,
    /// Its tests paired with other workers' tests of the same campaign and
    /// stratum, flagged partners left out (every test is evidence,
    /// docs/statistics.md, "Every test as evidence").
    #[serde(default)]
    pub test_pairs_compared: u64,
    /// Of those, the pairs where its test found the event and the
    /// partner's none.
    #[serde(default)]
    pub test_own_events: u64,
    /// Of those, the pairs where the partner's test found the event and
    /// its own none.
    #[serde(default)]
    pub test_partner_events: u64,
    /// The evidence from its tests that its program behaves unlike the
    /// others' (an e-value apart from the audits'); it is flagged at 10⁴.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_evidence: Option<f64>,
}

/// One test of a lease.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct TestCase {
    /// The test's index in its campaign.
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
    /// The lease's id.
    pub id: i64,
    /// How often the range has been handed out; the fence of this hand-out.
    pub attempt: i64,
    /// The holder's secret for this attempt (32 hex digits).
    pub key: LeaseKey,
    /// The campaign whose tests the lease covers.
    pub campaign_id: i64,
    /// First test index of the range.
    pub start: u64,
    /// One past the last test index of the range.
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
    /// Seconds one test of the campaign's vehicle takes on one thread, as
    /// the coordinator has measured it (on this campaign, or on earlier
    /// ones of the same program or vehicle); absent while nobody knows.
    /// The worker sizes its first chunk from it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seconds_per_test: Option<f64>,
    /// The test from which nearly every test of the campaign explores
    /// outside its library (the campaign switched: docs/statistics.md, "The
    /// allocation"); the worker draws its tests accordingly. Absent until
    /// the campaign switches.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub explore_from: Option<u64>,
}

/// `POST /api/v1/leases/{id}/heartbeat`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct LeaseFence {
    /// The worker the lease was handed to.
    pub worker: String,
    /// The attempt the worker holds.
    pub attempt: i64,
    /// The lease's `key`, as handed out with this attempt.
    pub key: LeaseKey,
}

/// `POST /api/v1/leases/{id}/release`: the fence, and why the worker
/// gives the rest of the lease back (logged by the coordinator and shown
/// with the worker in `GET /api/v1/workers`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct LeaseRelease {
    /// The worker the lease was handed to.
    pub worker: String,
    /// The attempt the worker holds.
    pub attempt: i64,
    /// The lease's `key`, as handed out with this attempt.
    pub key: LeaseKey,
    /// Why (at most 2000 bytes): shutdown, an unhealthy program, a report
    /// the coordinator refused.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

impl LeaseFence {
    /// A release of the fenced lease, saying `reason`.
    pub fn release(&self, reason: Option<String>) -> LeaseRelease {
        LeaseRelease {
            worker: self.worker.clone(),
            attempt: self.attempt,
            key: self.key.clone(),
            reason,
        }
    }
}

impl LeaseRelease {
    /// The fence part.
    pub fn fence(&self) -> LeaseFence {
        LeaseFence {
            worker: self.worker.clone(),
            attempt: self.attempt,
            key: self.key.clone(),
        }
    }
}

/// The answer to a heartbeat: whether to go on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct HeartbeatAck {
    /// False when the campaign stopped or was cancelled: drop the lease.
    #[serde(rename = "continue")]
    pub proceed: bool,
    /// The campaign's status now.
    pub campaign_status: CampaignStatus,
    /// Seconds the lease now has before it expires.
    pub ttl_seconds: f64,
}

/// A test with the event.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct EventResult {
    /// The test's index in its campaign.
    pub index: u64,
    /// The test's importance weight as the worker computed it; the
    /// coordinator checks it against its own.
    pub weight: f64,
}

/// A test that could not be run (the vehicle or simulator failed).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct InvalidResult {
    /// The test's index in its campaign.
    pub index: u64,
    /// Why it could not be run (at most 2000 bytes).
    pub reason: String,
}

/// Most threads a worker may declare in a lease request (and a report).
pub const MAX_THREADS: u32 = 4096;
/// Most tests one report may cover (`to − from`): a longer range is
/// reported in parts.
pub const MAX_REPORT_TESTS: u64 = 1 << 22;
/// Most events one report may carry (in `events` or `packed_events`): a
/// worker splits a range with more into several reports, so a report stays
/// a few megabytes whatever share of the tests has the event.
pub const MAX_REPORT_EVENTS: usize = 65_536;
/// Most invalid tests one report may carry (each with a reason of up to
/// [`MAX_INVALID_REASON`] bytes).
pub const MAX_REPORT_INVALID: usize = 512;
/// Longest accepted reason of an invalid test, in bytes.
pub const MAX_INVALID_REASON: usize = 2_000;
/// The largest report these limits allow, in bytes of JSON (events as
/// objects of two numbers, invalid tests with their reasons, and the
/// rest): a coordinator's body limit below it refuses valid reports.
pub const MAX_REPORT_BYTES: usize =
    MAX_REPORT_EVENTS * 64 + MAX_REPORT_INVALID * (MAX_INVALID_REASON * 6 + 48) + 4096;

/// `POST /api/v1/leases/{id}/results`: the outcomes of the tests
/// `from..to` of the lease. Listed tests are events or invalid; every
/// other index in the range had no event. Reports continue where the last
/// one ended (`from` ≤ the lease's `resume_at`); a repeated report is
/// acknowledged once. Events come either as `events` or, compactly, as
/// `packed_events` (see [`crate::packed`]), not both; at most
/// [`MAX_REPORT_EVENTS`] of them and [`MAX_REPORT_INVALID`] invalid tests.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ResultReport {
    /// The worker the lease was handed to.
    pub worker: String,
    /// The attempt the worker holds.
    pub attempt: i64,
    /// The lease's `key`, as handed out with this attempt.
    pub key: LeaseKey,
    /// First test index reported (at most the lease's `resume_at`).
    pub from: u64,
    /// One past the last test index reported (at most the lease's `end`).
    pub to: u64,
    /// The events, in increasing index (or `packed_events` instead).
    #[serde(default)]
    pub events: Vec<EventResult>,
    /// The events packed ([`crate::packed`], indices from `from`), in
    /// standard base64; instead of `events`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub packed_events: Option<String>,
    /// The tests that could not be run, in increasing index.
    #[serde(default)]
    pub invalid: Vec<InvalidResult>,
    /// Wall-clock seconds the worker spent on these tests (at most the
    /// time since the lease was handed to it), and on how many threads (at
    /// most those it asked the lease for); used to size later leases.
    #[serde(default)]
    pub compute_seconds: f64,
    /// Threads the tests ran on (1 when absent).
    #[serde(default = "one")]
    pub threads: u32,
    /// Adaptive campaigns: the tests of the range whose criticality was at
    /// most the plan's `near_miss` (events need not be listed), in
    /// increasing index.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub near_misses: Vec<NearMiss>,
    /// Asks for the worker's next lease in the same request (its `worker`
    /// must be the reporting worker): the answer's `next_lease` holds it,
    /// as `POST /api/v1/leases` would have answered. One request instead
    /// of two per lease, as BOINC's scheduler RPC reports results and asks
    /// for work at once; the report is recorded first, and a report that
    /// is refused takes no lease.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub next_lease: Option<LeaseRequest>,
}

/// A test that came close to the event.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct NearMiss {
    /// The test's index.
    pub index: u64,
    /// How close it came, in `[0, 1]` (0 is the event).
    pub criticality: f64,
}

fn one() -> u32 {
    1
}

impl ResultReport {
    /// The report's events however they were sent: the list, or the
    /// packed form decoded.
    pub fn event_list(&self) -> Result<Vec<(u64, f64)>, String> {
        match (&self.packed_events, self.events.is_empty()) {
            (None, _) => Ok(self.events.iter().map(|e| (e.index, e.weight)).collect()),
            (Some(_), false) => {
                Err("a report carries `events` or `packed_events`, not both".into())
            }
            (Some(text), true) => {
                use base64::Engine;
                let bytes = base64::engine::general_purpose::STANDARD
                    .decode(text)
                    .map_err(|e| format!("packed_events is not base64: {e}"))?;
                crate::packed::unpack(self.from, &bytes).map_err(|e| e.to_string())
            }
        }
    }

    /// Sets `packed_events` to `events` (`(index, weight)`, strictly
    /// increasing from `from`) and empties `events`.
    pub fn pack_events(&mut self, events: &[(u64, f64)]) {
        use base64::Engine;
        self.events.clear();
        self.packed_events = Some(
            base64::engine::general_purpose::STANDARD
                .encode(crate::packed::pack(self.from, events)),
        );
    }
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
    /// The campaign's status now.
    pub campaign_status: CampaignStatus,
    /// The next lease, when the report asked for one (`next_lease`) and
    /// there was work; absent otherwise (no work right now, or the lease
    /// could not be taken: the worker asks `POST /api/v1/leases`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub next_lease: Option<Lease>,
}

/// `POST /api/v1/leases/{id}/library`: the library a worker built whole
/// for a campaign of method `build`, or why it could not.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct LibraryUpload {
    /// The worker the lease was handed to.
    pub worker: String,
    /// The attempt the worker holds.
    pub attempt: i64,
    /// The lease's `key`, as handed out with this attempt.
    pub key: LeaseKey,
    /// Seconds the build took on the worker.
    pub seconds: f64,
    /// The library file, base64 (the bytes `GET
    /// /api/v1/libraries/{id}/file` will serve); absent when the build
    /// failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
    /// Why the build failed (at most 2000 bytes): the search found no
    /// failure of the surrogate, the solver did not converge. A failure
    /// fails the library with this reason: the build is deterministic, so
    /// another worker would fail the same way.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failed: Option<String>,
}

impl LibraryUpload {
    /// The fence part.
    pub fn fence(&self) -> LeaseFence {
        LeaseFence {
            worker: self.worker.clone(),
            attempt: self.attempt,
            key: self.key.clone(),
        }
    }

    /// The upload of a build that failed, saying why.
    pub fn of_failure(fence: &LeaseFence, seconds: f64, reason: String) -> Self {
        Self {
            worker: fence.worker.clone(),
            attempt: fence.attempt,
            key: fence.key.clone(),
            seconds,
            file: None,
            failed: Some(reason),
        }
    }

    /// The upload of `file`, base64-encoded.
    pub fn of_file(fence: &LeaseFence, seconds: f64, file: &[u8]) -> Self {
        use base64::Engine;
        Self {
            worker: fence.worker.clone(),
            attempt: fence.attempt,
            key: fence.key.clone(),
            seconds,
            file: Some(base64::engine::general_purpose::STANDARD.encode(file)),
            failed: None,
        }
    }
}
