//! `tslg library create|delete`: libraries built and deleted on a
//! running coordinator; a build watched with its progress until it ends.

use crate::args::{CaseArgs, SearchArgs, ServerArgs};
use crate::commands::listing::describe_library;
use crate::commands::progress::BuildBar;
use crate::commands::remote::{block_on, client, exposure_request, vehicle_json};
use crate::inputs::case_descriptor;
use clap::Args;
use std::time::Duration;
use tslg_api::{CreateLibrary, LibraryStatus, LibraryView};
use tslg_client::Client;

#[derive(Debug, Args)]
pub struct LibraryCreateArgs {
    #[command(flatten)]
    pub server: ServerArgs,
    #[command(flatten)]
    pub case: CaseArgs,
    /// The surrogate model: a built-in name or a JSON specification
    /// (default: the case's).
    #[arg(long)]
    pub surrogate: Option<String>,
    #[command(flatten)]
    pub search: SearchArgs,
    /// Wait until the build is done.
    #[arg(long)]
    pub wait: bool,
    /// Print JSON (as `GET /api/v1/libraries/{id}` answers).
    #[arg(long)]
    pub json: bool,
}

/// The case's name, default surrogate and multistart starts: from this
/// build's cases, else from the coordinator's (a case defined there with
/// `tslg case create`).
async fn case_defaults(
    client: &Client,
    case: &CaseArgs,
) -> anyhow::Result<(String, String, usize)> {
    let unknown = match case_descriptor(case) {
        Ok(d) => {
            return Ok((
                d.name.into(),
                d.default_surrogate.into(),
                d.multistart_starts,
            ))
        }
        Err(e) => e,
    };
    let defined = client.cases().await?;
    let view = defined
        .into_iter()
        .find(|c| c.name == case.name())
        .ok_or(unknown)?;
    let starts = match view.default_search {
        tslg_api::SearchRequest::Multistart { starts, .. } => starts,
        _ => DEFAULT_STARTS,
    };
    Ok((view.name, view.default_surrogate, starts))
}

/// Multistart starting points for a coordinator's case whose default search
/// is not multistart (the built-in cut-in's number).
const DEFAULT_STARTS: usize = 50;

/// Runs `tslg library create`.
pub fn create_library(args: &LibraryCreateArgs) -> anyhow::Result<()> {
    let client = client(&args.server)?;
    let exposure = exposure_request(&args.case)?;
    if args.search.starts == Some(0) {
        anyhow::bail!("--starts must be at least 1");
    }
    let (case, default_surrogate, starts) = block_on(case_defaults(&client, &args.case))?;
    let request = CreateLibrary {
        case,
        preset: args.case.preset.clone(),
        surrogate: vehicle_json(args.surrogate.as_deref().unwrap_or(&default_surrogate))?,
        exposure,
        search: args
            .search
            .search_with(starts)
            .map(tslg_client::wire::search_request),
        threshold: args
            .search
            .threshold()
            .map(tslg_client::wire::threshold_request),
    };
    block_on(async {
        let view = client.create_library(&request).await?;
        let view = if args.wait {
            wait_for_library(&client, view).await?
        } else {
            view
        };
        if args.json {
            outln!("{}", serde_json::to_string_pretty(&view)?);
        } else {
            outln!("{}", describe_library(&view));
        }
        if view.status == LibraryStatus::Failed {
            anyhow::bail!(
                "library {} failed: {}",
                view.id,
                view.error.unwrap_or_default()
            );
        }
        Ok(())
    })
}

/// Polls a library until its build ends, showing its progress on stderr.
pub async fn wait_for_library(
    client: &Client,
    mut view: LibraryView,
) -> anyhow::Result<LibraryView> {
    let bar = BuildBar::new(view.id);
    while view.status == LibraryStatus::Building {
        bar.update(&view);
        tokio::time::sleep(Duration::from_millis(200)).await;
        view = client.library(view.id).await?;
    }
    bar.finish(&view);
    Ok(view)
}

/// Runs `tslg library delete`.
pub fn delete_library(server: &ServerArgs, id: i64) -> anyhow::Result<()> {
    let client = client(server)?;
    block_on(async { Ok(client.delete_library(id).await?) })?;
    outln!("library {id} deleted");
    Ok(())
}
