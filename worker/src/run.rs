//! The worker loop: take a lease, work it ([`crate::lease_work`]: its tests
//! run on the rayon pool in chunks, each chunk reported, which also keeps
//! the lease alive, with heartbeats while a chunk runs); with no work, ask
//! with a wait the coordinator holds until work appears (long polling),
//! and back off with jitter when it answers at once or cannot be reached.
//! On shutdown the running chunk is finished and reported and the rest of
//! the lease is given back. A lease's last chunk is reported while the
//! next lease runs (see [`crate::sending`]).

use crate::backoff::Backoff;
use crate::config::{WorkerConfig, MIN_CLAIM_WAIT};
use crate::credential_file;
use crate::worker::{Worker, WorkerSummary};
use rand::SeedableRng;
use std::future::Future;
use std::sync::Arc;
use std::time::Instant;
use tslg_client::{CallError, Client};

/// How long a worker whose shutdown grace is over still tries to deliver
/// its last reports and give its leases back.
const LAST_WORDS: std::time::Duration = std::time::Duration::from_secs(8);

/// Runs a worker until `shutdown` completes (or, with
/// `exit_when_idle_seconds`, until there has been no work that long).
pub async fn run(
    config: WorkerConfig,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> anyhow::Result<WorkerSummary> {
    config.validate()?;
    let mut worker = Worker::start(&config, shutdown).await?;
    tracing::info!(
        worker = %worker.name,
        threads = worker.threads,
        server = %config.server,
        "worker started"
    );
    // The work, then the last reports; but once the shutdown's grace is
    // over, at most LAST_WORDS more, whatever the coordinator does: a
    // platform's kill deadline (Kubernetes' terminationGracePeriodSeconds,
    // SLURM's KillWait) must find the worker gone, not stuck in a retry.
    // Reports cut off here are not lost: their lease expires and is run
    // again.
    let mut abandon = worker.abandon.clone();
    let served = tokio::select! {
        served = async {
            serve(&mut worker, &config).await?;
            worker.finish().await;
            anyhow::Ok(())
        } => served,
        () = async {
            let _ = abandon.wait_for(|a| *a).await;
            tokio::time::sleep(LAST_WORDS).await;
        } => {
            tracing::warn!(
                seconds = LAST_WORDS.as_secs_f64(),
                "the coordinator did not take the last reports after the grace: leaving without them"
            );
            Ok(())
        }
    };
    // The programs' idle processes and their helpers end with the worker
    // (an exiting process does not drop them).
    worker.programs.shutdown();
    served?;
    // Out of the fleet at once: the queue an autoscaler reads stops
    // counting this worker (otherwise a minute after its last request). A
    // worker that never registered was never counted; a coordinator that
    // does not answer soon only counts it a minute longer.
    if worker.client.secret_of(&worker.name).is_some() {
        let leaving = worker.client.leave(&worker.name);
        match tokio::time::timeout(std::time::Duration::from_secs(5), leaving).await {
            Ok(Ok(())) => {}
            Ok(Err(e)) => {
                tracing::warn!(error = %e, "could not tell the coordinator this worker leaves")
            }
            Err(_) => tracing::warn!("the coordinator did not answer this worker's leaving in 5 s"),
        }
    }
    let WorkerSummary {
        leases,
        tests,
        events,
    } = worker.summary;
    tracing::info!(worker = %worker.name, leases, tests, events, "worker stopped");
    Ok(worker.summary)
}

/// Takes and works leases until the worker stops, or has been idle for
/// `exit_when_idle_seconds`; an error is one that asking again cannot
/// mend (a refused token, a flagged worker, a coordinator of another
/// release).
async fn serve(worker: &mut Worker, config: &WorkerConfig) -> anyhow::Result<()> {
    let mut idle = Backoff::new(0.05, config.max_backoff_seconds);
    let mut trouble = Backoff::new(0.2, config.max_backoff_seconds.max(5.0));
    let mut rng = rand::rngs::StdRng::from_os_rng();
    let mut idle_since = Instant::now();
    // The coordinator's release is checked before the first lease and after
    // every outage (it may come back upgraded): both speak one version of
    // the lease protocol.
    let mut version_checked = false;
    let mut registered = false;
    while !worker.stopping() {
        if !version_checked {
            match same_release(&worker.client).await {
                Ok(checked) => version_checked = checked?,
                Err(e) => {
                    tracing::warn!(error = %e, "cannot reach the coordinator");
                    worker.pause(trouble.next_wait(&mut rng)).await;
                    continue;
                }
            }
        }
        if !registered {
            match register(worker, config).await? {
                Ok(()) => registered = true,
                Err(CallError::Refused {
                    status: 401,
                    detail,
                }) => {
                    anyhow::bail!("the coordinator refused this worker's token: {detail}");
                }
                Err(CallError::Refused { status, detail }) => {
                    anyhow::bail!(
                        "the coordinator refused to register this worker ({status}): {detail}"
                    );
                }
                Err(e) => {
                    tracing::warn!(error = %e, "cannot register with the coordinator");
                    worker.pause(trouble.next_wait(&mut rng)).await;
                    continue;
                }
            }
        }
        if worker.programs.any_rested() {
            let programs = Arc::clone(&worker.programs);
            tokio::task::spawn_blocking(move || programs.probe_rested()).await?;
        }
        let wait = claim_wait(config, idle_since, !worker.programs.unhealthy().is_empty());
        let asked = Instant::now();
        let claimed = match worker.held_lease().await {
            Some(lease) => Ok(Some(lease)),
            None => worker.claim(wait).await,
        };
        // The coordinator held the request (it waited for work): ask again
        // at once. One that answered sooner than half the shortest wait (its
        // cap below that, or the worker's wait 0 or cut short by the idle
        // exit) is polled with backoff.
        let held = wait > 0.0 && asked.elapsed().as_secs_f64() >= wait.min(MIN_CLAIM_WAIT) / 2.0;
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
    Ok(())
}

/// Registers the worker for a credential of its own (docs/api.md, worker
/// identity): its name is the one asked for, or `NAME.k` when that name
/// was issued before (this worker's own, before a restart, included). With
/// `--credential-file`, a credential kept there is used instead, and a new
/// one is kept there. `Err` for a file that cannot be read or written.
async fn register(
    worker: &mut Worker,
    config: &WorkerConfig,
) -> anyhow::Result<Result<(), CallError>> {
    let file = config.credential_file.as_deref();
    if let Some(stored) = file
        .map(|path| credential_file::load(path, &config.server))
        .transpose()?
        .flatten()
    {
        tracing::info!(worker = %stored.name, issued_at = %stored.issued_at, "credential read from its file");
        worker.client.use_credential(&stored.name, &stored.secret);
        worker.name = stored.name;
        return Ok(Ok(()));
    }
    let enrolment = match (&config.enrolment, &config.enrolment_file) {
        (Some(secret), _) => Some(secret.trim().to_owned()),
        (None, Some(path)) => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| anyhow::anyhow!("--enrolment-file {}: {e}", path.display()))?;
            let secret = text.lines().next().unwrap_or("").trim().to_owned();
            anyhow::ensure!(
                !secret.is_empty(),
                "--enrolment-file {}: the file is empty",
                path.display()
            );
            Some(secret)
        }
        (None, None) => None,
    };
    let registered = worker
        .client
        .register_enrolled(&worker.name, enrolment.as_deref())
        .await;
    let issued = match registered {
        Ok(issued) => issued,
        Err(e) => return Ok(Err(e)),
    };
    if issued.name != worker.name {
        tracing::info!(
            asked = %worker.name,
            worker = %issued.name,
            "the name asked for was issued before: registered under the next free one"
        );
    }
    worker.name = issued.name.clone();
    if let Some(path) = file {
        credential_file::save(path, &config.server, &issued)?;
    }
    Ok(Ok(()))
}

/// Asks the coordinator for its release: `Err` when it cannot be reached,
/// `Ok(Err)` when it runs another release than this worker.
async fn same_release(client: &Client) -> Result<anyhow::Result<bool>, CallError> {
    let health = client.health().await?;
    Ok(if health.version == env!("CARGO_PKG_VERSION") {
        Ok(true)
    } else {
        Err(anyhow::anyhow!(
            "the coordinator runs tslg {}, this worker tslg {}: upgrade workers and \
             coordinator together (docs/operations.md)",
            health.version,
            env!("CARGO_PKG_VERSION")
        ))
    })
}

/// How long a request for work waits at the coordinator (long polling):
/// the configured wait, but not past the idle exit, and a second at most
/// while a program rests (it is probed between requests).
fn claim_wait(config: &WorkerConfig, idle_since: Instant, program_resting: bool) -> f64 {
    let mut wait = config
        .exit_when_idle_seconds
        .map_or(config.claim_wait_seconds, |s| {
            config
                .claim_wait_seconds
                .min((s - idle_since.elapsed().as_secs_f64()).max(0.0))
        });
    if program_resting {
        wait = wait.min(1.0);
    }
    wait
}
