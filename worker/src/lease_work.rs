//! Working one lease: prepare its campaign, run its tests on the rayon
//! pool chunk by chunk while the last chunk is reported, heartbeat
//! meanwhile, and give back what is left when the worker stops or its
//! program turns unhealthy. A build lease is run whole
//! ([`crate::building`]).

use crate::building::build_whole;
use crate::chunks::{first_chunk, measured_chunk};
use crate::external::Program;
use crate::heartbeat::heartbeat;
use crate::prepared::{PrepareError, Prepared, PreparedCampaign};
use crate::range::{run_range, Planned, RangeRun};
use crate::report_parts::{attach_near_misses, report_parts, PartLimits, Reporter};
use crate::sending::LeaseLink;
use crate::worker::Worker;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::task::JoinHandle;
use tslg_api::{Lease, LeaseRequest, ResultReport};

/// What a lease of tests runs on: its campaign, the program when the
/// vehicle is one, and the cells it names (adaptive campaigns).
#[derive(Clone)]
pub struct LeaseTests {
    pub prepared: Arc<PreparedCampaign>,
    pub program: Option<Arc<Program>>,
    pub planned: Option<Arc<Planned>>,
}

/// The tests of `lease` on `prepared`, or why this worker cannot run them:
/// a program it does not run, or an adaptive lease whose cells are missing
/// or do not match its range.
pub fn lease_tests(
    lease: &Lease,
    prepared: Arc<PreparedCampaign>,
    program_named: impl Fn(&str) -> Option<Arc<Program>>,
) -> Result<LeaseTests, String> {
    let program = match prepared.tests.external() {
        None => None,
        Some(vut) => Some(program_named(&vut.external).ok_or_else(|| {
            format!(
                "campaign {} tests the external program `{}`, which this worker does not run",
                lease.campaign_id, vut.external
            )
        })?),
    };
    // A campaign that switched draws nearly every test outside its library
    // from the lease's `explore_from` on: the worker draws as the
    // coordinator does (the switch is made once and never moved).
    if let Some(from) = lease.explore_from {
        if !prepared.tests.set_explore_from(Some(from)) {
            return Err(format!(
                "lease {} of campaign {} switches at test {from}, which its tests cannot",
                lease.id, lease.campaign_id
            ));
        }
    }
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
        return Err(format!(
            "lease {} of adaptive campaign {} does not name its tests' cells",
            lease.id, lease.campaign_id
        ));
    }
    if let Some(p) = &planned {
        if p.tests.len() as u64 != lease.end - lease.resume_at {
            return Err(format!(
                "lease {} lists {} tests for its range {}..{}",
                lease.id,
                p.tests.len(),
                lease.resume_at,
                lease.end
            ));
        }
    }
    Ok(LeaseTests {
        prepared,
        program,
        planned,
    })
}

/// What a chunk's report asks for besides its results.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Ask {
    Nothing,
    /// The worker's next lease: the lease's last chunk is running.
    NextLease,
    /// An audit this worker may run, if one is open.
    Audit,
}

/// A chunk running on the pool: tests `from..to`, started at `started`.
struct RunningChunk {
    from: u64,
    to: u64,
    started: Instant,
    handle: JoinHandle<RangeRun>,
}

impl LeaseTests {
    /// Starts tests `from..from + chunk` (cut at the lease's end) on `pool`;
    /// none starts once `go_on` is false.
    fn start(
        &self,
        pool: &Arc<rayon::ThreadPool>,
        lease: &Lease,
        (from, chunk): (u64, u64),
        go_on: &Arc<AtomicBool>,
    ) -> RunningChunk {
        let to = (from + chunk).min(lease.end);
        let (pool, tests, go_on) = (Arc::clone(pool), self.clone(), Arc::clone(go_on));
        let campaign = lease.campaign_id;
        let handle = tokio::task::spawn_blocking(move || {
            pool.install(|| {
                run_range(
                    &tests.prepared,
                    tests.program.as_deref(),
                    tests.planned.as_deref(),
                    campaign,
                    (from, to),
                    &go_on,
                )
            })
        });
        RunningChunk {
            from,
            to,
            started: Instant::now(),
            handle,
        }
    }
}

impl Worker {
    /// Works `lease` to its end, or until the coordinator, the worker's
    /// shutdown or its program stops it.
    pub async fn work(&mut self, lease: Lease) -> anyhow::Result<()> {
        let link = self.link(&lease);
        let prepared = match self.cache.get(&self.client, lease.campaign_id).await {
            Ok(Prepared::Tests(p)) => p,
            Ok(Prepared::Build(build)) => {
                return build_whole(
                    &self.client,
                    &self.pool,
                    &lease,
                    &link,
                    build,
                    self.abandon.clone(),
                )
                .await;
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
        let programs = Arc::clone(&self.programs);
        let tests = match lease_tests(&lease, prepared, |name| programs.get(name).cloned()) {
            Ok(tests) => tests,
            Err(reason) => {
                link.give_back(&reason).await;
                anyhow::bail!(reason);
            }
        };
        let proceed = Arc::new(AtomicBool::new(true));
        let beating = tokio::spawn(heartbeat(
            self.client.clone(),
            lease.id,
            link.fence.clone(),
            Duration::from_secs_f64(lease.heartbeat_seconds.max(0.1)),
            Arc::clone(&proceed),
        ));
        let reached = self.run_chunks(&lease, &link, &tests, &proceed).await;
        beating.abort();
        let at = reached?;
        let unhealthy = tests.program.as_ref().and_then(|p| p.unhealthy());
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

    /// Runs the lease's tests chunk by chunk, the next chunk running while
    /// the last one is reported (the threads do not wait for the
    /// coordinator's acknowledgement); returns how far the lease's tests
    /// are reported. Each chunk's size comes from the last one's rate. A
    /// program's reports ask for an audit this worker may run: one handed
    /// out runs before the next chunk starts, so a campaign's prefix held
    /// at an audited test waits for one chunk, not for this lease's end.
    /// Once `go_on` is false (a report's or heartbeat's answer: the
    /// campaign stopped) no test starts any more.
    async fn run_chunks(
        &mut self,
        lease: &Lease,
        link: &LeaseLink,
        tests: &LeaseTests,
        go_on: &Arc<AtomicBool>,
    ) -> anyhow::Result<u64> {
        let mut at = lease.resume_at;
        let mut chunk = first_chunk(
            self.chunks.get(lease.campaign_id),
            self.threads,
            lease.end.saturating_sub(at),
            lease.seconds_per_test,
        );
        let pool = Arc::clone(&self.pool);
        let mut running = (at < lease.end && !self.stopping())
            .then(|| tests.start(&pool, lease, (at, chunk), go_on));
        while let Some(RunningChunk {
            from,
            to,
            started,
            handle,
        }) = running.take()
        {
            let ran = handle.await?;
            let seconds = started.elapsed().as_secs_f64();
            if ran.end == from {
                // The program turned unhealthy, or the campaign stopped,
                // before this chunk ran.
                break;
            }
            self.run_pending_audit().await;
            if ran.end == to && to < lease.end && go_on.load(Ordering::Relaxed) && !self.stopping()
            {
                let rate = (ran.end - from) as f64 / seconds.max(1e-6);
                chunk = measured_chunk(rate, self.threads);
                self.chunks.set(lease.campaign_id, chunk);
                running = Some(tests.start(&pool, lease, (to, chunk), go_on));
            }
            // The chunk started meanwhile is the lease's last: this report
            // asks for the next lease, which is then in hand when that
            // chunk ends (one request per lease fewer).
            // A program's report while its lease's next chunk runs asks for
            // an audit to run before the chunk after. The lease's last
            // chunk asks nothing: its reports go as the tail, whose answer
            // nobody reads, and the worker's next claim takes audits first.
            let ask = match &running {
                Some(r) if r.to == lease.end => Ask::NextLease,
                Some(_) if tests.program.is_some() => Ask::Audit,
                _ => Ask::Nothing,
            };
            let parts = self.chunk_parts(lease, from, &ran, seconds, ask);
            self.summary.events += ran.events.len() as u64;
            if running.is_none() && ran.end == lease.end && !self.stopping() {
                // The lease's last chunk: its reports go while the threads
                // start the next lease (one tail at a time).
                if let Some(tail) = self.tail.take() {
                    self.summary.tests += tail.settle().await;
                }
                self.tail = Some(link.send_as_tail(parts, from));
                return Ok(lease.end);
            }
            let sent = link.send(&parts, from).await?;
            self.summary.tests += sent.accepted;
            at = sent.reported_to;
            if let Some(next) = sent.next_lease {
                match ask {
                    Ask::Audit => self.pending_audit = Some(next),
                    _ => self.next_lease = Some((next, Instant::now())),
                }
            }
            if !sent.proceed || at < to {
                // The campaign stopped, or the lease moved on: the chunk
                // started meanwhile starts no more tests and is left
                // unreported.
                go_on.store(false, Ordering::Relaxed);
                break;
            }
        }
        Ok(at)
    }

    /// Runs the audit a report's answer handed out, if there is one (a
    /// one-test lease, worked as any other).
    async fn run_pending_audit(&mut self) {
        let Some(audit) = self.pending_audit.take() else {
            return;
        };
        let id = audit.id;
        if let Err(e) = Box::pin(self.work(audit)).await {
            tracing::warn!(lease = id, error = %e, "an audit run was abandoned");
        }
    }

    /// The reports of a chunk's tests `from..ran.end`; the last asks for
    /// what `ask` says (unless the worker is stopping).
    fn chunk_parts(
        &self,
        lease: &Lease,
        from: u64,
        ran: &RangeRun,
        seconds: f64,
        ask: Ask,
    ) -> Vec<ResultReport> {
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
        let request = match ask {
            Ask::Nothing => None,
            Ask::NextLease => Some(self.lease_request()),
            Ask::Audit => Some(LeaseRequest {
                audits_only: true,
                ..self.lease_request()
            }),
        };
        if let (Some(request), false) = (request, self.stopping()) {
            if let Some(part) = parts.last_mut() {
                part.next_lease = Some(request);
            }
        }
        parts
    }
}
