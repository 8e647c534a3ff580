//! Library builds a worker runs whole (campaigns of method `build`: a
//! multistart search, a car-following policy), which the coordinator
//! leases to one worker when it sends builds to workers.

use crate::heartbeat::heartbeat;
use crate::prepared::WholeBuild;
use crate::sending::LeaseLink;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::watch;
use tslg_api::{Lease, LibraryUpload};
use tslg_client::Client;

/// Longest failure reason an upload carries.
const MAX_REASON: usize = 2000;

/// Builds the library on every thread of `pool`, heartbeating meanwhile,
/// and uploads it; a build the coordinator no longer wants (cancelled, or
/// the lease lost) is dropped. A build that fails is uploaded as a failure
/// with its reason: it is deterministic and would fail the same way on any
/// worker. A build cut off by the worker's shutdown (its programs stopped,
/// or the shutdown's grace over while it runs: `abandon`) is given back for
/// another worker, not uploaded as a failure.
pub async fn build_whole(
    client: &Client,
    pool: &Arc<rayon::ThreadPool>,
    lease: &Lease,
    link: &LeaseLink,
    build: Arc<WholeBuild>,
    mut abandon: watch::Receiver<bool>,
) -> anyhow::Result<()> {
    let proceed = Arc::new(AtomicBool::new(true));
    let beating = tokio::spawn(heartbeat(
        client.clone(),
        lease.id,
        link.fence.clone(),
        Duration::from_secs_f64(lease.heartbeat_seconds.max(0.1)),
        Arc::clone(&proceed),
    ));
    tracing::info!(
        lease = lease.id,
        campaign = lease.campaign_id,
        "building a library"
    );
    let started = Instant::now();
    let pool = Arc::clone(pool);
    let running = tokio::task::spawn_blocking(move || pool.install(|| build.run()));
    let built = tokio::select! {
        built = running => built,
        () = async { let _ = abandon.wait_for(|a| *a).await; } => {
            // The build thread is left to the process's exit.
            beating.abort();
            link.give_back("the worker is shutting down: its grace ended during a library build")
                .await;
            return Ok(());
        }
    };
    beating.abort();
    let seconds = started.elapsed().as_secs_f64();
    if !proceed.load(Ordering::Relaxed) {
        tracing::info!(lease = lease.id, "library build no longer wanted");
        return Ok(());
    }
    let stopping = *link.stop.borrow();
    let upload = match built? {
        Ok(file) => LibraryUpload::of_file(&link.fence, seconds, &file),
        Err(_) if stopping => {
            // Its programs were stopped under it: not the build's failure.
            link.give_back("the worker is shutting down").await;
            return Ok(());
        }
        Err(reason) => {
            LibraryUpload::of_failure(&link.fence, seconds, truncate(&reason, MAX_REASON))
        }
    };
    client.upload_library(lease.id, &upload).await?;
    tracing::info!(lease = lease.id, seconds, "library uploaded");
    Ok(())
}

/// `text` cut to at most `bytes` bytes on a character boundary.
fn truncate(text: &str, bytes: usize) -> String {
    let mut end = text.len().min(bytes);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    text[..end].to_owned()
}
