//! `tslg worker enrol PRINCIPAL`: an enrolment credential for a principal
//! (a host, an operator, a cluster job) from a coordinator run with
//! `--enrolment required`, for its workers' `--enrolment-file`
//! (docs/operations.md, "Who is trusted").

use crate::args::ServerArgs;
use crate::commands::remote::{block_on, client};
use clap::Subcommand;
use std::path::PathBuf;

#[derive(Debug, Subcommand)]
pub enum WorkerCommand {
    /// Issue an enrolment credential for a principal (admin token): its
    /// workers register with it, and audits, quorums and evidence count
    /// the principal once however many names it registers.
    Enrol {
        /// The principal: 1 to 120 letters, digits, `.`, `-` and `_`.
        principal: String,
        /// Write the secret to this file (mode 0600) instead of printing it.
        #[arg(long)]
        out: Option<PathBuf>,
        #[command(flatten)]
        server: ServerArgs,
    },
}

/// Runs `tslg worker …`.
pub fn run(command: WorkerCommand) -> anyhow::Result<()> {
    match command {
        WorkerCommand::Enrol {
            principal,
            out,
            server,
        } => {
            let client = client(&server)?;
            let issued = block_on(async { Ok(client.enrol(&principal).await?) })?;
            match out {
                Some(path) => {
                    write_secret(&path, &issued.secret)?;
                    out!(
                        "enrolled principal `{}` at {}; its secret is in {} (start its workers \
                         with --enrolment-file {})",
                        issued.principal,
                        issued.issued_at,
                        path.display(),
                        path.display()
                    );
                }
                None => out!("{}", issued.secret),
            }
            Ok(())
        }
    }
}

/// Writes `secret` to a new file only its owner can read.
fn write_secret(path: &std::path::Path, secret: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(0o600);
    }
    let mut file = options
        .open(path)
        .map_err(|e| anyhow::anyhow!("--out {}: {e}", path.display()))?;
    writeln!(file, "{secret}")?;
    Ok(())
}
