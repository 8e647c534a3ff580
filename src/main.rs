use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = tslg::Cli::parse();
    match tslg::run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
