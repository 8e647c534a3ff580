//! Shared state of the request handlers.

use crate::builds::progress::BuildTracker;
use crate::config::Config;
use crate::db::Database;
use crate::report::tests_cache::SamplerCache;
use crate::telemetry::requests::Metrics;
use crate::telemetry::throughput::Throughput;
use crate::workers::WorkerRegistry;
use std::sync::Arc;
use tokio::sync::Semaphore;

/// Library pictures (SVG), drawn once per library.
pub type PictureCache = tokio::sync::Mutex<std::collections::HashMap<i64, Arc<String>>>;

/// The handlers' state: one shared allocation. axum clones the state
/// several times for every request (the route's service, each middleware,
/// the extractor); a struct of a dozen `Arc`s made each clone and drop a
/// dozen atomic counter updates on lines both cores share, about a
/// twentieth of the request threads' time under load (`perf`).
#[derive(Clone)]
pub struct AppState(Arc<Shared>);

impl std::ops::Deref for AppState {
    type Target = Shared;

    fn deref(&self) -> &Shared {
        &self.0
    }
}

pub struct Shared {
    pub db: Database,
    pub config: Arc<Config>,
    /// Test samplers of the campaigns, built once each.
    pub samplers: Arc<SamplerCache>,
    /// Library builds run one at a time: each already uses every core.
    pub builds: Arc<Semaphore>,
    /// How far the running library build has come.
    pub build_progress: Arc<BuildTracker>,
    /// The workers seen, from their lease requests.
    pub workers: Arc<WorkerRegistry>,
    /// Tests per second of the running campaigns.
    pub throughput: Arc<Throughput>,
    /// Library pictures, drawn once each.
    pub pictures: Arc<PictureCache>,
    /// Request latencies, for `/metrics`.
    pub metrics: Arc<Metrics>,
    /// Which tests are checked again, by a generator of this process.
    pub sampler: Arc<crate::report::secret_sample::Sampler>,
    /// What the replay checks did, for `/metrics`.
    pub replays: Arc<crate::report::replay_counts::ReplayCounts>,
    /// Wakes the lease requests that wait for work.
    pub work: crate::work_signal::WorkSignal,
    /// The workers' credentials checked so far.
    pub credentials: crate::identity::Credentials,
}

impl AppState {
    pub fn new(db: Database, config: Config) -> Self {
        let enrolment_required = config.enrolment == crate::config::Enrolment::Required;
        Self(Arc::new(Shared {
            db,
            config: Arc::new(config),
            samplers: Arc::new(SamplerCache::default()),
            builds: Arc::new(Semaphore::new(1)),
            build_progress: Arc::new(BuildTracker::default()),
            workers: Arc::new(WorkerRegistry::default()),
            throughput: Arc::new(Throughput::default()),
            metrics: Arc::new(Metrics::default()),
            pictures: Arc::default(),
            sampler: Arc::default(),
            replays: Arc::default(),
            work: Default::default(),
            credentials: crate::identity::Credentials::new(enrolment_required),
        }))
    }
}
