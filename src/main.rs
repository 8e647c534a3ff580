use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = tslg::Cli::parse();
    match tslg::run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        // A gate's verdict (`--fail-above`) has its own exit status.
        Err(e) => match e.downcast_ref::<tslg::GateFailed>() {
            Some(gate) => {
                eprintln!("{gate}");
                ExitCode::from(gate.code)
            }
            None => {
                eprintln!("error: {}", tslg::error_text(&e));
                ExitCode::FAILURE
            }
        },
    }
}
