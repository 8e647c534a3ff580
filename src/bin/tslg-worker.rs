//! `tslg-worker`: runs the tests a coordinator hands out (see `tslg_worker`).

use clap::Parser;
use std::process::ExitCode;

#[tokio::main]
async fn main() -> ExitCode {
    tslg::service::init_tracing();
    let config = tslg_worker::WorkerConfig::parse();
    match tslg::service::worker_main(config).await {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
