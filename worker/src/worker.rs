//! A worker's state between leases: its client, threads and programs, what
//! it has done, and the lease or reports it carries from one lease to the
//! next; asking for work and pausing, both of which end on shutdown.

use crate::chunks::ChunkSizes;
use crate::config::WorkerConfig;
use crate::external::{ProgramSettings, Programs};
use crate::prepared::Cache;
use crate::sending::{fence_of, LeaseLink, Tail};
use std::future::Future;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::watch;
use tslg_api::{Lease, LeaseRequest};
use tslg_client::{CallError, Client};

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

/// A running worker.
pub struct Worker {
    pub client: Client,
    pub name: String,
    pub threads: usize,
    pub pool: Arc<rayon::ThreadPool>,
    pub cache: Cache,
    pub programs: Arc<Programs>,
    pub stop: watch::Receiver<bool>,
    /// Turns true when the shutdown's grace is over: work still running
    /// is given back rather than waited for.
    pub abandon: watch::Receiver<bool>,
    pub summary: WorkerSummary,
    /// The last lease's final reports, still being sent.
    pub tail: Option<Tail>,
    /// The next lease, taken with the report of a lease's last chunk but
    /// one (`next_lease`), and when: the worker asks no separate request
    /// for it.
    pub next_lease: Option<(Lease, Instant)>,
    /// The chunk sizes measured on recent campaigns, which their next
    /// leases start from ([`crate::chunks::first_chunk`]).
    pub chunks: ChunkSizes,
    /// An audit's run handed out with a report, to run before the next
    /// chunk (or, at a lease's end, before the next lease).
    pub pending_audit: Option<Lease>,
}

impl Worker {
    /// Starts the worker `config` describes: its thread pool and its
    /// programs; `shutdown` completing stops the programs and the worker.
    pub async fn start(
        config: &WorkerConfig,
        shutdown: impl Future<Output = ()> + Send + 'static,
    ) -> anyhow::Result<Self> {
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
        // Blank lines of TSLG_VUT_EXEC (a YAML block's last newline) are
        // no programs.
        let specs: Vec<String> = config
            .vut_exec
            .iter()
            .filter(|spec| !spec.trim().is_empty())
            .cloned()
            .collect();
        let programs = tokio::task::spawn_blocking(move || Programs::start(&specs, &settings))
            .await?
            .map_err(anyhow::Error::msg)?;
        let programs = Arc::new(programs);
        let (tx, stop) = watch::channel(false);
        let (grace_over, abandon) = watch::channel(false);
        let stopping = Arc::clone(&programs);
        let grace = Duration::from_secs_f64(config.grace_seconds);
        tokio::spawn(async move {
            shutdown.await;
            stopping.stop();
            let _ = tx.send(true);
            // The tests running may finish within the grace; then their
            // programs are killed and the tests given back. (The task ends
            // with the runtime when the worker is done sooner.)
            tokio::time::sleep(grace).await;
            tracing::warn!(
                grace_seconds = grace.as_secs_f64(),
                "the shutdown's grace is over: the tests still running are given back"
            );
            stopping.abort();
            let _ = grace_over.send(true);
        });
        Ok(Worker {
            client: Client::new(&config.server, config.token.clone())?,
            name,
            threads,
            pool: Arc::new(pool),
            cache: Cache::with_host(
                Arc::clone(&programs) as Arc<dyn tslg_method::external::ProgramHost>
            ),
            programs,
            stop,
            abandon,
            summary: WorkerSummary::default(),
            tail: None,
            next_lease: None,
            chunks: ChunkSizes::default(),
            pending_audit: None,
        })
    }

    /// Whether the worker is shutting down.
    pub fn stopping(&self) -> bool {
        *self.stop.borrow()
    }

    /// Where `lease`'s reports go.
    pub fn link(&self, lease: &Lease) -> LeaseLink {
        LeaseLink {
            client: self.client.clone(),
            lease: lease.id,
            fence: fence_of(lease, &self.name),
            stop: self.stop.clone(),
        }
    }

    /// The next lease taken with a report, still the worker's: one held
    /// longer than its heartbeat period (a long last chunk, a slow
    /// coordinator) is kept alive first, and dropped if the coordinator
    /// says it is gone or its campaign stopped.
    pub async fn held_lease(&mut self) -> Option<Lease> {
        if let Some(audit) = self.pending_audit.take() {
            return Some(audit);
        }
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
    pub fn lease_request(&self) -> LeaseRequest {
        LeaseRequest {
            worker: self.name.clone(),
            threads: self.threads as u32,
            include_tests: false,
            offers: self.programs.offers(),
            unhealthy: self.programs.unhealthy(),
            max_tests: None,
            wait_seconds: None,
            audits_only: false,
            noisy: self.programs.noisy_offers(),
        }
    }

    /// Asks for a lease, waiting at the coordinator up to `wait` seconds
    /// for one; `None` at once on shutdown. (A lease granted just as the
    /// request is dropped is nobody's: it expires and is handed out again.)
    pub async fn claim(&mut self, wait: f64) -> Result<Option<Lease>, CallError> {
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
    pub async fn pause(&mut self, wait: Duration) {
        let mut stop = self.stop.clone();
        tokio::select! {
            _ = tokio::time::sleep(wait) => {}
            _ = stop.wait_for(|s| *s) => {}
        }
    }

    /// Ends the worker's business with the coordinator: the last reports
    /// are delivered, and a lease taken with a report but never started
    /// (an audit's run too) is given back, so another worker gets it at
    /// once rather than when it expires.
    pub async fn finish(&mut self) {
        if let Some(tail) = self.tail.take() {
            self.summary.tests += tail.settle().await;
        }
        let unstarted = self.next_lease.take().map(|(lease, _)| lease);
        for lease in unstarted.into_iter().chain(self.pending_audit.take()) {
            self.link(&lease)
                .give_back("the worker is shutting down")
                .await;
        }
    }
}
