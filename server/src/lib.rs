//! The tslg coordinator: stores scenario libraries and running
//! importance-sampling campaigns in SQLite, hands out ranges of tests to
//! workers as leases, and folds their results into each campaign's prefix
//! estimator until the stopping rule holds. See `docs/architecture.md`.

pub mod audit;
pub mod build_progress;
pub mod builder;
pub mod campaign_start;
pub mod config;
pub mod db;
pub mod error;
pub mod history;
pub mod latency;
pub mod lease_size;
pub mod metrics;
pub mod problem_io;
pub mod replay_check;
pub mod report_check;
pub mod reporting;
pub mod routes;
pub mod sampler_cache;
pub mod state;
pub mod store;
pub mod throughput;
pub mod validate;
pub mod workers;

pub use config::Config;

use anyhow::Context;
use std::future::Future;
use tokio::net::TcpListener;

/// Runs the coordinator on `listener` until `shutdown` completes, then
/// finishes the requests in flight.
pub async fn serve(
    listener: TcpListener,
    config: Config,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    config.validate()?;
    if config.max_body_bytes < tslg_api::MAX_REPORT_BYTES {
        tracing::warn!(
            max_body_bytes = config.max_body_bytes,
            largest_report = tslg_api::MAX_REPORT_BYTES,
            "the body limit is below the largest report a worker may send: reports with many \
             events or invalid tests will be refused (413) and their leases released"
        );
    }
    let db = db::Database::open(&config.database_url, config.durability).await?;
    store::reports::move_legacy_events(&db).await?;
    let state = state::AppState::new(db, config);
    builder::resume_builds(&state).await?;
    let address = listener.local_addr()?;
    tracing::info!(%address, "coordinator listening");
    axum::serve(problem_io::ProblemListener(listener), routes::router(state))
        .with_graceful_shutdown(shutdown)
        .await
        .context("server error")
}
