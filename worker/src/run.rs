//! The worker loop: take a lease, run its tests on the rayon pool in
//! chunks, report each chunk (which also keeps the lease alive), heartbeat
//! while a chunk runs; with no work, ask with a wait the coordinator holds
//! until work appears (long polling), and back off with jitter when it
//! answers at once or cannot be reached. On shutdown the running chunk is
//! finished and reported and the rest of the lease is given back. A lease's
//! last chunk is reported while the next lease runs (see
//! [`crate::sending`]).

use crate::backoff::Backoff;
use crate::config::WorkerConfig;
use crate::external::{Program, ProgramRun, ProgramSettings, Programs};
use crate::prepared::{Cache, PrepareError, Prepared, PreparedCampaign};
use crate::report_parts::{attach_near_misses, report_parts, PartLimits, Reporter};
use crate::sending::{fence_of, LeaseLink, Tail};
use rand::SeedableRng;
use rayon::prelude::*;
use std::future::Future;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::watch;
use tslg_api::{EventResult, InvalidResult, Lease, LeaseFence, LeaseRequest, NearMiss};
use tslg_client::{CallError, Client};
use tslg_method::registry::TestOutcome;

/// Times a test whose simulation panics is tried before it is reported
/// `invalid`.
const INVALID_TRIES: usize = 2;
/// A chunk aims at this much work, so reports double as heartbeats and a
/// stopped campaign is noticed quickly.
const CHUNK_SECONDS: f64 = 0.5;
const FIRST_CHUNK_PER_THREAD: u64 = 64;
/// Most tests in a chunk: a chunk's events are held until it is
/// reported, so this bounds the worker's memory on a campaign whose tests
/// are mostly events (2²² tests, at most 64 MB of events), whatever its
/// threads' rate. A lease longer than that runs in several chunks.
const MAX_CHUNK: u64 = 1 << 22;

/// Campaigns whose chunk size a worker remembers: more than a coordinator
/// runs side by side in practice (leases take turns between campaigns).
const REMEMBERED_CAMPAIGNS: usize = 16;

/// The chunk size last measured on each of the campaigns a worker ran
/// most recently, so that a lease of any of them starts at its own size
/// ([`first_chunk`]) when leases alternate between campaigns.
#[derive(Debug, Default)]
struct ChunkSizes {
    /// `(campaign, size)`, the most recently measured first.
    sizes: Vec<(i64, u64)>,
}

impl ChunkSizes {
    /// The size last measured on `campaign`, if it is remembered.
    fn get(&self, campaign: i64) -> Option<u64> {
        self.sizes
            .iter()
            .find(|(c, _)| *c == campaign)
            .map(|&(_, size)| size)
    }

    /// Remembers `size` for `campaign`, forgetting the campaign measured
    /// longest ago beyond [`REMEMBERED_CAMPAIGNS`].
    fn set(&mut self, campaign: i64, size: u64) {
        self.sizes.retain(|(c, _)| *c != campaign);
        self.sizes.insert(0, (campaign, size));
        self.sizes.truncate(REMEMBERED_CAMPAIGNS);
    }
}

/// The first chunk of a lease of `left` tests. Of a campaign the worker
/// has measured a chunk of (`known`), that size, but at most half the
/// lease: so the lease runs in two chunks or more, the report of the last
/// but one asks for the next lease, and the threads start the second chunk
/// while the first is reported. Else a small first chunk, whose time sizes
/// the next.
///
/// A first chunk of 64 tests per thread at every lease, as before, cost a
/// cheap campaign a tenth of the threads' time: a chunk of a few ms ran
/// while the last lease's final reports were checked and folded, and the
/// threads waited for that acknowledgement (measured: 1.8 of 2 cores busy
/// through the service, 1.9 after). Remembering only the last campaign's
/// size did the same to campaigns run side by side, whose leases alternate.
fn first_chunk(known: Option<u64>, threads: usize, left: u64) -> u64 {
    match known {
        Some(size) => size.min(left.div_ceil(2)).max(1),
        None => FIRST_CHUNK_PER_THREAD * threads as u64,
    }
}

/// What a worker did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WorkerSummary {
    /// Leases the worker took.
    pub leases: u64,
    /// Tests it reported.
    pub tests: u64,
    /// Events among them.
    pub events: u64,
}

struct Worker {
    client: Client,
    name: String,
    threads: usize,
    pool: Arc<rayon::ThreadPool>,
    cache: Cache,
    programs: Arc<Programs>,
    stop: watch::Receiver<bool>,
    summary: WorkerSummary,
    /// The last lease's final reports, still being sent.
    tail: Option<Tail>,
    /// The next lease, taken with the report of a lease's last chunk but
    /// one (`next_lease`), and when: the worker asks no separate request
    /// for it.
    next_lease: Option<(Lease, Instant)>,
    /// The chunk sizes measured on recent campaigns, which their next
    /// leases start from ([`first_chunk`]).
    chunks: ChunkSizes,
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
    let settings = ProgramSettings {
        worker: name.clone(),
        timeout: Duration::from_secs_f64(config.vut_timeout_seconds),
        max_failures: config.vut_max_failures,
        cooldown: Duration::from_secs_f64(config.vut_cooldown_seconds),
    };
    let specs = config.vut_exec.clone();
    let programs = tokio::task::spawn_blocking(move || Programs::start(&specs, &settings))
        .await?
        .map_err(anyhow::Error::msg)?;
    let programs = Arc::new(programs);
    let (tx, stop) = watch::channel(false);
    let stopping = Arc::clone(&programs);
    tokio::spawn(async move {
        shutdown.await;
        stopping.stop();
        let _ = tx.send(true);
    });
    let mut worker = Worker {
        client: Client::new(&config.server, config.token.clone())?,
        name,
        threads,
        pool: Arc::new(pool),
        cache: Cache::with_host(
            Arc::clone(&programs) as Arc<dyn tslg_method::external::ProgramHost>
        ),
        programs,
        stop,
        summary: WorkerSummary::default(),
        tail: None,
        next_lease: None,
        chunks: ChunkSizes::default(),
    };
    tracing::info!(worker = %worker.name, threads, server = %config.server, "worker started");
    let mut idle = Backoff::new(0.05, config.max_backoff_seconds);
    let mut trouble = Backoff::new(0.2, config.max_backoff_seconds.max(5.0));
    let mut rng = rand::rngs::StdRng::from_os_rng();
    let mut idle_since = Instant::now();
    // The coordinator's release is checked before the first lease and after
    // every outage (it may come back upgraded): both speak one version of
    // the lease protocol.
    let mut version_checked = false;
    while !worker.stopping() {
        if !version_checked {
            match worker.client.health().await {
                Ok(health) => {
                    anyhow::ensure!(
                        health.version == env!("CARGO_PKG_VERSION"),
                        "the coordinator runs tslg {}, this worker tslg {}: upgrade workers \
                         and coordinator together (docs/operations.md)",
                        health.version,
                        env!("CARGO_PKG_VERSION")
                    );
                    version_checked = true;
                }
                Err(e) => {
                    tracing::warn!(error = %e, "cannot reach the coordinator");
                    worker.pause(trouble.next_wait(&mut rng)).await;
                    continue;
                }
            }
        }
        if worker.programs.any_rested() {
            let programs = Arc::clone(&worker.programs);
            tokio::task::spawn_blocking(move || programs.probe_rested()).await?;
        }
        // With no lease at hand, the request waits at the coordinator for
        // work (long polling), but not past the idle exit, and a second at
        // most while a program rests (it is probed between requests).
        let mut wait = config
            .exit_when_idle_seconds
            .map_or(config.claim_wait_seconds, |s| {
                config
                    .claim_wait_seconds
                    .min((s - idle_since.elapsed().as_secs_f64()).max(0.0))
            });
        if !worker.programs.unhealthy().is_empty() {
            wait = wait.min(1.0);
        }
        let asked = Instant::now();
        let claimed = match worker.held_lease().await {
            Some(lease) => Ok(Some(lease)),
            None => worker.claim(wait).await,
        };
        // The coordinator held the request (it waited for work): ask again
        // at once. One that answered sooner than half the shortest wait (its
        // cap below that, or the worker's wait 0 or cut short by the idle
        // exit) is polled with backoff.
        let held = wait > 0.0
            && asked.elapsed().as_secs_f64() >= wait.min(crate::config::MIN_CLAIM_WAIT) / 2.0;
        match claimed {
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
                if !held {
                    worker.pause(idle.next_wait(&mut rng)).await;
                }
            }
            Err(CallError::Refused {
                status: 401,
                detail,
            }) => {
                anyhow::bail!("the coordinator refused this worker's token: {detail}");
            }
            Err(CallError::Refused {
                status: 403,
                detail,
            }) => {
                // Flagged: its results contradicted others'. Asking again
                // changes nothing until an operator clears the flag.
                anyhow::bail!("the coordinator refuses this worker: {detail}");
            }
            Err(e) => {
                tracing::warn!(error = %e, "cannot get work");
                version_checked = false;
                worker.pause(trouble.next_wait(&mut rng)).await;
            }
        }
    }
    if let Some(tail) = worker.tail.take() {
        worker.summary.tests += tail.settle().await;
    }
    if let Some((lease, _)) = worker.next_lease.take() {
        // Taken with a report but never started: another worker gets it
        // at once rather than when it expires.
        LeaseLink {
            client: worker.client.clone(),
            lease: lease.id,
            fence: fence_of(&lease, &worker.name),
            stop: worker.stop.clone(),
        }
        .give_back("the worker is shutting down")
        .await;
    }
    let WorkerSummary {
        leases,
        tests,
        events,
    } = worker.summary;
    tracing::info!(worker = %worker.name, leases, tests, events, "worker stopped");
    Ok(worker.summary)
}

impl Worker {
    fn stopping(&self) -> bool {
        *self.stop.borrow()
    }

    /// The next lease taken with a report, still the worker's: one held
    /// longer than its heartbeat period (a long last chunk, a slow
    /// coordinator) is kept alive first, and dropped if the coordinator
    /// says it is gone or its campaign stopped.
    async fn held_lease(&mut self) -> Option<Lease> {
        let (lease, since) = self.next_lease.take()?;
        if since.elapsed().as_secs_f64() < lease.heartbeat_seconds {
            return Some(lease);
        }
        let fence = fence_of(&lease, &self.name);
        match self.client.heartbeat(lease.id, &fence).await {
            Ok(ack) if ack.proceed => Some(lease),
            Ok(_) => None,
            Err(e) => {
                tracing::warn!(lease = lease.id, error = %e, "the next lease is gone");
                None
            }
        }
    }

    /// What the worker asks for when it asks for work.
    fn lease_request(&self) -> LeaseRequest {
        LeaseRequest {
            worker: self.name.clone(),
            threads: self.threads as u32,
            include_tests: false,
            offers: self.programs.offers(),
            unhealthy: self.programs.unhealthy(),
            max_tests: None,
            wait_seconds: None,
        }
    }

    /// Asks for a lease, waiting at the coordinator up to `wait` seconds
    /// for one; `None` at once on shutdown. (A lease granted just as the
    /// request is dropped is nobody's: it expires and is handed out again.)
    async fn claim(&mut self, wait: f64) -> Result<Option<Lease>, CallError> {
        let request = LeaseRequest {
            wait_seconds: (wait > 0.0).then_some(wait),
            ..self.lease_request()
        };
        let mut stop = self.stop.clone();
        tokio::select! {
            // An answer already there is taken, not dropped.
            biased;
            claimed = self.client.claim(&request) => claimed,
            _ = stop.wait_for(|s| *s) => Ok(None),
        }
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
        let link = LeaseLink {
            client: self.client.clone(),
            lease: lease.id,
            fence: fence_of(&lease, &self.name),
            stop: self.stop.clone(),
        };
        let prepared = match self.cache.get(&self.client, lease.campaign_id).await {
            Ok(Prepared::Tests(p)) => p,
            Ok(Prepared::Build(build)) => {
                let ran =
                    crate::building::build_whole(&self.client, &self.pool, &lease, &link, build);
                return ran.await;
            }
            Err(e) => {
                let error = match e {
                    PrepareError::Call(c) => anyhow::Error::from(c),
                    PrepareError::Unusable(reason) => {
                        anyhow::anyhow!("campaign {}: {reason}", lease.campaign_id)
                    }
                };
                link.give_back(&format!("cannot prepare: {error}")).await;
                return Err(error);
            }
        };
        let program = match prepared.tests.external() {
            None => None,
            Some(vut) => match self.programs.get(&vut.external) {
                Some(program) => Some(Arc::clone(program)),
                None => {
                    let reason = format!(
                        "campaign {} tests the external program `{}`, which this worker does \
                         not run",
                        lease.campaign_id, vut.external
                    );
                    link.give_back(&reason).await;
                    anyhow::bail!(reason);
                }
            },
        };
        let proceed = Arc::new(AtomicBool::new(true));
        let heartbeat = tokio::spawn(heartbeat(
            self.client.clone(),
            lease.id,
            link.fence.clone(),
            Duration::from_secs_f64(lease.heartbeat_seconds.max(0.1)),
            Arc::clone(&proceed),
        ));
        // An adaptive campaign's lease names each test's cell and weight.
        let near_miss = prepared.near_miss;
        let planned: Option<Arc<Planned>> = lease.tests.as_ref().map(|tests| {
            Arc::new(Planned {
                first: lease.resume_at,
                tests: tests.iter().map(|t| (t.cell, t.weight)).collect(),
                near_miss,
            })
        });
        if planned.is_none() && near_miss.is_some() {
            let reason = format!(
                "lease {} of adaptive campaign {} does not name its tests' cells",
                lease.id, lease.campaign_id
            );
            link.give_back(&reason).await;
            anyhow::bail!(reason);
        }
        if let Some(p) = &planned {
            if p.tests.len() as u64 != lease.end - lease.resume_at {
                let reason = format!(
                    "lease {} lists {} tests for its range {}..{}",
                    lease.id,
                    p.tests.len(),
                    lease.resume_at,
                    lease.end
                );
                link.give_back(&reason).await;
                anyhow::bail!(reason);
            }
        }
        let mut at = lease.resume_at;
        let mut chunk = first_chunk(
            self.chunks.get(lease.campaign_id),
            self.threads,
            lease.end.saturating_sub(at),
        );
        let pool = Arc::clone(&self.pool);
        let start = |from: u64, chunk: u64| {
            let to = (from + chunk).min(lease.end);
            let (pool, p, program) = (Arc::clone(&pool), Arc::clone(&prepared), program.clone());
            let planned = planned.clone();
            let campaign = lease.campaign_id;
            let handle = tokio::task::spawn_blocking(move || {
                pool.install(|| {
                    run_range(
                        &p,
                        program.as_deref(),
                        planned.as_deref(),
                        campaign,
                        from,
                        to,
                    )
                })
            });
            (from, to, Instant::now(), handle)
        };
        // The next chunk runs while the last one is reported: the worker's
        // threads do not wait for the coordinator's acknowledgement.
        let mut running = (at < lease.end && !self.stopping()).then(|| start(at, chunk));
        while let Some((from, to, started, handle)) = running.take() {
            let ran = handle.await?;
            let seconds = started.elapsed().as_secs_f64();
            if ran.end == from {
                // The program turned unhealthy before this chunk ran.
                break;
            }
            if ran.end == to
                && to < lease.end
                && proceed.load(Ordering::Relaxed)
                && !self.stopping()
            {
                let rate = (ran.end - from) as f64 / seconds.max(1e-6);
                chunk = ((rate * CHUNK_SECONDS) as u64).clamp(16, MAX_CHUNK);
                self.chunks.set(lease.campaign_id, chunk);
                running = Some(start(to, chunk));
            }
            let found = ran.events.len() as u64;
            let who = Reporter {
                worker: &self.name,
                attempt: lease.attempt,
                key: &lease.key,
                threads: self.threads as u32,
            };
            let mut parts = report_parts(
                &who,
                from,
                ran.end,
                seconds,
                &ran.events,
                &ran.invalid,
                PartLimits::default(),
            );
            attach_near_misses(&mut parts, &ran.near_misses);
            self.summary.events += found;
            // The chunk started meanwhile is the lease's last: this report
            // asks for the next lease, which is then in hand when that
            // chunk ends (one request per lease fewer).
            let last_started = running.as_ref().is_some_and(|r| r.1 == lease.end);
            if last_started && !self.stopping() {
                if let Some(part) = parts.last_mut() {
                    part.next_lease = Some(self.lease_request());
                }
            }
            if running.is_none() && ran.end == lease.end && !self.stopping() {
                // The lease's last chunk: its reports go while the threads
                // start the next lease (one tail at a time).
                if let Some(tail) = self.tail.take() {
                    self.summary.tests += tail.settle().await;
                }
                self.tail = Some(link.send_as_tail(parts, from));
                at = lease.end;
                break;
            }
            let sent = match link.send(&parts, from).await {
                Ok(sent) => sent,
                Err(e) => {
                    heartbeat.abort();
                    return Err(e.into());
                }
            };
            self.summary.tests += sent.accepted;
            at = sent.reported_to;
            if let Some(next) = sent.next_lease {
                self.next_lease = Some((next, Instant::now()));
            }
            if !sent.proceed || at < to {
                // A chunk started meanwhile is left to finish unreported.
                break;
            }
        }
        heartbeat.abort();
        let unhealthy = program.as_ref().and_then(|p| p.unhealthy());
        if at < lease.end && (self.stopping() || unhealthy.is_some()) {
            let reason = match &unhealthy {
                Some(u) => format!(
                    "the external program `{}` is unhealthy: {}",
                    u.name, u.reason
                ),
                None => "the worker is shutting down".to_owned(),
            };
            link.give_back(&reason).await;
        }
        Ok(())
    }
}

pub(crate) async fn heartbeat(
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

/// What a range of tests gave.
#[derive(Debug, Default)]
pub struct RangeRun {
    /// Tests `from..end` ran; `end < to` when an external program turned
    /// unhealthy, and the rest is left for others.
    pub end: u64,
    pub events: Vec<EventResult>,
    pub invalid: Vec<InvalidResult>,
    /// Tests without the event that came within the plan's `near_miss`
    /// (adaptive campaigns).
    pub near_misses: Vec<NearMiss>,
}

/// The tests a lease names (adaptive campaigns): the cell and weight of
/// each index from `first`.
pub struct Planned {
    pub first: u64,
    pub tests: Vec<(u64, f64)>,
    /// Criticality at or below which a test is reported as a near miss.
    pub near_miss: Option<f64>,
}

/// Runs tests `from..to` in parallel, on the campaign's built-in vehicle or
/// with `program`; returns the events and invalid tests in index order.
pub fn run_range(
    p: &PreparedCampaign,
    program: Option<&Program>,
    planned: Option<&Planned>,
    campaign: i64,
    from: u64,
    to: u64,
) -> RangeRun {
    if program.is_none() && planned.is_none() {
        if let Some(ran) = run_spans(p, from, to) {
            return ran;
        }
    }
    let near = |c: Option<f64>| {
        planned
            .and_then(|p| p.near_miss)
            .is_some_and(|n| c.is_some_and(|c| c <= n))
    };
    let mut found: Vec<(u64, ProgramRun)> = (from..to)
        .into_par_iter()
        .filter_map(|index| {
            let cell = planned.map(|p| p.tests[(index - p.first) as usize]);
            let run = match (program, cell) {
                (Some(program), None) => program.run_test(p.tests.as_ref(), campaign, index),
                (Some(program), Some((cell, weight))) => {
                    program.run_cell(p.tests.as_ref(), campaign, index, cell as usize, weight)
                }
                (None, cell) => match run_builtin(p, index, cell) {
                    Ok((outcome, criticality)) => ProgramRun::Done(outcome, criticality),
                    Err(reason) => ProgramRun::Invalid(reason),
                },
            };
            match run {
                ProgramRun::Done(outcome, c) if !outcome.event && !near(c) => None,
                other => Some((index, other)),
            }
        })
        .collect();
    found.sort_by_key(|(i, _)| *i);
    let end = found
        .iter()
        .find(|(_, run)| *run == ProgramRun::Skipped)
        .map_or(to, |(i, _)| *i);
    let mut ran = RangeRun {
        end,
        ..RangeRun::default()
    };
    for (index, run) in found.into_iter().take_while(|(i, _)| *i < end) {
        match run {
            ProgramRun::Done(outcome, _) if outcome.event => ran.events.push(EventResult {
                index,
                weight: outcome.weight,
            }),
            ProgramRun::Done(_, criticality) => ran.near_misses.push(NearMiss {
                index,
                criticality: criticality.unwrap_or(1.0),
            }),
            ProgramRun::Invalid(reason) => ran.invalid.push(InvalidResult { index, reason }),
            ProgramRun::Skipped => unreachable!("skipped tests are past the end"),
        }
    }
    ran
}

/// Runs test `index` on the built-in vehicle: drawn from the campaign's
/// plan, or on the `(cell, weight)` its lease names.
/// Tests per span of a built-in vehicle's range, each run in batches
/// where its case has them (`CampaignTests::run_span`).
const SPAN: u64 = 1024;

/// `from..to` on the campaign's built-in vehicle, span by span in parallel;
/// `None` when the case runs tests one by one, or when a span panicked
/// (the one-by-one path then retries each test and reports what fails).
fn run_spans(p: &PreparedCampaign, from: u64, to: u64) -> Option<RangeRun> {
    let starts: Vec<u64> = (from..to).step_by(SPAN as usize).collect();
    let spans: Option<Vec<Vec<EventResult>>> = starts
        .into_par_iter()
        .map(|start| {
            let end = (start + SPAN).min(to);
            let outcomes =
                catch_unwind(AssertUnwindSafe(|| p.tests.run_span(start, end))).ok()??;
            Some(
                (start..end)
                    .zip(outcomes)
                    .filter(|(_, o)| o.event)
                    .map(|(index, o)| EventResult {
                        index,
                        weight: o.weight,
                    })
                    .collect(),
            )
        })
        .collect();
    Some(RangeRun {
        end: to,
        events: spans?.into_iter().flatten().collect(),
        ..RangeRun::default()
    })
}

fn run_builtin(
    p: &PreparedCampaign,
    index: u64,
    cell: Option<(u64, f64)>,
) -> Result<(TestOutcome, Option<f64>), String> {
    let run = || match cell {
        None => p.tests.run_with(index, None).map(|o| (o, None)),
        Some((cell, weight)) => p
            .tests
            .run_cell(index, cell as usize, None)
            .map(|(event, c)| (TestOutcome { event, weight }, c)),
    };
    let mut last = String::new();
    for _ in 0..INVALID_TRIES {
        match catch_unwind(AssertUnwindSafe(run)) {
            Ok(Ok(outcome)) => return Ok(outcome),
            Ok(Err(e)) => return Err(e.0),
            Err(panic) => last = crate::panics::panic_message(panic.as_ref()),
        }
    }
    Err(format!(
        "the simulation failed {INVALID_TRIES} times: {last}"
    ))
}

#[cfg(test)]
mod tests {
    use super::{first_chunk, ChunkSizes, REMEMBERED_CAMPAIGNS};

    #[test]
    fn a_lease_of_a_known_campaign_starts_at_the_measured_chunk_but_in_two_parts() {
        // A campaign never measured: a small first chunk.
        assert_eq!(first_chunk(None, 2, 1 << 20), 128);
        // A measured one: its size, if the lease is twice that.
        assert_eq!(first_chunk(Some(5_000), 2, 1 << 20), 5_000);
        // A lease smaller than two chunks: its first half (rounded up).
        assert_eq!(first_chunk(Some(1 << 24), 2, 1_001), 501);
        assert_eq!(first_chunk(Some(1 << 24), 2, 1), 1);
        assert_eq!(first_chunk(Some(1 << 24), 2, 0), 1);
    }

    #[test]
    fn campaigns_whose_leases_alternate_keep_their_own_chunk_sizes() {
        let mut sizes = ChunkSizes::default();
        assert_eq!(sizes.get(7), None);
        sizes.set(7, 5_000);
        sizes.set(8, 90_000);
        // Leases of 7 and 8 alternating: each starts at its own size.
        assert_eq!(sizes.get(7), Some(5_000));
        assert_eq!(sizes.get(8), Some(90_000));
        sizes.set(7, 6_000);
        assert_eq!(sizes.get(7), Some(6_000));
        assert_eq!(sizes.get(8), Some(90_000));
        // Past the limit, the campaign measured longest ago is forgotten.
        for c in 100..100 + REMEMBERED_CAMPAIGNS as i64 - 1 {
            sizes.set(c, 1);
        }
        assert_eq!(sizes.get(7), Some(6_000));
        assert_eq!(sizes.get(8), None);
        assert_eq!(sizes.sizes.len(), REMEMBERED_CAMPAIGNS);
    }
}
