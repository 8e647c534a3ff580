//! The tslg coordinator: stores scenario libraries and running
//! importance-sampling campaigns in SQLite, hands out ranges of tests to
//! workers as leases, and folds their results into each campaign's prefix
//! estimator until the stopping rule holds. See `docs/architecture.md`.
//!
//! # Layout
//!
//! Four layers; imports point down or sideways, never up, and no two files
//! import each other (`tests/it/architecture.rs` checks both).
//!
//! HTTP:
//! - `routes/`: the API, the dashboard and `/metrics`: parse, call the
//!   domain, answer; errors as problem+json (`routes/problem.rs`), tokens
//!   (`routes/auth.rs`), request latencies (`routes/latency.rs`).
//!
//! Domain:
//! - `campaign/`: a campaign's start, end, views, history, exported events,
//!   and the coordinator's copy of its tests.
//! - `report/`: what happens to a worker's report: shape, replays, audits,
//!   recording, the fold, adaptive stages, the pair's fold.
//! - `leasing/`: which lease a request gets, how many tests it holds, who
//!   may keep, report on or give back a lease.
//! - `builds/`: library builds, on the coordinator or on workers.
//! - `telemetry/`: `/metrics`, per-campaign series, request latencies and
//!   campaigns' rates.
//! - `workers.rs` (the workers seen), `identity.rs` (their credentials),
//!   `queue.rs` (how many workers the campaigns want), `work_signal.rs`
//!   (waking held lease requests), `state.rs` (the handlers' shared state), `validate.rs`
//!   (names), `error.rs` (the service's error), `config.rs` (settings).
//!
//! Rows:
//! - `store/`: one module per table family, its own error type, every SQL
//!   statement and the states they name (`store/states.rs`).
//! - `db/`: the SQLite database: one writer with group commit, a pool of
//!   readers, the migrations.

mod builds;
mod campaign;
mod config;
mod db;
mod error;
mod identity;
mod leasing;
mod queue;
mod report;
mod routes;
mod state;
mod store;
mod telemetry;
mod validate;
mod work_signal;
mod workers;

// The crate's surface is the coordinator itself: `serve` with its `Config`
// (or `Coordinator::open` then `Coordinator::serve`, to know it is ready),
// and the online backup the `tslg db backup` command runs. Everything else is
// internal to the coordinator (and documented where it helps a reader).
pub use config::Config;
pub use db::backup;

use anyhow::Context;
use std::future::Future;
use tokio::net::TcpListener;

/// A coordinator whose store is open and migrated, its stored cases
/// registered and its interrupted library builds resumed: ready to answer
/// as soon as it serves. Opening is the slow part of a start (tens of
/// milliseconds for a new database: the migrations, each with its fsync),
/// and where a bad configuration or database fails.
pub struct Coordinator {
    state: state::AppState,
}

impl Coordinator {
    /// Opens the coordinator `config` describes.
    pub async fn open(config: Config) -> anyhow::Result<Self> {
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
        db.read(store::user_cases::register_stored)
            .await
            .map_err(|e| anyhow::anyhow!("user-defined cases: {e}"))?;
        let state = state::AppState::new(db, config);
        builds::resume_builds(&state).await?;
        Ok(Self { state })
    }

    /// Serves on `listener` until `shutdown` completes, then finishes the
    /// requests in flight.
    pub async fn serve(
        self,
        listener: TcpListener,
        shutdown: impl Future<Output = ()> + Send + 'static,
    ) -> anyhow::Result<()> {
        let address = listener.local_addr()?;
        tracing::info!(%address, "coordinator listening");
        // Lease requests waiting for work end at once on shutdown, so the
        // graceful shutdown does not wait out their waits.
        let work = self.state.work.clone();
        let shutdown = async move {
            shutdown.await;
            work.close();
        };
        axum::serve(
            routes::problem_io::ProblemListener(listener),
            routes::router(self.state),
        )
        .with_graceful_shutdown(shutdown)
        .await
        .context("server error")
    }
}

/// Runs the coordinator on `listener` until `shutdown` completes, then
/// finishes the requests in flight ([`Coordinator::open`], then
/// [`Coordinator::serve`]).
pub async fn serve(
    listener: TcpListener,
    config: Config,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    Coordinator::open(config)
        .await?
        .serve(listener, shutdown)
        .await
}
