//! Library builds on the coordinator: CPU work off the async runtime, one
//! build at a time (each already uses every core through rayon), status in
//! the database.

use super::request::build_request;
use crate::state::AppState;
use crate::store::libraries::{self, Built};
use std::time::Instant;
use tslg_api::CreateLibrary;
use tslg_method::cases::open_case;
use tslg_method::progress::Progress;
use tslg_method::registry::BuiltLibrary;

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
        .build_library_observed(&tslg_api::vehicle_spec(&req.surrogate), &request, progress)
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
