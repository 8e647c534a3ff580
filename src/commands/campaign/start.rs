//! `tslg campaign start` and `tslg campaign watch`: a campaign started on a
//! coordinator, and watched with a progress bar until it stops, as a gate
//! when `--fail-above` is given.

use crate::args::{
    search_for_method, search_parser, ExplorationArgs, OutsideArg, RuleArgs, ServerArgs,
};
use crate::commands::gate;
use crate::commands::progress::CampaignBars;
use crate::commands::remote::{block_on, client, print_campaign as print, vehicle_json};
use clap::Args;
use std::time::Duration;
use tslg_api::{AdaptiveSearch, CreateCampaign, Method};
use tslg_client::Client;

#[derive(Debug, Args)]
pub struct CampaignStartArgs {
    #[command(flatten)]
    pub server: ServerArgs,
    /// The case (default: the library's, with `--library-id`; else
    /// `cut-in`).
    #[arg(long)]
    pub case: Option<String>,
    /// How the campaign draws its tests (docs/statistics.md).
    #[arg(long, value_parser = crate::args::method_parser(), default_value = "library")]
    pub method: Method,
    /// The library (on the coordinator) to sample from; for `ndd`, the exposure to use.
    #[arg(long)]
    pub library_id: Option<i64>,
    /// The vehicle under test: a built-in name or a JSON specification.
    #[arg(long)]
    pub vut: String,
    #[command(flatten)]
    pub exploration: ExplorationArgs,
    #[command(flatten)]
    pub rule: RuleArgs,
    /// Campaign seed: test i is determined by (seed, i).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// A paired regression campaign: test this vehicle too (a built-in name
    /// or a JSON specification, as --vut) on the same tests, and estimate
    /// the difference of the rates (--vut's minus this one's) from the same
    /// draws; methods library and ndd (docs/statistics.md).
    #[arg(long, value_name = "VUT")]
    pub paired_with: Option<String>,
    /// The program under test may give different outcomes for one test
    /// (thread timing, sensor noise): audit it by statistics, so that a
    /// single disagreement between workers flags nobody
    /// (docs/statistics.md, "Noisy vehicles").
    #[arg(long)]
    pub vehicle_noise: bool,
    /// How an adaptive campaign searches: `grid` (every neighbour of a
    /// failure or near miss; the default) or `lattice` (a fine grid's
    /// coarser lattice, whole blocks into the support: far cheaper on
    /// highway-exit's paper grid, blind to failures in sheets thinner than
    /// a block; docs/adaptive-design.md, "Fine grids").
    #[arg(long, value_parser = search_parser())]
    pub adaptive_search: Option<AdaptiveSearch>,
    /// Tests of an adaptive campaign's estimation stages (a multiple of 20,
    /// 20 to 100000); by default 100, or about five rounds of the live
    /// workers offering its vehicle when they have more than 20 threads.
    #[arg(long)]
    pub stage_tests: Option<u64>,
    /// Wait until the campaign stops, showing progress.
    #[arg(long)]
    pub wait: bool,
    /// With --wait, a gate for continuous integration: exit 3 when the
    /// campaign converged with its upper bound (the guarded one where the
    /// campaign has it) above this probability, 4 when it stopped without
    /// converging, 0 when it converged at or below it. With `--interval
    /// anytime` the gate decides as soon as the interval lies wholly above
    /// (3) or below (0) the limit, and the campaign is cancelled.
    #[arg(
        long,
        value_name = "P",
        requires = "wait",
        allow_negative_numbers = true
    )]
    pub fail_above: Option<f64>,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// Runs `tslg campaign start`.
pub fn start(args: &CampaignStartArgs) -> anyhow::Result<()> {
    let client = client(&args.server)?;
    let method = args.method;
    let vut = vehicle_json(&args.vut)?;
    let case = args.case.clone().unwrap_or_else(|| "cut-in".into());
    let mut request = CreateCampaign {
        library_id: args.library_id,
        epsilon: args.exploration.epsilon,
        outside: args.exploration.outside.map(OutsideArg::wire),
        split: Some(args.exploration.split.wire()),
        beta: args.rule.beta,
        confidence: args.rule.confidence,
        max_tests: args.rule.max_tests,
        seed: args.seed,
        n_min: args.rule.n_min,
        min_events: Some(args.rule.min_events),
        guard_outside: args.rule.guard_request(),
        interval: tslg_client::wire::wire_interval(args.rule.interval),
        paired_with: args.paired_with.as_deref().map(vehicle_json).transpose()?,
        vehicle_noise: args.vehicle_noise,
        adaptive_search: search_for_method(args.adaptive_search, args.method)?,
        stage_tests: args.stage_tests,
        ..CreateCampaign::new(case, method, vut)
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
        let (view, early) = watch(&client, view.id, args.fail_above).await?;
        // The gate decided: the campaign this command started stops too
        // (unless it stopped on its own meanwhile: then it is shown as it
        // ended, and the verdict stands).
        let view = match early {
            Some(_) => match client.cancel_campaign(view.id).await {
                Ok(view) => view,
                Err(_) => client.campaign(view.id).await?,
            },
            None => view,
        };
        print(&view, args.json)?;
        judge(&view, args.fail_above, early)
    })
}

/// The gate's verdict when a limit is given (`--fail-above`): the early
/// one of an anytime campaign, or the one at the stop.
fn judge(
    view: &tslg_api::CampaignView,
    limit: Option<f64>,
    early: Option<Result<String, gate::GateFailed>>,
) -> anyhow::Result<()> {
    match (early, limit) {
        (Some(verdict), _) => eprintln!("{}", verdict?),
        (None, Some(limit)) => eprintln!("{}", gate::judge(view, limit)?),
        (None, None) => {}
    }
    Ok(())
}

/// Polls a campaign until it stops, showing a progress bar on stderr, and
/// why it waits when no worker serves it (once each time it starts to).
/// With a gate's `limit`, an anytime campaign is judged at every poll, and
/// the watch ends with the verdict as soon as its interval lies wholly on
/// one side of the limit ([`gate::early`]).
pub async fn watch(
    client: &Client,
    id: i64,
    limit: Option<f64>,
) -> anyhow::Result<(tslg_api::CampaignView, Option<EarlyVerdict>)> {
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
            return Ok((view, None));
        }
        if let Some(verdict) = limit.and_then(|limit| gate::early(&view, limit)) {
            return Ok((view, Some(verdict)));
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
        // A campaign watched, not started, here is left running when the
        // gate decides early.
        let (view, early) = watch(&client, id, fail_above).await?;
        print(&view, json)?;
        judge(&view, fail_above, early)
    })
}

/// A gate's verdict reached before the campaign stopped.
pub type EarlyVerdict = Result<String, gate::GateFailed>;
