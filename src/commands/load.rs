//! `tslg load-test`: many simulated workers against one coordinator.
//!
//! It starts an NDD campaign that cannot converge within the test (cut-in,
//! IDM, the smallest β a campaign takes) and runs `--workers` concurrent
//! simulated workers, each making `--requests` rounds of: take a lease of
//! at most `--lease-tests` tests (a worker's own cap, so a coordinator with
//! adaptive lease sizes hands out what one round can run at once), run its
//! tests for real (a fraction of a microsecond each), report them all. It times
//! every lease and result request, then cancels the campaign, whatever
//! happened (also on a failure, a timeout or Ctrl-C: a campaign left running
//! would keep real workers busy), and checks the books: the tests the
//! coordinator acknowledged as new must be exactly its resolved prefix, and
//! the events reported exactly its events, so no test was lost or counted
//! twice. It also reports how many requests the coordinator committed per
//! transaction meanwhile (group commit, from `/metrics`). It fails (exit 1)
//! on any refused or failed request or a mismatch, and refuses to start on
//! a coordinator that live workers serve (they would take its leases).

use crate::args::ServerArgs;
use crate::commands::remote::client;
use clap::Args;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tslg_api::{CreateCampaign, LeaseRequest, Method, ResultReport};
use tslg_client::Client;
use tslg_method::estimator::{DEFAULT_N_MIN, MIN_BETA};
use tslg_worker::prepared::{Cache, PreparedCampaign};

#[derive(Debug, Args)]
pub struct LoadArgs {
    #[command(flatten)]
    pub server: ServerArgs,
    /// The worker token, when the coordinator has one.
    #[arg(long, env = "TSLG_WORKER_TOKEN", hide_env_values = true)]
    pub worker_token: Option<String>,
    /// Concurrent simulated workers.
    #[arg(long, default_value_t = 64)]
    pub workers: usize,
    /// Lease-and-report rounds per worker.
    #[arg(long, default_value_t = 50)]
    pub requests: usize,
    /// The most tests a simulated worker takes per lease (the coordinator
    /// may give fewer: `--lease-size`, the campaign's budget).
    #[arg(long, default_value_t = 100)]
    pub lease_tests: u64,
    /// Take every lease with its own request (`POST /api/v1/leases`), as
    /// coordinators before the combined request did; by default a report
    /// asks for the next lease (`next_lease`), so a round is one request.
    #[arg(long)]
    pub separate_claims: bool,
    /// Give up (exit 1) after this many seconds.
    #[arg(long, default_value_t = 300.0, allow_negative_numbers = true)]
    pub time_limit: f64,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
}

/// What one simulated worker saw.
#[derive(Default)]
struct WorkerLog {
    lease_ms: Vec<f64>,
    result_ms: Vec<f64>,
    accepted: u64,
    events: u64,
    errors: Vec<String>,
}

/// The measured latencies and the books of one run.
#[derive(Debug, serde::Serialize)]
pub struct LoadReport {
    pub campaign_id: i64,
    pub workers: usize,
    pub requests: usize,
    pub seconds: f64,
    /// Whether each lease was taken with its own request.
    pub separate_claims: bool,
    /// Rounds (a lease taken and reported) per second.
    pub round_trips_per_second: f64,
    pub lease_ms: Percentiles,
    pub result_ms: Percentiles,
    pub errors: Vec<String>,
    pub accepted_tests: u64,
    pub campaign_tests: u64,
    pub reported_events: u64,
    pub campaign_events: u64,
    /// The coordinator's group commits during the run (from `/metrics`,
    /// so they include any other traffic it had); `None` when `/metrics`
    /// could not be read.
    pub commits: Option<GroupCommits>,
}

/// Transactions that committed leases and reports, and the requests they
/// committed: their ratio is the mean group size (group commit).
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct GroupCommits {
    pub transactions: u64,
    pub requests: u64,
}

impl GroupCommits {
    /// The coordinator's counters in a `/metrics` text.
    fn scraped(metrics: &str) -> Option<Self> {
        let counter = |name: &str| -> Option<u64> {
            metrics
                .lines()
                .find_map(|l| l.strip_prefix(name)?.strip_prefix(' '))?
                .trim()
                .parse::<f64>()
                .ok()
                .map(|v| v as u64)
        };
        Some(Self {
            transactions: counter("tslg_write_groups_total")?,
            requests: counter("tslg_grouped_writes_total")?,
        })
    }

    /// What happened between two readings.
    fn since(self, before: Self) -> Self {
        Self {
            transactions: self.transactions.saturating_sub(before.transactions),
            requests: self.requests.saturating_sub(before.requests),
        }
    }
}

/// The coordinator's group-commit counters now, when `/metrics` answers.
async fn group_commits(admin: &Client) -> Option<GroupCommits> {
    GroupCommits::scraped(&admin.metrics().await.ok()?)
}

/// Nearest-rank percentiles of a sample, in milliseconds.
#[derive(Debug, serde::Serialize)]
pub struct Percentiles {
    pub count: usize,
    pub p50: f64,
    pub p90: f64,
    pub p99: f64,
    pub max: f64,
}

impl Percentiles {
    fn of(mut sample: Vec<f64>) -> Self {
        sample.sort_by(f64::total_cmp);
        let rank = |p: f64| {
            if sample.is_empty() {
                return f64::NAN;
            }
            let k = ((p * sample.len() as f64).ceil() as usize).clamp(1, sample.len());
            sample[k - 1]
        };
        Self {
            count: sample.len(),
            p50: rank(0.5),
            p90: rank(0.9),
            p99: rank(0.99),
            max: rank(1.0),
        }
    }
}

impl LoadReport {
    /// Whether the books balance and nothing failed.
    pub fn clean(&self) -> bool {
        self.errors.is_empty()
            && self.accepted_tests == self.campaign_tests
            && self.reported_events == self.campaign_events
    }
}

pub fn run(args: &LoadArgs) -> anyhow::Result<()> {
    anyhow::ensure!(args.workers >= 1, "--workers must be at least 1");
    anyhow::ensure!(args.requests >= 1, "--requests must be at least 1");
    anyhow::ensure!(
        (1..=MAX_LEASE_TESTS).contains(&args.lease_tests),
        "--lease-tests must be in 1..={MAX_LEASE_TESTS}"
    );
    anyhow::ensure!(
        args.time_limit.is_finite() && args.time_limit > 0.0 && args.time_limit <= 86_400.0,
        "--time-limit must be in (0, 86400] seconds"
    );
    let admin = client(&args.server)?;
    let worker = client(&ServerArgs {
        server: args.server.server.clone(),
        token: args.worker_token.clone(),
    })?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let limit = Duration::from_secs_f64(args.time_limit);
    let shape = Shape {
        workers: args.workers,
        requests: args.requests,
        lease_tests: args.lease_tests,
        separate_claims: args.separate_claims,
    };
    let report = runtime.block_on(async {
        refuse_live_workers(&admin).await?;
        let commits_before = group_commits(&admin).await;
        let campaign = admin.create_campaign(&load_campaign(&shape)).await?;
        let outcome = tokio::select! {
            run = tokio::time::timeout(limit, load(&worker, campaign.id, shape)) => match run {
                Ok(run) => run,
                Err(_) => Err(anyhow::anyhow!("the load test did not finish within {limit:?}")),
            },
            _ = tokio::signal::ctrl_c() => Err(anyhow::anyhow!("interrupted")),
        };
        // Cancelled whatever happened: a campaign that cannot converge would
        // keep every real worker busy.
        let cancelled = admin.cancel_campaign(campaign.id).await;
        let mut report =
            outcome.map_err(|e| anyhow::anyhow!("{e}; campaign {} was cancelled", campaign.id))?;
        let view = cancelled.map_err(|e| {
            anyhow::anyhow!(
                "cannot cancel the load test's campaign {}: {e}",
                campaign.id
            )
        })?;
        report.campaign_tests = view.indices;
        report.campaign_events = view.events;
        report.commits = match (commits_before, group_commits(&admin).await) {
            (Some(before), Some(after)) => Some(after.since(before)),
            _ => None,
        };
        anyhow::Ok(report)
    })?;
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_table(&report);
    }
    anyhow::ensure!(
        report.clean(),
        "the load test found errors or unbalanced books ({} errors{})",
        report.errors.len(),
        if report.errors.is_empty() {
            "; a worker that joined during the run takes leases of its campaign too"
        } else {
            ""
        }
    );
    Ok(())
}

/// Refuses to load a coordinator that live workers serve: they would take
/// leases of the load test's campaign, and the books, which count only the
/// simulated workers' tests, could not balance. (The simulated workers of
/// an earlier run, `load-N`, stay listed for a minute; they do not count.)
async fn refuse_live_workers(admin: &Client) -> anyhow::Result<()> {
    let live: Vec<String> = admin
        .workers()
        .await?
        .workers
        .into_iter()
        .filter(|w| w.live && !is_simulated(&w.name))
        .map(|w| w.name)
        .collect();
    anyhow::ensure!(
        live.is_empty(),
        "{} live worker(s) ({}) serve this coordinator: they would take leases of the load \
         test's campaign and unbalance its books; run it against a coordinator without workers",
        live.len(),
        live.join(", ")
    );
    Ok(())
}

/// Whether `name` is one of the load test's simulated workers (`load-N`,
/// or `load-N.k` as registered after an earlier load test).
fn is_simulated(name: &str) -> bool {
    let number = |n: &str| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit());
    name.strip_prefix("load-")
        .is_some_and(|n| match n.split_once('.') {
            Some((n, k)) => number(n) && number(k),
            None => number(n),
        })
}

fn print_table(r: &LoadReport) {
    outln!(
        "{} workers × {} rounds in {:.1} s ({:.0} round trips/s, {:.0} requests/s; {})",
        r.workers,
        r.requests,
        r.seconds,
        r.round_trips_per_second,
        (r.lease_ms.count + r.result_ms.count) as f64 / r.seconds,
        if r.separate_claims {
            "a request per lease and per report"
        } else {
            "reports take the next lease"
        }
    );
    outln!("| request | count | p50 ms | p90 ms | p99 ms | max ms |");
    outln!("|---|---|---|---|---|---|");
    for (name, p) in [("lease", &r.lease_ms), ("result", &r.result_ms)] {
        outln!(
            "| {name} | {} | {:.2} | {:.2} | {:.2} | {:.2} |",
            p.count,
            p.p50,
            p.p90,
            p.p99,
            p.max
        );
    }
    outln!(
        "tests acknowledged {} / resolved by the coordinator {}; events reported {} / counted {}; errors {}",
        r.accepted_tests,
        r.campaign_tests,
        r.reported_events,
        r.campaign_events,
        r.errors.len()
    );
    match r.commits {
        Some(c) if c.transactions > 0 => outln!(
            "group commits: {} requests in {} transactions ({:.1} a commit)",
            c.requests,
            c.transactions,
            c.requests as f64 / c.transactions as f64
        ),
        Some(_) => outln!("group commits: none"),
        None => outln!("group commits: /metrics could not be read"),
    }
    for e in r.errors.iter().take(10) {
        outln!("  error: {e}");
    }
}

/// The most tests per lease the command asks for.
const MAX_LEASE_TESTS: u64 = 1 << 20;

/// How many simulated workers make how many rounds of leases how large.
#[derive(Debug, Clone, Copy)]
struct Shape {
    workers: usize,
    requests: usize,
    lease_tests: u64,
    separate_claims: bool,
}

/// The campaign the load runs on: cut-in NDD of the IDM at the smallest β
/// a campaign takes, which needs billions of tests (about 2.7 × 10⁹ at
/// P(A) ≈ 10⁻³), so it cannot stop during a load test. Its `n_min` is the
/// tests the load plans (`shape`): a campaign's leases reach no further
/// than its stop can need (`server/src/leasing/size.rs`), which before
/// its first prediction is `n_min` or twice its resolved prefix, and the
/// load's leases are to be the size it asks for from the start.
fn load_campaign(shape: &Shape) -> CreateCampaign {
    let max_tests = 1 << 50;
    let planned = (shape.workers as u64)
        .saturating_mul(shape.requests as u64)
        .saturating_mul(shape.lease_tests);
    CreateCampaign {
        beta: MIN_BETA,
        max_tests,
        seed: 1,
        n_min: Some(planned.clamp(DEFAULT_N_MIN, max_tests)),
        ..CreateCampaign::new("cut-in", Method::Ndd, serde_json::json!({"model": "idm"}))
    }
}

async fn load(worker: &Client, campaign_id: i64, shape: Shape) -> anyhow::Result<LoadReport> {
    let prepared = Cache::default()
        .get(worker, campaign_id)
        .await?
        .tests()
        .ok_or_else(|| anyhow::anyhow!("campaign {campaign_id} is a library build, not tests"))?;
    // Each simulated worker registers for its credential first, outside
    // the timed part: `load-k`, or `load-k.j` on a coordinator where an
    // earlier load test had that name.
    let mut names = Vec::with_capacity(shape.workers);
    for w in 0..shape.workers {
        names.push(worker.register(&format!("load-{w}")).await?.name);
    }
    let started = Instant::now();
    let tasks: Vec<_> = names
        .into_iter()
        .map(|name| {
            let (client, prepared) = (worker.clone(), Arc::clone(&prepared));
            tokio::spawn(simulated_worker(client, prepared, name, shape))
        })
        .collect();
    let mut logs = Vec::with_capacity(shape.workers);
    for task in tasks {
        logs.push(task.await?);
    }
    let seconds = started.elapsed().as_secs_f64();
    let all = |f: fn(&WorkerLog) -> &Vec<f64>| logs.iter().flat_map(f).copied().collect();
    Ok(LoadReport {
        campaign_id,
        workers: shape.workers,
        requests: shape.requests,
        seconds,
        separate_claims: shape.separate_claims,
        round_trips_per_second: (shape.workers * shape.requests) as f64 / seconds,
        lease_ms: Percentiles::of(all(|l| &l.lease_ms)),
        result_ms: Percentiles::of(all(|l| &l.result_ms)),
        errors: logs.iter().flat_map(|l| l.errors.clone()).collect(),
        accepted_tests: logs.iter().map(|l| l.accepted).sum(),
        campaign_tests: 0,
        reported_events: logs.iter().map(|l| l.events).sum(),
        campaign_events: 0,
        commits: None,
    })
}

/// Tests a simulated worker runs on its own task rather than on the
/// blocking pool: a few microseconds of work, less than the hand-over.
const INLINE_TESTS: u64 = 1000;

/// The events of tests `from..to`, in batches where the case runs them
/// that way, as a worker runs them.
fn run_tests(prepared: &PreparedCampaign, from: u64, to: u64) -> Vec<(u64, f64)> {
    let tests = &prepared.tests;
    let outcomes = tests
        .run_span(from, to)
        .unwrap_or_else(|| (from..to).map(|index| tests.run(index)).collect());
    (from..to)
        .zip(outcomes)
        .filter_map(|(index, outcome)| outcome.event.then_some((index, outcome.weight)))
        .collect()
}

/// One simulated worker: `rounds` leases, each run and reported whole;
/// unless `separate_claims`, each report but the last asks for the next
/// lease, and a lease is claimed on its own only when none came with it.
async fn simulated_worker(
    client: Client,
    prepared: Arc<PreparedCampaign>,
    name: String,
    shape: Shape,
) -> WorkerLog {
    let mut log = WorkerLog::default();
    let ask = LeaseRequest {
        worker: name.clone(),
        threads: 1,
        include_tests: false,
        offers: Vec::new(),
        unhealthy: Vec::new(),
        max_tests: Some(shape.lease_tests),
        wait_seconds: None,
        audits_only: false,
        noisy: Vec::new(),
    };
    let mut given = None;
    for round in 0..shape.requests {
        let lease = match given.take() {
            Some(lease) => lease,
            None => {
                let asked = Instant::now();
                match client.claim(&ask).await {
                    Ok(Some(lease)) => {
                        log.lease_ms.push(asked.elapsed().as_secs_f64() * 1e3);
                        lease
                    }
                    Ok(None) => {
                        log.errors.push(format!("{name}: no work offered"));
                        continue;
                    }
                    Err(e) => {
                        log.errors.push(format!("{name}: lease: {e}"));
                        continue;
                    }
                }
            }
        };
        let ran = Instant::now();
        let (from, to) = (lease.resume_at, lease.end);
        let events = if to - from <= INLINE_TESTS {
            Ok(run_tests(&prepared, from, to))
        } else {
            let tests = Arc::clone(&prepared);
            tokio::task::spawn_blocking(move || run_tests(&tests, from, to)).await
        };
        let Ok(events) = events else {
            log.errors
                .push(format!("{name}: running lease {}'s tests failed", lease.id));
            continue;
        };
        let mut report = ResultReport {
            worker: name.clone(),
            attempt: lease.attempt,
            key: lease.key.clone(),
            from,
            to,
            compute_seconds: ran.elapsed().as_secs_f64(),
            threads: 1,
            invalid: Vec::new(),
            events: Vec::new(),
            packed_events: None,
            near_misses: Vec::new(),
            next_lease: (!shape.separate_claims && round + 1 < shape.requests).then(|| ask.clone()),
        };
        let found = events.len() as u64;
        report.pack_events(&events);
        let sent = Instant::now();
        match client.report(lease.id, &report).await {
            Ok(ack) => {
                log.result_ms.push(sent.elapsed().as_secs_f64() * 1e3);
                log.accepted += ack.accepted;
                log.events += found;
                given = ack.next_lease;
            }
            Err(e) => log.errors.push(format!("{name}: result: {e}")),
        }
    }
    log
}

#[cfg(test)]
mod tests {
    use super::{GroupCommits, Percentiles};

    #[test]
    fn group_commit_counters_are_read_from_the_metrics_text() {
        let text = "# HELP tslg_write_groups_total Transactions\n\
                    # TYPE tslg_write_groups_total counter\n\
                    tslg_write_groups_total 12\n\
                    tslg_write_groups_total_other 99\n\
                    tslg_grouped_writes_total 150\n";
        let before = GroupCommits::scraped(text).unwrap();
        assert_eq!((before.transactions, before.requests), (12, 150));
        let after =
            GroupCommits::scraped("tslg_write_groups_total 20\ntslg_grouped_writes_total 250\n")
                .unwrap();
        let run = after.since(before);
        assert_eq!((run.transactions, run.requests), (8, 100));
        // A coordinator without the counters (an older release).
        assert!(GroupCommits::scraped("tslg_events_total 3\n").is_none());
    }

    #[test]
    fn nearest_rank_percentiles() {
        let p = Percentiles::of((1..=100).rev().map(f64::from).collect());
        assert_eq!(
            (p.count, p.p50, p.p90, p.p99, p.max),
            (100, 50.0, 90.0, 99.0, 100.0)
        );
        let one = Percentiles::of(vec![7.0]);
        assert_eq!((one.p50, one.p99), (7.0, 7.0));
    }
}
