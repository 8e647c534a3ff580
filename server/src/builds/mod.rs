//! Library builds: on the coordinator ([`local`]), or on workers
//! ([`on_workers`]: the surrogate's runs leased cell by cell as a campaign
//! of method `enumerate`, or the whole build leased to one worker,
//! [`whole`]), with their progress ([`progress`]) and the request checked
//! first ([`request`]).

pub mod local;
pub mod on_workers;
pub mod progress;
pub mod request;
pub mod start;
pub mod whole;

use crate::state::AppState;
use crate::store::libraries;

/// Restarts the builds a stopped coordinator left unfinished.
pub async fn resume_builds(state: &AppState) -> anyhow::Result<()> {
    for row in state.db.read(libraries::building).await? {
        // A build on workers goes on as its campaign does; one whose
        // campaign stopped while the coordinator was down is recorded now.
        if let Some(campaign) = on_workers::campaign_of(state, row.id)
            .await
            .map_err(|e| anyhow::anyhow!("library {}: {e}", row.id))?
        {
            on_workers::finish(state, campaign.id)
                .await
                .map_err(|e| anyhow::anyhow!("library {}: {e}", row.id))?;
            continue;
        }
        tracing::info!(library = row.id, "resuming an unfinished library build");
        local::spawn_build(state.clone(), row.id);
    }
    Ok(())
}
