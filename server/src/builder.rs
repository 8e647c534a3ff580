//! Library builds: CPU work off the async runtime, one build at a time
//! (each already uses every core through rayon), status in the database.

use crate::state::AppState;
use crate::store::libraries::{self, Built};
use std::time::Instant;
use tslg_api::{CreateLibrary, SearchRequest, ThresholdRequest};
use tslg_method::library::{Library, LibraryRequest, SearchMethod, Threshold};
use tslg_method::registry::{open_case, ExposureSource};

/// The method's threshold and search from the request, validated.
pub fn library_request(req: &CreateLibrary) -> Result<LibraryRequest, String> {
    let threshold = match req.threshold {
        ThresholdRequest::Relative { m } => Threshold::Relative { m },
        ThresholdRequest::Absolute { gamma } => Threshold::Absolute { gamma },
    };
    threshold.validate().map_err(|e| e.to_string())?;
    let search = match req.search {
        SearchRequest::Exhaustive => SearchMethod::Exhaustive,
        SearchRequest::Multistart { starts, seed } => {
            if !(1..=100_000).contains(&starts) {
                return Err(format!("search.starts = {starts} must be in 1..=100000"));
            }
            SearchMethod::Multistart { starts, seed }
        }
    };
    Ok(LibraryRequest { threshold, search })
}

/// The exposure source of a request.
pub fn exposure_source(req: &CreateLibrary) -> ExposureSource {
    match &req.exposure {
        tslg_api::ExposureRequest::Builtin => ExposureSource::Builtin,
        tslg_api::ExposureRequest::Table { name, text } => ExposureSource::Table {
            name: name.clone(),
            text: text.clone(),
        },
    }
}

fn build(req: &CreateLibrary) -> Result<(Library, f64), String> {
    let started = Instant::now();
    let case = open_case(&req.case, req.preset.as_deref(), &exposure_source(req))
        .map_err(|e| e.to_string())?;
    let request = library_request(req)?;
    let library = case
        .build_library(&req.surrogate, &request)
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
    let row = libraries::get(&state.db.read, id).await?;
    let req: CreateLibrary = serde_json::from_str(&row.request)?;
    tracing::info!(library = id, case = %req.case, "library build started");
    let outcome = tokio::task::spawn_blocking(move || build(&req)).await?;
    match outcome {
        Ok((library, seconds)) => {
            let body = library.to_json();
            libraries::mark_ready(
                &state.db.write,
                id,
                &Built {
                    body: &body,
                    size: library.size(),
                    sm_evaluations: library.search.sm_evaluations,
                    mu_s: library.mu_s,
                    w: library.w,
                    seconds,
                },
            )
            .await?;
            tracing::info!(
                library = id,
                size = library.size(),
                seconds,
                "library ready"
            );
        }
        Err(reason) => {
            libraries::mark_failed(&state.db.write, id, &reason).await?;
            tracing::warn!(library = id, %reason, "library build failed");
        }
    }
    Ok(())
}

/// Restarts the builds a stopped coordinator left unfinished.
pub async fn resume_builds(state: &AppState) -> anyhow::Result<()> {
    for row in libraries::building(&state.db.read).await? {
        tracing::info!(library = row.id, "resuming an unfinished library build");
        spawn_build(state.clone(), row.id);
    }
    Ok(())
}
