//! `tslg-server`: the campaign coordinator (see `tslg_server`).

use clap::Parser;
use std::process::ExitCode;

#[tokio::main]
async fn main() -> ExitCode {
    tslg::service::init_tracing();
    let config = tslg_server::Config::parse();
    match tslg::service::server_main(config).await {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", tslg::error_text(&e));
            ExitCode::FAILURE
        }
    }
}
