//! The worker loop: take a lease, run its tests on the rayon pool in
//! chunks, report each chunk (which also keeps the lease alive), heartbeat
//! while a chunk runs, and back off with jitter when there is no work or no
//! coordinator. On shutdown the running chunk is finished and reported and
//! the rest of the lease is given back.

use crate::backoff::Backoff;
use crate::client::{CallError, Client};
use crate::config::WorkerConfig;
use crate::prepared::{Cache, PrepareError, PreparedCampaign};
use rand::SeedableRng;
use rayon::prelude::*;
use std::future::Future;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::watch;
use tslg_api::{EventResult, InvalidResult, Lease, LeaseFence, LeaseRequest, ResultReport};
use tslg_method::registry::TestOutcome;

/// Times a test whose simulation panics is tried before it is reported
/// `invalid`.
const INVALID_TRIES: usize = 2;
/// A chunk aims at this much work, so reports double as heartbeats and a
/// stopped campaign is noticed quickly.
const CHUNK_SECONDS: f64 = 0.5;
const FIRST_CHUNK_PER_THREAD: u64 = 64;

/// What a worker did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WorkerSummary {
    pub leases: u64,
    pub tests: u64,
    pub events: u64,
}

struct Worker {
    client: Client,
    name: String,
    threads: usize,
    pool: Arc<rayon::ThreadPool>,
    cache: Cache,
    stop: watch::Receiver<bool>,
    summary: WorkerSummary,
}

/// Runs a worker until `shutdown` completes (or, with
/// `exit_when_idle_seconds`, until there has been no work that long).
pub async fn run(
    config: WorkerConfig,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> anyhow::Result<WorkerSummary> {
    config.validate()?;
    let threads = config.threads();
    let name = config.name();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(move |i| format!("tslg-sim-{i}"))
        .build()?;
    let (tx, stop) = watch::channel(false);
    tokio::spawn(async move {
        shutdown.await;
        let _ = tx.send(true);
    });
    let mut worker = Worker {
        client: Client::new(&config.server, config.token.clone())?,
        name,
        threads,
        pool: Arc::new(pool),
        cache: Cache::default(),
        stop,
        summary: WorkerSummary::default(),
    };
    tracing::info!(worker = %worker.name, threads, server = %config.server, "worker started");
    let mut idle = Backoff::new(0.05, config.max_backoff_seconds);
    let mut trouble = Backoff::new(0.2, config.max_backoff_seconds.max(5.0));
    let mut rng = rand::rngs::StdRng::from_os_rng();
    let mut idle_since = Instant::now();
    while !worker.stopping() {
        let request = LeaseRequest {
            worker: worker.name.clone(),
            threads: threads as u32,
            include_tests: false,
        };
        match worker.client.claim(&request).await {
            Ok(Some(lease)) => {
                idle.reset();
                trouble.reset();
                worker.summary.leases += 1;
                if let Err(e) = worker.work(lease).await {
                    tracing::warn!(error = %e, "lease abandoned");
                    worker.pause(trouble.next_wait(&mut rng)).await;
                }
                idle_since = Instant::now();
            }
            Ok(None) => {
                if config
                    .exit_when_idle_seconds
                    .is_some_and(|s| idle_since.elapsed().as_secs_f64() >= s)
                {
                    break;
                }
                worker.pause(idle.next_wait(&mut rng)).await;
            }
            Err(CallError::Refused {
                status: 401,
                detail,
            }) => {
                anyhow::bail!("the coordinator refused this worker's token: {detail}");
            }
            Err(e) => {
                tracing::warn!(error = %e, "cannot get work");
                worker.pause(trouble.next_wait(&mut rng)).await;
            }
        }
    }
    tracing::info!(worker = %worker.name, ?worker.summary, "worker stopped");
    Ok(worker.summary)
}

impl Worker {
    fn stopping(&self) -> bool {
        *self.stop.borrow()
    }

    /// Sleeps, waking early on shutdown.
    async fn pause(&mut self, wait: Duration) {
        let mut stop = self.stop.clone();
        tokio::select! {
            _ = tokio::time::sleep(wait) => {}
            _ = stop.wait_for(|s| *s) => {}
        }
    }

    async fn work(&mut self, lease: Lease) -> anyhow::Result<()> {
        let fence = LeaseFence {
            worker: self.name.clone(),
            attempt: lease.attempt,
        };
        let prepared = match self.cache.get(&self.client, lease.campaign_id).await {
            Ok(p) => p,
            Err(e) => {
                let _ = self.client.release(lease.id, &fence).await;
                return Err(match e {
                    PrepareError::Call(c) => c.into(),
                    PrepareError::Unusable(reason) => {
                        anyhow::anyhow!("campaign {}: {reason}", lease.campaign_id)
                    }
                });
            }
        };
        let proceed = Arc::new(AtomicBool::new(true));
        let heartbeat = tokio::spawn(heartbeat(
            self.client.clone(),
            lease.id,
            fence.clone(),
            Duration::from_secs_f64(lease.heartbeat_seconds.max(0.1)),
            Arc::clone(&proceed),
        ));
        let mut at = lease.resume_at;
        let mut chunk = FIRST_CHUNK_PER_THREAD * self.threads as u64;
        while at < lease.end && proceed.load(Ordering::Relaxed) && !self.stopping() {
            let to = (at + chunk).min(lease.end);
            let started = Instant::now();
            let (pool, p) = (Arc::clone(&self.pool), Arc::clone(&prepared));
            let (events, invalid) =
                tokio::task::spawn_blocking(move || pool.install(|| run_range(&p, at, to))).await?;
            let seconds = started.elapsed().as_secs_f64();
            let found = events.len() as u64;
            let report = ResultReport {
                worker: self.name.clone(),
                attempt: lease.attempt,
                from: at,
                to,
                events,
                invalid,
                compute_seconds: seconds,
                threads: self.threads as u32,
            };
            match self.report(lease.id, &report).await {
                Ok(ack) => {
                    self.summary.tests += ack.accepted;
                    self.summary.events += found;
                    at = to;
                    if !ack.proceed {
                        break;
                    }
                }
                Err(e) => {
                    heartbeat.abort();
                    return Err(e.into());
                }
            }
            let rate = (to - report.from) as f64 / seconds.max(1e-6);
            chunk = ((rate * CHUNK_SECONDS) as u64).clamp(16, 1 << 22);
        }
        heartbeat.abort();
        if at < lease.end && self.stopping() {
            self.client.release(lease.id, &fence).await?;
            tracing::info!(lease = lease.id, at, "lease given back on shutdown");
        }
        Ok(())
    }

    /// Reports, retrying while the coordinator is unreachable: the same
    /// report twice is acknowledged once, so a retry cannot double-count.
    async fn report(
        &mut self,
        lease: i64,
        report: &ResultReport,
    ) -> Result<tslg_api::ResultAck, CallError> {
        let mut backoff = Backoff::new(0.2, 5.0);
        let mut rng = rand::rngs::StdRng::from_os_rng();
        let mut tries = 0;
        loop {
            match self.client.report(lease, report).await {
                Err(CallError::Transient(e)) => {
                    tries += 1;
                    if self.stopping() && tries > 5 {
                        return Err(CallError::Transient(e));
                    }
                    tracing::warn!(lease, error = %e, "result not delivered; retrying");
                    let wait = backoff.next_wait(&mut rng);
                    tokio::time::sleep(wait).await;
                }
                other => return other,
            }
        }
    }
}

async fn heartbeat(
    client: Client,
    lease: i64,
    fence: LeaseFence,
    every: Duration,
    proceed: Arc<AtomicBool>,
) {
    loop {
        tokio::time::sleep(every).await;
        match client.heartbeat(lease, &fence).await {
            Ok(ack) if ack.proceed => {}
            Ok(_) | Err(CallError::Refused { .. }) => {
                proceed.store(false, Ordering::Relaxed);
                return;
            }
            Err(CallError::Transient(e)) => {
                tracing::debug!(lease, error = %e, "heartbeat not delivered")
            }
        }
    }
}

/// Runs tests `from..to` in parallel; returns the events and invalid tests
/// in index order.
pub fn run_range(
    p: &PreparedCampaign,
    from: u64,
    to: u64,
) -> (Vec<EventResult>, Vec<InvalidResult>) {
    let mut found: Vec<(u64, Result<f64, String>)> = (from..to)
        .into_par_iter()
        .filter_map(|index| match run_one(p, index) {
            Ok(outcome) if outcome.event => Some((index, Ok(outcome.weight))),
            Ok(_) => None,
            Err(reason) => Some((index, Err(reason))),
        })
        .collect();
    found.sort_by_key(|(i, _)| *i);
    let mut events = Vec::new();
    let mut invalid = Vec::new();
    for (index, outcome) in found {
        match outcome {
            Ok(weight) => events.push(EventResult { index, weight }),
            Err(reason) => invalid.push(InvalidResult { index, reason }),
        }
    }
    (events, invalid)
}

fn run_one(p: &PreparedCampaign, index: u64) -> Result<TestOutcome, String> {
    let mut last = String::new();
    for _ in 0..INVALID_TRIES {
        match catch_unwind(AssertUnwindSafe(|| p.tests.run(index))) {
            Ok(outcome) => return Ok(outcome),
            Err(panic) => {
                last = panic
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| panic.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "unknown panic".into());
            }
        }
    }
    Err(format!(
        "the simulation failed {INVALID_TRIES} times: {last}"
    ))
}
