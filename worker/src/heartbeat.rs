//! Keeping a lease alive while its tests or its build run.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;
use tslg_api::LeaseFence;
use tslg_client::{CallError, Client};

/// Heartbeats `lease` every `every` until aborted; clears `proceed` (and
/// ends) once the coordinator says the lease is gone or its campaign
/// stopped. A heartbeat that is not delivered is tried again next period.
pub async fn heartbeat(
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
