//! `tslg-worker`: runs the tests a coordinator hands out (see `tslg_worker`).

use clap::Parser;

#[tokio::main]
async fn main() {
    tslg::service::init_tracing();
    let config = tslg_worker::WorkerConfig::parse();
    let code = match tslg::service::worker_main(config).await {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("error: {}", tslg::error_text(&e));
            1
        }
    };
    // Exits without waiting for a library build its shutdown gave back
    // (dropping the runtime would wait for its thread).
    std::process::exit(code)
}
