//! `tslg backup`: a consistent copy of a coordinator's SQLite database,
//! taken while the coordinator runs (SQLite's `VACUUM INTO`).

use crate::commands::remote::block_on;
use clap::Args;

#[derive(Debug, Args)]
pub struct BackupArgs {
    /// The database to copy, as the coordinator's `--database-url`.
    #[arg(
        long,
        env = "TSLG_DATABASE_URL",
        default_value = "sqlite://tslg.sqlite"
    )]
    pub database_url: String,
    /// The backup file to write; it must not exist.
    #[arg(long)]
    pub out: std::path::PathBuf,
}

/// Runs `tslg backup`.
pub fn run(args: &BackupArgs) -> anyhow::Result<()> {
    block_on(async {
        let bytes = tslg_server::backup(&args.database_url, &args.out).await?;
        outln!(
            "backed up {} to {} ({bytes} bytes)",
            args.database_url,
            args.out.display()
        );
        Ok(())
    })
}
