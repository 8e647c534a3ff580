//! Library builds: CPU work off the async runtime, one build at a time
//! (each already uses every core through rayon), status in the database.

use crate::state::AppState;
use crate::store::libraries::{self, Built};
use std::time::Instant;
use tslg_api::{CreateLibrary, SearchRequest};
use tslg_method::cases::open_case;
use tslg_method::progress::Progress;
use tslg_method::registry::{BuildRequest, BuiltLibrary, LibrarySearch};

/// The method's threshold and search from the request, validated; what the
/// request leaves out is the case's default.
pub fn build_request(req: &CreateLibrary) -> Result<BuildRequest, String> {
    let threshold = req.threshold.map(tslg_client::wire::threshold);
    if let Some(t) = threshold {
        t.validate().map_err(|e| e.to_string())?;
    }
    if let Some(SearchRequest::Multistart { starts, .. }) = req.search {
        if !(1..=100_000).contains(&starts) {
            return Err(format!("search.starts = {starts} must be in 1..=100000"));
        }
    }
    let search = req.search.map(tslg_client::wire::library_search);
    if let Some(LibrarySearch::Policy(solver)) = search {
        solver.validate()?;
    }
    Ok(BuildRequest { threshold, search })
}

fn build(req: &CreateLibrary, progress: &Progress) -> Result<(BuiltLibrary, f64), String> {
    let started = Instant::now();
    let case = open_case(
        &req.case,
        req.preset.as_deref(),
        &tslg_client::wire::exposure_source(&req.exposure),
    )
    .map_err(|e| e.to_string())?;
    let request = build_request(req)?;
    let library = case
        .build_library_observed(&req.surrogate, &request, progress)
        .map_err(|e| e.to_string())?;
    Ok((library, started.elapsed().as_secs_f64()))
}

/// Builds library `id` in the background and records the result.
pub fn spawn_build(state: AppState, id: i64) {
    tokio::spawn(async move {
        if let Err(e) = run_build(&state, id).await {
            tracing::error!(library = id, error = %e, "library build could not be recorded");
        }
    });
}

async fn run_build(state: &AppState, id: i64) -> anyhow::Result<()> {
    let _permit = state.builds.acquire().await?;
    let row = state.db.read(move |conn| libraries::get(conn, id)).await?;
    let req: CreateLibrary = serde_json::from_str(&row.request)?;
    tracing::info!(library = id, case = %req.case, "library build started");
    let progress = state.build_progress.begin(id);
    let outcome = tokio::task::spawn_blocking(move || build(&req, &progress)).await;
    // The progress stays until the outcome is recorded: the library is
    // `building` until then.
    let recorded = record_build(state, id, outcome).await;
    state.build_progress.end(id);
    recorded
}

async fn record_build(
    state: &AppState,
    id: i64,
    outcome: Result<Result<(BuiltLibrary, f64), String>, tokio::task::JoinError>,
) -> anyhow::Result<()> {
    match outcome? {
        Ok((library, seconds)) => {
            let size = library.size;
            state
                .db
                .write(move |conn| libraries::mark_ready(conn, id, &Built::of(&library, seconds)))
                .await?;
            // Its pending campaigns run now.
            state.work.announce();
            tracing::info!(library = id, size, seconds, "library ready");
        }
        Err(reason) => {
            let failed = reason.clone();
            state
                .db
                .write(move |conn| libraries::mark_failed(conn, id, &failed))
                .await?;
            tracing::warn!(library = id, %reason, "library build failed");
        }
    }
    Ok(())
}

/// Restarts the builds a stopped coordinator left unfinished.
pub async fn resume_builds(state: &AppState) -> anyhow::Result<()> {
    for row in state.db.read(libraries::building).await? {
        // A build on workers goes on as its campaign does; one whose
        // campaign stopped while the coordinator was down is recorded now.
        if let Some(campaign) = crate::enumeration::campaign_of(state, row.id)
            .await
            .map_err(|e| anyhow::anyhow!("library {}: {e}", row.id))?
        {
            crate::enumeration::finish(state, campaign.id)
                .await
                .map_err(|e| anyhow::anyhow!("library {}: {e}", row.id))?;
            continue;
        }
        tracing::info!(library = row.id, "resuming an unfinished library build");
        spawn_build(state.clone(), row.id);
    }
    Ok(())
}
