//! The service run in this process for `tslg demo` and `tslg reproduce`: a
//! coordinator on a scratch (or kept) SQLite file with local workers, a
//! library built through the API, and the exact answer computed beside it.

use crate::commands::library::wait_for_library;
use crate::commands::progress::CampaignBars;
use crate::service::LocalService;
use std::path::{Path, PathBuf};
use tslg_api::{CampaignView, CreateLibrary, ExposureRequest, LibraryStatus, LibraryView, Outside};
use tslg_client::wire::exposure_source;
use tslg_client::Client;
use tslg_method::cases::open_case;
use tslg_method::exact::ExactReport;
use tslg_method::registry::CaseError;
use tslg_method::sampling::OutsideSpread;

/// A local coordinator and its workers; the scratch database is removed on
/// [`Local::stop`].
pub struct Local {
    pub service: LocalService,
    pub database: PathBuf,
    /// Threads of each worker: the cores shared among the workers.
    pub threads: usize,
    scratch: Option<PathBuf>,
}

impl Local {
    /// Starts `workers` workers sharing this machine's cores, on `database`
    /// or, when `None`, on a scratch file named after `label`.
    pub async fn start(
        database: Option<&Path>,
        workers: usize,
        label: &str,
    ) -> anyhow::Result<Self> {
        anyhow::ensure!(workers >= 1, "--workers must be at least 1");
        let (database, scratch) = match database {
            Some(path) => (path.to_path_buf(), None),
            None => {
                let dir = std::env::temp_dir().join(format!("tslg-{label}-{}", std::process::id()));
                std::fs::create_dir_all(&dir)?;
                (dir.join("tslg.sqlite"), Some(dir))
            }
        };
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let threads = (cores / workers).max(1);
        let service = LocalService::start(
            &format!("sqlite://{}", database.display()),
            workers,
            threads,
        )
        .await?;
        Ok(Self {
            service,
            database,
            threads,
            scratch,
        })
    }

    pub fn client(&self) -> anyhow::Result<Client> {
        Client::new(&self.service.url, None)
    }

    pub async fn stop(self) -> anyhow::Result<()> {
        self.service.stop().await?;
        if let Some(dir) = self.scratch {
            let _ = std::fs::remove_dir_all(dir);
        }
        Ok(())
    }
}

/// Asks the coordinator to build a library and waits until it is ready.
pub async fn build_library(
    client: &Client,
    request: &CreateLibrary,
) -> anyhow::Result<LibraryView> {
    let library = wait_for_library(client, client.create_library(request).await?).await?;
    anyhow::ensure!(
        library.status == LibraryStatus::Ready,
        "the {} library failed to build: {}",
        library.case,
        library.error.clone().unwrap_or_default()
    );
    Ok(library)
}

/// What an exact answer is computed for: the campaign's case, exposure,
/// vehicle, library and rule.
pub struct ExactQuestion {
    pub case: String,
    pub preset: Option<String>,
    pub exposure: ExposureRequest,
    pub vut: serde_json::Value,
    pub library_file: Vec<u8>,
    pub epsilon: f64,
    pub outside: Outside,
    pub beta: f64,
    pub confidence: f64,
}

/// The exact `P(A)` and the analytic tests of both methods, by enumeration
/// off the async runtime; `None` where the case has no exact answer
/// (car-following: its scenarios are sequences).
pub async fn exact_report(question: ExactQuestion) -> anyhow::Result<Option<ExactReport>> {
    tokio::task::spawn_blocking(move || {
        let source = exposure_source(&question.exposure);
        let outside: OutsideSpread = question
            .outside
            .as_str()
            .parse()
            .map_err(anyhow::Error::msg)?;
        match open_case(&question.case, question.preset.as_deref(), &source)?.exact_report(
            &question.vut,
            &question.library_file,
            question.epsilon,
            outside,
            question.beta,
            question.confidence,
        ) {
            Ok(report) => Ok(Some(report)),
            Err(CaseError::NoExactAnswer(_)) => Ok(None),
            Err(e) => Err(e.into()),
        }
    })
    .await?
}

/// Polls campaigns `ids` with a progress bar each (`labels`) until all
/// have stopped; their final views, in order.
pub async fn watch_campaigns(
    client: &Client,
    ids: &[i64],
    labels: &[&str],
) -> anyhow::Result<Vec<CampaignView>> {
    let bars = CampaignBars::new(labels);
    loop {
        let mut views = Vec::with_capacity(ids.len());
        for (k, &id) in ids.iter().enumerate() {
            let view = client.campaign(id).await?;
            bars.update(k, &view);
            views.push(view);
        }
        if views.iter().all(|v| v.status.is_final()) {
            return Ok(views);
        }
        tokio::time::sleep(std::time::Duration::from_millis(200)).await;
    }
}
