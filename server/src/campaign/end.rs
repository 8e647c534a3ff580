//! Ending a campaign on request: cancelling a pending or running one (with
//! the other campaign of its pair, and the library build it runs), and
//! deleting a stopped one with everything recorded for it. The
//! coordinator's copies of its tests and its rate go with it.

use crate::error::ServiceError;
use crate::state::AppState;
use crate::store::campaigns::CampaignRow;
use crate::store::{deletion, pairs};

/// Cancels campaign `id` (and its pair's other campaign); its leases are
/// told to stop. A library build's enumeration cancelled fails the build.
pub async fn cancel(state: &AppState, id: i64) -> Result<CampaignRow, ServiceError> {
    let row = state.db.write(move |conn| pairs::cancel(conn, id)).await?;
    forget(state, std::iter::once(id).chain(row.paired_with));
    crate::builds::on_workers::finish(state, id).await?;
    Ok(row)
}

/// Deletes stopped campaign `id` and everything recorded for it (with the
/// other campaign of its pair).
pub async fn delete(state: &AppState, id: i64) -> Result<(), ServiceError> {
    let partner = state
        .db
        .write(move |conn| deletion::delete_campaign(conn, id))
        .await?;
    forget(state, std::iter::once(id).chain(partner));
    tracing::info!(campaign = id, "campaign deleted");
    Ok(())
}

/// Drops what the coordinator keeps in memory of `campaigns`.
fn forget(state: &AppState, campaigns: impl IntoIterator<Item = i64>) {
    for id in campaigns {
        state.samplers.forget(id);
        state.throughput.forget(id);
    }
}
