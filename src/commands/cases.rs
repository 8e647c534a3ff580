//! `tslg cases`: every case with its presets, vehicles and defaults, from
//! the case descriptors (what `GET /api/v1/cases` serves); `tslg case
//! create|list` on a coordinator; `tslg table`, a case's built-in exposure.

use crate::args::ServerArgs;
use crate::commands::remote::{block_on, client};
use anyhow::Context;
use clap::Subcommand;
use std::path::{Path, PathBuf};
use tslg_api::{CaseView, ScenarioKind};
use tslg_client::wire::case_view;

#[derive(Debug, Subcommand)]
pub enum CaseCommand {
    /// Define a user-defined case from its case file (and the exposure table
    /// it names) on a coordinator; libraries and campaigns then name it.
    Create {
        /// The case file (TOML; docs/bring-your-own.md).
        file: PathBuf,
        #[command(flatten)]
        server: ServerArgs,
    },
    /// List the cases a coordinator runs, its user-defined ones included.
    List {
        #[command(flatten)]
        server: ServerArgs,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
}

/// Runs `tslg case …`.
pub fn run_case(command: CaseCommand) -> anyhow::Result<()> {
    match command {
        CaseCommand::Create { file, server } => create(&file, &server),
        CaseCommand::List { server, json } => list(&server, json),
    }
}

/// `tslg table`: the case's built-in exposure model as the table it accepts.
pub fn table(case: &str, preset: Option<&str>) -> anyhow::Result<()> {
    out!("{}", tslg_method::cases::builtin_table(case, preset)?);
    Ok(())
}

/// `tslg cases`: the cases this build knows.
pub fn run(json: bool) -> anyhow::Result<()> {
    let views: Vec<_> = tslg_method::cases::descriptors()
        .iter()
        .map(case_view)
        .collect();
    print_views(&views, json)
}

/// `tslg case create FILE`: the case file and its exposure table sent to
/// the coordinator.
pub fn create(path: &Path, server: &ServerArgs) -> anyhow::Result<()> {
    let (file, dir) = crate::inputs::read_case_file(path)?;
    let table_path = dir.join(&file.exposure);
    let table = std::fs::read_to_string(&table_path)
        .with_context(|| format!("cannot read the exposure table {}", table_path.display()))?;
    let request = tslg_api::CreateCase {
        file: std::fs::read_to_string(path)?,
        table,
        table_name: Some(file.exposure.clone()),
    };
    let client = client(server)?;
    block_on(async {
        let view = client.create_case(&request).await?;
        outln!(
            "case {} defined on {}: {} (program {}, {})",
            view.name,
            server.server,
            view.summary,
            view.default_surrogate,
            view.tables.first().map_or("", |t| t.holds.as_str())
        );
        Ok(())
    })
}

/// `tslg case list`: a coordinator's cases.
pub fn list(server: &ServerArgs, json: bool) -> anyhow::Result<()> {
    let client = client(server)?;
    let views = block_on(async { Ok(client.cases().await?) })?;
    print_views(&views, json)
}

fn print_views(cases: &[CaseView], json: bool) -> anyhow::Result<()> {
    if json {
        outln!("{}", serde_json::to_string_pretty(cases)?);
        return Ok(());
    }
    for (k, case) in cases.iter().enumerate() {
        if k > 0 {
            outln!();
        }
        let user = if case.user_defined {
            " (user-defined)"
        } else {
            ""
        };
        outln!("{}{user}", case.name);
        outln!("  {}", case.summary);
        for (i, preset) in case.presets.iter().enumerate() {
            let default = if i == 0 { " (default)" } else { "" };
            outln!("  preset {}{default}: {}", preset.name, preset.summary);
        }
        outln!("  vehicles: {}", case.vehicles.join(", "));
        outln!(
            "  library: surrogate {} by default, search {}",
            case.default_surrogate,
            serde_json::to_string(&case.default_search)?
        );
        outln!(
            "  scenarios: {} ({})",
            if case.scenarios == ScenarioKind::Grid {
                "grid cells drawn before each test; exact answers and adaptive campaigns"
            } else {
                "drawn while each test runs"
            },
            case.scenario_unit
        );
        match case.tables.as_slice() {
            [] => outln!("  exposure: its built-in model only"),
            tables => {
                for t in tables {
                    outln!(
                        "  exposure: built-in, or a table of {} ({})",
                        t.holds,
                        t.doc
                    );
                }
            }
        }
    }
    Ok(())
}
