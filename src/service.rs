//! Running the coordinator and workers: the two service binaries, and an
//! embedded coordinator with local workers for `tslg demo` and tests.

use std::net::SocketAddr;
use tokio::sync::watch;

/// Logs to stderr, filtered by `RUST_LOG` (default `info`).
pub fn init_tracing() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    use std::io::IsTerminal;
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::stderr().is_terminal())
        .with_writer(std::io::stderr)
        .try_init();
}

/// Completes on Ctrl-C or SIGTERM.
pub async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = terminate => {},
    }
    tracing::info!("shutdown requested");
}

/// `tslg-server`.
pub async fn server_main(config: tslg_server::Config) -> anyhow::Result<()> {
    use anyhow::Context;
    let listener = tokio::net::TcpListener::bind(config.bind)
        .await
        .with_context(|| format!("cannot listen on {}", config.bind))?;
    tslg_server::serve(listener, config, shutdown_signal()).await
}

/// `tslg-worker`.
pub async fn worker_main(config: tslg_worker::WorkerConfig) -> anyhow::Result<()> {
    tslg_worker::run(config, shutdown_signal())
        .await
        .map(|_| ())
}

/// A coordinator and workers in this process, talking over loopback HTTP.
pub struct LocalService {
    pub url: String,
    stop: watch::Sender<bool>,
    server: tokio::task::JoinHandle<anyhow::Result<()>>,
    workers: Vec<tokio::task::JoinHandle<anyhow::Result<tslg_worker::WorkerSummary>>>,
}

async fn stopped(mut rx: watch::Receiver<bool>) {
    let _ = rx.wait_for(|s| *s).await;
}

impl LocalService {
    /// Starts a coordinator on `database_url` (a free loopback port) and
    /// `workers` workers of `threads` threads each. The coordinator is open
    /// (its store migrated) when this returns, so a bad database fails here
    /// and the first request is answered at once rather than queued behind
    /// the migrations.
    pub async fn start(database_url: &str, workers: usize, threads: usize) -> anyhow::Result<Self> {
        let listener = tokio::net::TcpListener::bind(SocketAddr::from(([127, 0, 0, 1], 0))).await?;
        let url = format!("http://{}", listener.local_addr()?);
        let (stop, rx) = watch::channel(false);
        let config = tslg_server::Config::embedded(database_url);
        let coordinator = tslg_server::Coordinator::open(config).await?;
        let server = tokio::spawn(coordinator.serve(listener, stopped(rx.clone())));
        let workers = (1..=workers)
            .map(|k| {
                let config =
                    tslg_worker::WorkerConfig::local(&url, threads, format!("local-worker-{k}"));
                tokio::spawn(tslg_worker::run(config, stopped(rx.clone())))
            })
            .collect();
        Ok(Self {
            url,
            stop,
            server,
            workers,
        })
    }

    /// Stops the workers (each finishes or gives back its lease), then the
    /// coordinator.
    pub async fn stop(self) -> anyhow::Result<Vec<tslg_worker::WorkerSummary>> {
        let _ = self.stop.send(true);
        let mut summaries = Vec::new();
        for w in self.workers {
            summaries.push(w.await??);
        }
        self.server.await??;
        Ok(summaries)
    }
}
