//! `GET /api/v1/queue`: the work the running campaigns still want, per
//! program, and the workers that would do it in time: what an autoscaler
//! (KEDA's `metrics-api` scaler, a HorizontalPodAutoscaler on the
//! Prometheus gauge `tslg_workers_wanted`, a SLURM submission loop) reads.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// `GET /api/v1/queue`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct QueueView {
    /// The time the wanted workers would finish the predicted work in
    /// (`--queue-target-seconds`).
    pub target_seconds: f64,
    /// The workers of a fleet that runs every program listed (built-in
    /// vehicles included): the programs' work adds up, and the workers
    /// kept for campaigns not yet sized count once (they serve them all),
    /// so it is at least each program's `workers_wanted` and at most their
    /// sum.
    pub workers_wanted: u32,
    /// One entry per program with running campaigns, and per program a
    /// live worker offers (wanting 0 when it has no work).
    pub programs: Vec<ProgramDemand>,
}

/// The demand for one program (`NAME:case:mode`), or for the built-in
/// vehicles (`builtin`, which every worker runs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ProgramDemand {
    /// `NAME:case:mode`, or `builtin`.
    pub program: String,
    /// Its running campaigns.
    pub campaigns: u32,
    /// The tests its running campaigns are still predicted to need; a
    /// campaign without a prediction yet counts the fewest it still needs
    /// (as many again as it has run, its `n_min`, or its way to
    /// `min_events` at its event rate, whichever is most).
    pub tests_needed: u64,
    /// Those tests' cost in worker-thread seconds, from the measured cost
    /// per test; absent while no campaign of it has a measured cost.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub worker_seconds: Option<f64>,
    /// Running campaigns without a prediction yet (too few tests or
    /// events, or no cost measured): each wants at least the workers
    /// serving it now, or one.
    pub unpredicted: u32,
    /// Live workers offering it (all live workers for `builtin`).
    pub workers: u32,
    /// Their threads.
    pub threads: u32,
    /// The workers that would finish the predicted work within
    /// `target_seconds`: `⌈worker_seconds / (target · threads per
    /// worker)⌉`, at least 1 while a campaign has work, and 0 when none
    /// has.
    pub workers_wanted: u32,
}
