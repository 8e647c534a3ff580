//! `tslg campaign …`: clients of a running coordinator's campaigns.

mod start;
mod summary;
mod timeline;

use crate::args::{wire_name, ServerArgs};
use crate::commands::remote::{block_on, client, print_campaign as print};
use crate::commands::{events, listing};
use anyhow::Context;
use clap::Subcommand;
use std::path::{Path, PathBuf};

#[derive(Debug, Subcommand)]
pub enum CampaignCommand {
    /// Start a campaign.
    Start(start::CampaignStartArgs),
    /// Print a campaign's state and estimate.
    Status {
        /// The campaign's id.
        id: i64,
        #[command(flatten)]
        server: ServerArgs,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Show a progress bar toward β until the campaign stops, then its state.
    Watch {
        /// The campaign's id.
        id: i64,
        #[command(flatten)]
        server: ServerArgs,
        /// The gate of `campaign start --wait --fail-above P`: exit 3 when
        /// the campaign converged with its upper bound above P, 4 when it
        /// stopped without converging. An anytime campaign is judged while
        /// it runs (exit 3 as soon as its interval lies above P, 0 as soon
        /// as below) and left running.
        #[arg(long, value_name = "P", allow_negative_numbers = true)]
        fail_above: Option<f64>,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Write the campaign's figures (SVG), numbers (CSV, JSON) and a summary
    /// (summary.md: its verdict, numbers, warnings and figures) to a directory.
    Report {
        /// The campaign's id.
        id: i64,
        #[command(flatten)]
        server: ServerArgs,
        /// The directory to write estimate.svg, relative-half-width.svg,
        /// history.csv and campaign.json to (created if missing).
        #[arg(long)]
        out: PathBuf,
        /// History points in the figures and the CSV (2 to 5000), spaced
        /// logarithmically in the number of tests; the dashboard shows 300.
        #[arg(long, default_value_t = 300)]
        points: usize,
    },
    /// Export the campaign's events (its resolved prefix): test index,
    /// weight, the library's criticality and the scenario by dimension, as
    /// CSV or JSON on stdout, or one OpenSCENARIO file per event (grid
    /// cases) in a directory.
    Events {
        /// The campaign's id.
        id: i64,
        #[command(flatten)]
        server: ServerArgs,
        /// `csv`, `json` or `xosc` (OpenSCENARIO 1.0, needs --out).
        #[arg(long, value_enum, default_value = "csv")]
        format: events::EventFormat,
        /// The directory for the xosc files and their road
        /// (tslg_straight_road.xodr); created if missing.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Export at most this many events (the first by test index).
        #[arg(long)]
        max: Option<u64>,
    },
    /// Where the campaign's wall time went: its workers busy on it over
    /// time, from when each piece of its work was leased and reported.
    Timeline {
        /// The campaign's id.
        id: i64,
        #[command(flatten)]
        server: ServerArgs,
        /// Buckets of equal length from its first lease to its last report
        /// (1 to 1000).
        #[arg(long, default_value_t = 30)]
        buckets: u32,
        /// Print JSON (as `GET /api/v1/campaigns/{id}/timeline` answers).
        #[arg(long)]
        json: bool,
    },
    /// Cancel a pending or running campaign.
    Cancel {
        /// The campaign's id.
        id: i64,
        #[command(flatten)]
        server: ServerArgs,
    },
    /// Delete a stopped campaign and everything recorded for it.
    Delete {
        /// The campaign's id.
        id: i64,
        #[command(flatten)]
        server: ServerArgs,
    },
    /// List the coordinator's campaigns, newest first, a line each.
    List {
        #[command(flatten)]
        server: ServerArgs,
        /// Only those in this state: pending, running, converged,
        /// exhausted, cancelled or failed.
        #[arg(long, value_parser = wire_name::<tslg_api::CampaignStatus>)]
        status: Option<tslg_api::CampaignStatus>,
        /// Print JSON (as `GET /api/v1/campaigns` answers).
        #[arg(long)]
        json: bool,
    },
}

/// Runs `tslg campaign …`.
pub fn run(command: CampaignCommand) -> anyhow::Result<()> {
    match command {
        CampaignCommand::Start(args) => start::start(&args),
        CampaignCommand::Status { id, server, json } => status(&server, id, json),
        CampaignCommand::Watch {
            id,
            server,
            fail_above,
            json,
        } => start::watch_command(&server, id, fail_above, json),
        CampaignCommand::Report {
            id,
            server,
            out,
            points,
        } => report(&server, id, &out, points),
        CampaignCommand::Events {
            id,
            server,
            format,
            out,
            max,
        } => events::export(&server, id, format, out.as_deref(), max),
        CampaignCommand::Timeline {
            id,
            server,
            buckets,
            json,
        } => timeline::timeline(&server, id, buckets, json),
        CampaignCommand::Cancel { id, server } => cancel(&server, id),
        CampaignCommand::Delete { id, server } => delete_campaign(&server, id),
        CampaignCommand::List {
            server,
            status,
            json,
        } => listing::campaigns(&server, status, json),
    }
}

/// `tslg campaign report ID --out DIR`: the dashboard's figures as SVG
/// files, and the numbers behind them as CSV and JSON; an adaptive
/// campaign's stages and support too, as its page shows them.
pub fn report(server: &ServerArgs, id: i64, out: &Path, points: usize) -> anyhow::Result<()> {
    let client = client(server)?;
    let (view, history) = block_on(async {
        Ok((
            client.campaign(id).await?,
            client.history_points(id, points).await?,
        ))
    })?;
    // A coordinator older than the stages' list answers 404: no stages.
    let stages = match view.method.in_stages() {
        true => block_on(async {
            match client.stages(id).await {
                Ok(stages) => Ok(Some(stages)),
                Err(tslg_client::CallError::Refused { status: 404, .. }) => Ok(None),
                Err(e) => Err(e.into()),
            }
        })?,
        _ => None,
    };
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create the directory {}", out.display()))?;
    let mut files = vec![
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
    if let Some(stages) = stages {
        files.extend([
            (
                "stages.svg",
                tslg_figures::stages_svg(&view, &stages.stages)?,
            ),
            (
                "support.svg",
                tslg_figures::support_svg(&view, &stages.stages)?,
            ),
            ("stages.json", serde_json::to_string_pretty(&stages)? + "\n"),
        ]);
    }
    let figures: Vec<&str> = files
        .iter()
        .map(|(name, _)| *name)
        .filter(|name| name.ends_with(".svg"))
        .collect();
    let summary = summary::markdown(&view, &figures);
    files.push(("summary.md", summary));
    for (name, content) in files {
        let path = out.join(name);
        std::fs::write(&path, content)
            .with_context(|| format!("cannot write {}", path.display()))?;
        outln!("{}", path.display());
    }
    Ok(())
}

fn status(server: &ServerArgs, id: i64, json: bool) -> anyhow::Result<()> {
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

fn cancel(server: &ServerArgs, id: i64) -> anyhow::Result<()> {
    let client = client(server)?;
    block_on(async { print(&client.cancel_campaign(id).await?, false) })
}

fn delete_campaign(server: &ServerArgs, id: i64) -> anyhow::Result<()> {
    let client = client(server)?;
    block_on(async { Ok(client.delete_campaign(id).await?) })?;
    outln!("campaign {id} deleted");
    Ok(())
}
