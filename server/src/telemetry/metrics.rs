//! `/metrics` in the Prometheus text exposition format (version 0.0.4).
//!
//! Request latencies are observed as they happen (a histogram by method,
//! route template and status). Everything about campaigns, leases and
//! libraries is read from the database at scrape time, so the numbers
//! survive a restart and agree with the API: totals over all campaigns are
//! counters (`_total`: they only grow; a deleted campaign's share is kept in
//! `deleted_totals`), the
//! state of things now are gauges.

use crate::error::ServiceError;
use crate::report::replay_counts::{Place, ReplayTotals};
use crate::state::AppState;
use crate::store::error::StoreError;
use crate::store::totals::{self, LeaseTotals, ResultTotals};
use prometheus::{
    Encoder, IntCounter, IntCounterVec, IntGauge, IntGaugeVec, Opts, Registry, TextEncoder,
};
use tslg_api::{CampaignStatus, LibraryStatus};

/// Counts read from the database for one scrape.
#[derive(Default)]
struct Snapshot {
    campaigns: Vec<(CampaignStatus, i64)>,
    libraries: Vec<(LibraryStatus, i64)>,
    results: ResultTotals,
    leases: LeaseTotals,
    /// Group commits since the coordinator started, and the requests
    /// they answered.
    groups: (u64, u64),
    /// Tests library campaigns' folds drew again since it started.
    fold_drawn: u64,
    /// What the replay checks did since it started.
    replays: ReplayTotals,
    /// Lease requests waiting for work now.
    waiting: u64,
}

async fn snapshot(state: &AppState) -> Result<Snapshot, ServiceError> {
    let groups = state.db.group_counts();
    let fold_drawn = state.samplers.explored().drawn();
    let replays = state.replays.totals();
    let waiting = state.work.waiting();
    let mut snapshot = state
        .db
        .read(move |conn| read_snapshot(conn, groups, fold_drawn, replays))
        .await?;
    snapshot.waiting = waiting;
    Ok(snapshot)
}

fn read_snapshot(
    conn: &rusqlite::Connection,
    groups: (u64, u64),
    fold_drawn: u64,
    replays: ReplayTotals,
) -> Result<Snapshot, StoreError> {
    Ok(Snapshot {
        campaigns: totals::campaigns_by_status(conn)?,
        libraries: totals::libraries_by_status(conn)?,
        results: totals::results(conn)?,
        leases: totals::leases(conn, crate::db::now_ms())?,
        groups,
        fold_drawn,
        replays,
        waiting: 0,
    })
}

fn gauge_vec(registry: &Registry, name: &str, help: &str, label: &str) -> IntGaugeVec {
    labelled_gauges(registry, name, help, &[label])
}

fn labelled_gauges(registry: &Registry, name: &str, help: &str, labels: &[&str]) -> IntGaugeVec {
    let gauge = IntGaugeVec::new(Opts::new(name, help), labels).expect("valid gauge");
    registry
        .register(Box::new(gauge.clone()))
        .expect("registered once");
    gauge
}

fn counter(registry: &Registry, name: &str, help: &str, value: i64) {
    let counter = IntCounter::new(name, help).expect("valid counter");
    counter.inc_by(value.max(0) as u64);
    registry
        .register(Box::new(counter))
        .expect("registered once");
}

fn gauge(registry: &Registry, name: &str, help: &str, value: i64) {
    let gauge = IntGauge::new(name, help).expect("valid gauge");
    gauge.set(value);
    registry.register(Box::new(gauge)).expect("registered once");
}

/// The metrics of this moment, as a registry of its own.
fn scrape_registry(s: &Snapshot, live: usize, known: usize) -> Registry {
    let r = Registry::new();
    register_statuses(&r, s);
    register_results(&r, &s.results);
    register_leases(&r, &s.leases);
    gauge(
        &r,
        "tslg_lease_requests_waiting",
        "Lease requests held for work now (wait_seconds): idle workers.",
        s.waiting as i64,
    );
    register_writer(&r, s);
    register_replays(&r, &s.replays);
    let workers = gauge_vec(
        &r,
        "tslg_workers",
        "Workers seen since the coordinator started: live (asked for work within a minute) or stale.",
        "state",
    );
    workers.with_label_values(&["live"]).set(live as i64);
    workers
        .with_label_values(&["stale"])
        .set((known - live) as i64);
    r
}

/// Campaigns and libraries by status (every status, 0 where none is).
fn register_statuses(r: &Registry, s: &Snapshot) {
    let campaigns = gauge_vec(r, "tslg_campaigns", "Campaigns by status.", "status");
    for status in CampaignStatus::ALL {
        let n = s
            .campaigns
            .iter()
            .find(|(k, _)| *k == status)
            .map_or(0, |c| c.1);
        campaigns.with_label_values(&[status.as_str()]).set(n);
    }
    let libraries = gauge_vec(
        r,
        "tslg_libraries",
        "Scenario libraries by status.",
        "status",
    );
    for status in LibraryStatus::ALL {
        let n = s
            .libraries
            .iter()
            .find(|(k, _)| *k == status)
            .map_or(0, |c| c.1);
        libraries.with_label_values(&[status.as_str()]).set(n);
    }
}

/// The tests resolved over all campaigns, their events and invalid tests.
fn register_results(r: &Registry, totals: &ResultTotals) {
    counter(
        r,
        "tslg_tests_resolved_total",
        "Test indices resolved in order over all campaigns (valid and invalid).",
        totals.resolved,
    );
    counter(
        r,
        "tslg_events_total",
        "Tests with the event, over all campaigns.",
        totals.events,
    );
    counter(
        r,
        "tslg_invalid_tests_total",
        "Tests recorded invalid (an external vehicle failed them), over all campaigns.",
        totals.invalid,
    );
}

/// Leases out, expired and handed out again.
fn register_leases(r: &Registry, totals: &LeaseTotals) {
    gauge(
        r,
        "tslg_leases_outstanding",
        "Leases held by workers and not expired.",
        totals.outstanding,
    );
    gauge(
        r,
        "tslg_leases_expired",
        "Leases expired and not yet handed out again.",
        totals.expired,
    );
    counter(
        r,
        "tslg_leases_reclaimed_total",
        "Expired or released leases handed out again.",
        totals.reclaimed,
    );
}

/// The writer's group commits, and the draws folds made again.
fn register_writer(r: &Registry, s: &Snapshot) {
    counter(
        r,
        "tslg_write_groups_total",
        "Transactions that committed the coordinator's writes together, since it started \
         (one fsync each).",
        s.groups.0 as i64,
    );
    counter(
        r,
        "tslg_grouped_writes_total",
        "Writes committed by those transactions (divided by tslg_write_groups_total: the mean \
         group size).",
        s.groups.1 as i64,
    );
    counter(
        r,
        "tslg_fold_drawn_tests_total",
        "Tests whose draws a library campaign's fold made again to find which explored outside \
         the library, since the coordinator started (0 while its own runs of the reports cover \
         them).",
        s.fold_drawn as i64,
    );
}

/// What the replay checks did since the coordinator started.
fn register_replays(r: &Registry, replays: &ReplayTotals) {
    let checks = IntCounterVec::new(
        Opts::new(
            "tslg_replay_checks_total",
            "Reports on built-in vehicles the coordinator checked by running tests again, since \
             it started, by where the check ran: on the writer in the report's transaction, on \
             the request's task, or on the blocking pool.",
        ),
        &["place"],
    )
    .expect("valid counter");
    r.register(Box::new(checks.clone()))
        .expect("registered once");
    for (place, n) in Place::ALL.iter().zip(replays.reports) {
        checks.with_label_values(&[place.label()]).inc_by(n);
    }
    counter(
        r,
        "tslg_replay_sample_range_tests_total",
        "Tests of the checked reports whose quiet tests were sampled, since the coordinator \
         started (the tests the secret sample was drawn from).",
        replays.sample_range as i64,
    );
    counter(
        r,
        "tslg_replay_sampled_tests_total",
        "Tests the secret sample chose to run again (divided by \
         tslg_replay_sample_range_tests_total: the replay share).",
        replays.sampled as i64,
    );
}

/// The metrics of this moment in the Prometheus text exposition format:
/// the observed request latencies, totals read from the store, and one
/// set of series per running campaign.
pub async fn exposition(state: &AppState) -> Result<Vec<u8>, ServiceError> {
    let snapshot = snapshot(state).await?;
    let (live, known) = state.workers.counts();
    let running = state
        .db
        .read(|conn| crate::store::campaigns::list(conn, Some(CampaignStatus::Running)))
        .await?;
    let views: Vec<_> = running
        .iter()
        .take(crate::telemetry::campaign_metrics::MAX_CAMPAIGN_SERIES)
        .map(|row| {
            let mut view = crate::campaign::views::campaign_view(row);
            state.throughput.fill(&mut view, None);
            view
        })
        .collect();
    let registry = scrape_registry(&snapshot, live, known);
    let queue = crate::queue::of_rows(
        &running,
        &state.workers.fleet(),
        state.config.queue_target_seconds,
        None,
    );
    let wanted = labelled_gauges(
        &registry,
        "tslg_workers_wanted",
        "Workers that would finish the running campaigns' predicted work within \
         --queue-target-seconds, per program (NAME:case:mode; builtin: the built-in vehicles) \
         and its vehicle (the program's NAME, a valid Kubernetes label value for an HPA's \
         selector); 0 when idle (GET /api/v1/queue).",
        &["program", "vehicle"],
    );
    for d in &queue.programs {
        let vehicle = d.program.split(':').next().unwrap_or(&d.program);
        wanted
            .with_label_values(&[d.program.as_str(), vehicle])
            .set(i64::from(d.workers_wanted));
    }
    // The total, always present (0 when idle, when the per-program gauge
    // has no series): what one HorizontalPodAutoscaler of all workers reads.
    gauge(
        &registry,
        "tslg_fleet_workers_wanted",
        "Workers wanted over all programs (GET /api/v1/queue's workers_wanted): the programs' \
         work adds up, the workers kept for campaigns not yet sized are counted once.",
        i64::from(queue.workers_wanted),
    );
    // Every running campaign counts toward the omitted ones; only the
    // newest have views built.
    crate::telemetry::campaign_metrics::register(&registry, &views, running.len());
    let mut families = state.metrics.gather();
    families.extend(registry.gather());
    let mut body = Vec::new();
    TextEncoder::new()
        .encode(&families, &mut body)
        .map_err(|e| ServiceError::Internal(e.into()))?;
    Ok(body)
}
