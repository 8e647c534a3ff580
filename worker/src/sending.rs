//! Sending a chunk's reports to the coordinator, and giving a lease back.
//!
//! A chunk's reports go in index order and each waits for its
//! acknowledgement (the coordinator folds a campaign's prefix in order and
//! a lease's reports must follow its resume point). The last chunk of a
//! lease is sent as a *tail*, a task of its own, so the worker's threads
//! start the next lease instead of waiting for the coordinator to check
//! and store what they found: on a high-event campaign those checks take
//! a large part of a second per chunk.

use crate::backoff::Backoff;
use crate::report_parts::truncated;
use rand::SeedableRng;
use tokio::sync::watch;
use tokio::task::JoinHandle;
use tslg_api::{Lease, LeaseFence, LeaseRelease, ResultAck, ResultReport, MAX_INVALID_REASON};
use tslg_client::{CallError, Client};

/// Where a lease's reports go.
#[derive(Clone)]
pub struct LeaseLink {
    pub client: Client,
    pub lease: i64,
    pub fence: LeaseFence,
    /// Set when the worker shuts down: retries give up sooner.
    pub stop: watch::Receiver<bool>,
}

/// What the coordinator acknowledged of a chunk's reports.
#[derive(Debug, Clone, PartialEq)]
pub struct Sent {
    /// Tests the coordinator counted (a repeated report counts once).
    pub accepted: u64,
    /// The lease's tests are reported up to here.
    pub reported_to: u64,
    /// `false` once the coordinator says to stop (the campaign converged or
    /// was cancelled, or the lease moved on).
    pub proceed: bool,
    /// The worker's next lease, when a report asked for it and got one.
    pub next_lease: Option<Lease>,
}

impl LeaseLink {
    /// Sends `parts` in order, stopping at the first that says not to
    /// proceed. A refusal will not change by waiting: the rest of the lease
    /// is given back at once, saying why, instead of letting it expire.
    pub async fn send(&self, parts: &[ResultReport], from: u64) -> Result<Sent, CallError> {
        let mut sent = Sent {
            accepted: 0,
            reported_to: from,
            proceed: true,
            next_lease: None,
        };
        for part in parts {
            match self.report(part).await {
                Ok(ResultAck {
                    accepted,
                    proceed,
                    next_lease,
                    ..
                }) => {
                    sent.accepted += accepted;
                    sent.next_lease = next_lease.or(sent.next_lease.take());
                    sent.reported_to = part.to;
                    if !proceed {
                        sent.proceed = false;
                        break;
                    }
                }
                Err(e) => {
                    if let CallError::Refused { status, detail } = &e {
                        self.give_back(&format!("report refused ({status}): {detail}"))
                            .await;
                    }
                    return Err(e);
                }
            }
        }
        Ok(sent)
    }

    /// Sends `parts` from a task of its own (see the module's doc).
    pub fn send_as_tail(&self, parts: Vec<ResultReport>, from: u64) -> Tail {
        let link = self.clone();
        Tail(tokio::spawn(async move { link.send(&parts, from).await }))
    }

    /// Reports, retrying while the coordinator is unreachable: the same
    /// report twice is acknowledged once, so a retry cannot double-count.
    async fn report(&self, report: &ResultReport) -> Result<ResultAck, CallError> {
        let mut backoff = Backoff::new(0.2, 5.0);
        let mut rng = rand::rngs::StdRng::from_os_rng();
        let mut tries = 0;
        loop {
            match self.client.report(self.lease, report).await {
                Err(CallError::Transient(e)) => {
                    tries += 1;
                    if *self.stop.borrow() && tries > 5 {
                        return Err(CallError::Transient(e));
                    }
                    tracing::warn!(lease = self.lease, error = %e, "result not delivered; retrying");
                    tokio::time::sleep(backoff.next_wait(&mut rng)).await;
                }
                other => return other,
            }
        }
    }

    /// Releases the rest of the lease for another worker at once, telling
    /// the coordinator `reason` (it logs it and shows it with the worker).
    pub async fn give_back(&self, reason: &str) {
        let release = LeaseRelease {
            worker: self.fence.worker.clone(),
            attempt: self.fence.attempt,
            key: self.fence.key.clone(),
            reason: Some(truncated(&sanitised(reason), MAX_INVALID_REASON)),
        };
        match self.client.release(self.lease, &release).await {
            Ok(()) => tracing::warn!(lease = self.lease, reason, "lease given back"),
            Err(e) => tracing::warn!(
                lease = self.lease,
                reason,
                error = %e,
                "could not give the lease back; it expires by itself"
            ),
        }
    }
}

/// The reports of a lease's last chunk, under way.
pub struct Tail(JoinHandle<Result<Sent, CallError>>);

impl Tail {
    /// Waits for the tail; the tests the coordinator counted (0 when it
    /// failed, which is logged: the lease's rest was given back or expires).
    pub async fn settle(self) -> u64 {
        match self.0.await {
            Ok(Ok(sent)) => sent.accepted,
            Ok(Err(e)) => {
                tracing::warn!(error = %e, "the last reports of a lease were not accepted");
                0
            }
            Err(e) => {
                tracing::warn!(error = %e, "the task sending a lease's last reports failed");
                0
            }
        }
    }
}

/// The fence of `lease` for worker `name`.
pub fn fence_of(lease: &Lease, name: &str) -> LeaseFence {
    LeaseFence {
        worker: name.to_owned(),
        attempt: lease.attempt,
        key: lease.key.clone(),
    }
}

/// `text` with control characters (but new lines) replaced by spaces, as
/// the coordinator takes reasons.
fn sanitised(text: &str) -> String {
    text.chars()
        .map(|c| if c.is_control() && c != '\n' { ' ' } else { c })
        .collect()
}
