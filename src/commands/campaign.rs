//! `tslg campaign start|status|cancel` and `tslg library create`: clients
//! of a running coordinator.

use crate::commands::gate;
use crate::commands::progress::{BuildBar, CampaignBars};
use crate::commands::remote::{block_on, client, describe, exposure_request, vehicle_json};
use crate::{CampaignStartArgs, LibraryCreateArgs, MethodArg, OutsideArg, ServerArgs};
use anyhow::Context;
use std::path::Path;
use std::time::Duration;
use tslg_api::{CreateCampaign, CreateLibrary, LibraryStatus, LibraryView, Method};
use tslg_client::Client;

pub fn start(args: &CampaignStartArgs) -> anyhow::Result<()> {
    let client = client(&args.server)?;
    let mut request = CreateCampaign {
        case: args.case.clone().unwrap_or_else(|| "cut-in".into()),
        method: match args.method {
            MethodArg::Library => Method::Library,
            MethodArg::Adaptive => Method::Adaptive,
            MethodArg::Ndd => Method::Ndd,
        },
        library_id: args.library_id,
        vut: vehicle_json(&args.vut)?,
        epsilon: args.exploration.epsilon,
        outside: args.exploration.outside.map(OutsideArg::wire),
        split: Some(args.exploration.split.wire()),
        beta: args.rule.beta,
        confidence: args.rule.confidence,
        max_tests: args.rule.max_tests,
        seed: args.seed,
        n_min: args.rule.n_min,
        min_events: Some(args.rule.min_events),
        guard_outside: args.rule.guard_outside,
        paired_with: args.paired_with.as_deref().map(vehicle_json).transpose()?,
    };
    if let Some(limit) = args.fail_above {
        gate::check_limit(limit)?;
    }
    block_on(async {
        // Without --case, a library's campaign is of the library's case.
        if let (None, Some(id)) = (&args.case, args.library_id) {
            request.case = client.library(id).await?.case;
        }
        let view = client.create_campaign(&request).await?;
        if !args.wait {
            return print(&view, args.json);
        }
        eprintln!("campaign {} started; waiting for it to stop", view.id);
        let view = watch(&client, view.id).await?;
        print(&view, args.json)?;
        judge(&view, args.fail_above)
    })
}

/// The gate's verdict when a limit is given (`--fail-above`).
fn judge(view: &tslg_api::CampaignView, limit: Option<f64>) -> anyhow::Result<()> {
    if let Some(limit) = limit {
        eprintln!("{}", gate::judge(view, limit)?);
    }
    Ok(())
}

/// Polls a campaign until it stops, showing a progress bar on stderr, and
/// why it waits when no worker serves it (once each time it starts to).
pub async fn watch(client: &Client, id: i64) -> anyhow::Result<tslg_api::CampaignView> {
    let bars = CampaignBars::new(&["campaign"]);
    let mut waiting: Vec<String> = Vec::new();
    loop {
        let view = client.campaign(id).await?;
        let now: Vec<String> = view
            .warnings
            .iter()
            .filter(|w| w.starts_with("no worker"))
            .cloned()
            .collect();
        for warning in now.iter().filter(|w| !waiting.contains(w)) {
            bars.note(0, &format!("campaign {id}: {warning}"));
        }
        waiting = now;
        bars.update(0, &view);
        if view.status.is_final() {
            return Ok(view);
        }
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
}

/// `tslg campaign watch ID`: a progress bar until the campaign stops, then
/// its state.
pub fn watch_command(
    server: &ServerArgs,
    id: i64,
    fail_above: Option<f64>,
    json: bool,
) -> anyhow::Result<()> {
    if let Some(limit) = fail_above {
        gate::check_limit(limit)?;
    }
    let client = client(server)?;
    block_on(async {
        let view = watch(&client, id).await?;
        print(&view, json)?;
        judge(&view, fail_above)
    })
}

/// `tslg campaign report ID --out DIR`: the dashboard's figures as SVG
/// files, and the numbers behind them as CSV and JSON.
pub fn report(server: &ServerArgs, id: i64, out: &Path, points: usize) -> anyhow::Result<()> {
    let client = client(server)?;
    let (view, history) = block_on(async {
        Ok((
            client.campaign(id).await?,
            client.history_points(id, points).await?,
        ))
    })?;
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create the directory {}", out.display()))?;
    let files = [
        (
            "estimate.svg",
            tslg_figures::estimate_svg(&view, &history.points)?,
        ),
        (
            "relative-half-width.svg",
            tslg_figures::relative_half_width_svg(&view, &history.points)?,
        ),
        ("history.csv", tslg_figures::history_csv(&history.points)),
        ("campaign.json", serde_json::to_string_pretty(&view)? + "\n"),
    ];
    for (name, content) in files {
        let path = out.join(name);
        std::fs::write(&path, content)
            .with_context(|| format!("cannot write {}", path.display()))?;
        outln!("{}", path.display());
    }
    Ok(())
}

fn print(view: &tslg_api::CampaignView, json: bool) -> anyhow::Result<()> {
    if json {
        outln!("{}", serde_json::to_string_pretty(view)?);
    } else {
        outln!("{}", describe(view));
    }
    Ok(())
}

pub fn status(server: &ServerArgs, id: i64, json: bool) -> anyhow::Result<()> {
    let client = client(server)?;
    block_on(async { print(&client.campaign(id).await?, json) })
}

pub fn health(server: &ServerArgs) -> anyhow::Result<()> {
    let client = client(server)?;
    block_on(async {
        let health = client.health().await?;
        outln!("{} (tslg {})", health.status, health.version);
        Ok(())
    })
}

pub fn cancel(server: &ServerArgs, id: i64) -> anyhow::Result<()> {
    let client = client(server)?;
    block_on(async { print(&client.cancel_campaign(id).await?, false) })
}

/// The case's name, default surrogate and multistart starts: from this
/// build's cases, else from the coordinator's (a case defined there with
/// `tslg case create`).
async fn case_defaults(
    client: &Client,
    case: &crate::CaseArgs,
) -> anyhow::Result<(String, String, usize)> {
    let unknown = match case.descriptor() {
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
            outln!("{}", crate::commands::listing::describe_library(&view));
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

pub fn delete_campaign(server: &ServerArgs, id: i64) -> anyhow::Result<()> {
    let client = client(server)?;
    block_on(async { Ok(client.delete_campaign(id).await?) })?;
    outln!("campaign {id} deleted");
    Ok(())
}

pub fn delete_library(server: &ServerArgs, id: i64) -> anyhow::Result<()> {
    let client = client(server)?;
    block_on(async { Ok(client.delete_library(id).await?) })?;
    outln!("library {id} deleted");
    Ok(())
}
