//! `tslg demo`: the whole service in one command. Starts a coordinator on an
//! embedded SQLite file and local workers, builds the case's library through
//! the API, runs a library campaign, an adaptive campaign (grid cases) and
//! the NDD baseline of the same vehicle side by side with progress, and
//! prints them beside the exact answer (or, for car-following, where no
//! enumeration exists, beside each other), each with what its interval
//! assumes. On cut-in the vehicle is by default the FVDM, which fails where
//! the IDM's library does not.

#[derive(Debug, Args)]
pub struct DemoArgs {
    #[command(flatten)]
    pub case: CaseArgs,
    /// The surrogate model the library is built from (default: idm for cut-in
    /// and car-following, mobil for highway-exit).
    #[arg(long)]
    pub surrogate: Option<String>,
    /// The vehicle under test: a built-in name or a JSON specification
    /// (default: on cut-in with its default surrogate, fvdm, a vehicle that
    /// fails where the IDM's library does not look; else the surrogate's
    /// model).
    #[arg(long)]
    pub vut: Option<String>,
    /// Target relative half-width.
    #[arg(long, default_value_t = 0.2, allow_negative_numbers = true)]
    pub beta: f64,
    #[command(flatten)]
    pub exploration: ExplorationArgs,
    /// Campaign seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Test budget of each campaign.
    #[arg(long, default_value_t = 10_000_000)]
    pub max_tests: u64,
    /// Local workers to start.
    #[arg(long, default_value_t = 2)]
    pub workers: usize,
    /// Keep the coordinator's database in this file (default: a scratch file, removed after).
    #[arg(long)]
    pub database: Option<PathBuf>,
}

use crate::args::{CaseArgs, ExplorationArgs};
use crate::commands::local::{build_library, exact_report, watch_campaigns, ExactQuestion, Local};
use crate::commands::remote::{exposure_request, vehicle_json};
use crate::inputs::{case_descriptor, surrogate_or_default};
use clap::Args;
use std::path::PathBuf;
use std::time::Instant;
use tslg_api::{CampaignView, CreateCampaign, CreateLibrary, ExposureRequest, Method};
use tslg_client::Client;
use tslg_method::exact::ExactReport;
use tslg_method::warnings::Dialect;

pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?
        .block_on(demo(args))
}

async fn demo(args: &DemoArgs) -> anyhow::Result<()> {
    let exposure = exposure_request(&args.case)?;
    let vut_name = demo_vut(args)?;
    check_before_starting(args, &vut_name)?;
    let vut = vehicle_json(&vut_name)?;
    let local = Local::start(args.database.as_deref(), args.workers, "demo").await?;
    outln!(
        "coordinator {} on {}, {} workers × {} threads",
        local.service.url,
        local.database.display(),
        args.workers,
        local.threads
    );
    let outcome = drive(args, &local.service.url, exposure, vut).await;
    local.stop().await?;
    outcome
}

async fn drive(
    args: &DemoArgs,
    url: &str,
    exposure: ExposureRequest,
    vut: serde_json::Value,
) -> anyhow::Result<()> {
    let client = Client::new(url, None)?;
    let started = Instant::now();
    let descriptor = case_descriptor(&args.case)?;
    let surrogate = surrogate_or_default(&args.case, &args.surrogate)?;
    let library = build_library(
        &client,
        &CreateLibrary {
            case: descriptor.name.to_owned(),
            preset: args.case.preset.clone(),
            surrogate: vehicle_json(surrogate)?,
            exposure: exposure.clone(),
            search: None,
            threshold: None,
        },
    )
    .await?;
    outln!(
        "{} library {} of {surrogate}: {} of {} {} ({} surrogate runs, {:.2} s), exposure {}",
        library.case,
        library.id,
        library.size.unwrap_or(0),
        library.total_scenarios,
        descriptor.scenario_unit,
        library.sm_evaluations.unwrap_or(0),
        started.elapsed().as_secs_f64(),
        library.exposure
    );
    let request = |method: Method| CreateCampaign {
        library_id: Some(library.id),
        epsilon: args.exploration.epsilon,
        outside: args.exploration.outside.map(crate::args::OutsideArg::wire),
        split: Some(args.exploration.split.wire()),
        beta: args.beta,
        max_tests: args.max_tests,
        seed: args.seed,
        // The demo's numbers are those of stages of 100 on any machine.
        stage_tests: method
            .in_stages()
            .then_some(tslg_method::adaptive::AdaptiveSettings::default().stage_tests),
        ..CreateCampaign::new(descriptor.name, method, vut.clone())
    };
    // The service runs adaptive campaigns of grid cases; a sequential
    // case's probes the vehicle from grid states, which it cannot lease
    // yet (`tslg evaluate` runs them).
    let methods: &[Method] = if descriptor.is_grid() {
        &[Method::Library, Method::Adaptive, Method::Ndd]
    } else {
        &[Method::Library, Method::Ndd]
    };
    let mut ids = Vec::new();
    for &method in methods {
        ids.push(client.create_campaign(&request(method)).await?.id);
    }
    let labels: Vec<&str> = methods.iter().map(|m| m.as_str()).collect();
    let views = watch_campaigns(&client, &ids, &labels).await?;
    let by_library = &views[0];
    let exact = exact_report(ExactQuestion {
        case: descriptor.name.to_owned(),
        preset: args.case.preset.clone(),
        exposure,
        vut,
        library_file: client.library_file(library.id).await?,
        epsilon: args.exploration.epsilon,
        outside: by_library.outside,
        beta: args.beta,
        confidence: 0.9,
    })
    .await?;
    print_table(args, &views, exact.as_ref());
    Ok(())
}

/// What the coordinator would refuse, refused before it is started and the
/// library built: the stopping rule, ε and (for a built-in case, which
/// opens in milliseconds) the surrogate and the vehicle under test `vut`.
fn check_before_starting(args: &DemoArgs, vut: &str) -> anyhow::Result<()> {
    crate::inputs::check_epsilon(args.exploration.epsilon)?;
    tslg_method::estimator::StoppingRule::new(args.beta, args.max_tests)
        .validate()
        .map_err(|e| anyhow::anyhow!("--{e}"))?;
    if args.case.case_file.is_none() {
        let case = crate::inputs::open(&args.case)?;
        let surrogate = surrogate_or_default(&args.case, &args.surrogate)?;
        crate::inputs::vehicle_spec(case.as_ref(), surrogate, "surrogate")?;
        crate::inputs::vehicle_spec(case.as_ref(), vut, "vehicle under test")?;
    }
    Ok(())
}

/// `--vut`; else the case's demo vehicle, one that is not the surrogate
/// (on cut-in the FVDM, which fails where the IDM library does not), when
/// the surrogate is the case's own; else the surrogate.
fn demo_vut(args: &DemoArgs) -> anyhow::Result<String> {
    let descriptor = case_descriptor(&args.case)?;
    Ok(match (&args.vut, descriptor.demo_vut) {
        (Some(vut), _) => vut.clone(),
        (None, Some(vut)) if args.surrogate.is_none() => vut.to_owned(),
        (None, _) => surrogate_or_default(&args.case, &args.surrogate)?.to_owned(),
    })
}

fn print_table(args: &DemoArgs, views: &[CampaignView], report: Option<&ExactReport>) {
    let by_library = &views[0];
    let by_ndd = &views[views.len() - 1];
    let exact = report.map(|r| r.probability);
    let interval = |v: &CampaignView| (v.ci_low.unwrap_or(f64::NAN), v.ci_high.unwrap_or(f64::NAN));
    outln!(
        "\nvehicle under test {}, β {}, confidence 0.9, ε {}, seed {}\n",
        crate::inputs::vehicle_name(&by_library.vut, &by_library.case),
        args.beta,
        args.exploration.epsilon,
        args.seed
    );
    outln!(
        "{:<8} {:>10} {:>7} {:>11} {:>25} {:>8} {:>10}",
        "method",
        "tests",
        "events",
        "estimate",
        "90% interval",
        if exact.is_some() { "covers" } else { "" },
        "status"
    );
    for v in views {
        let name = v.method.as_str();
        let (lo, hi) = interval(v);
        let covers = match exact {
            Some(p) if lo <= p && p <= hi => "yes",
            Some(_) => "no",
            None => "",
        };
        outln!(
            "{:<8} {:>10} {:>7} {:>11.3e} {:>25} {:>8} {:>10}",
            name,
            v.indices,
            v.events,
            v.estimate.unwrap_or(f64::NAN),
            format!("[{lo:.3e}, {hi:.3e}]"),
            covers,
            v.status.as_str()
        );
    }
    outln!();
    for v in views {
        outln!(
            "{:<8} assumes {}",
            v.method.as_str(),
            v.method.spec().rests_on
        );
        if let Some(a) = &v.adaptive {
            outln!(
                "{:<8}   ({} library and {} search tests found where the vehicle fails; {} \
                 estimation tests)",
                "",
                a.library_tests,
                a.search_tests,
                v.tests
            );
            if let (Some(upper), Some(guarded)) = (v.outside_upper, v.guarded_ci_high) {
                outln!(
                    "{:<8}   without that assumption: up to {upper:.3e} of failure mass outside \
                     its support ({} exploring tests), guarded upper end {guarded:.3e}",
                    "",
                    v.outside_tests
                );
            }
        }
    }
    print_outside(by_library, exact);
    let measured = by_ndd.tests as f64 / by_library.indices.max(1) as f64;
    if let Some(adaptive) = views.iter().find(|v| v.method.in_stages()) {
        outln!(
            "\nNDD tests / adaptive tests: {} measured",
            crate::output::ratio(by_ndd.tests as f64 / adaptive.indices.max(1) as f64)
        );
    }
    let Some(report) = report else {
        let ((a, b), (c, d)) = (interval(by_library), interval(by_ndd));
        outln!(
            "\nno exact P(A) for this case (its scenarios are sequences); the intervals {}",
            if a <= d && c <= b {
                "overlap"
            } else {
                "do not overlap"
            }
        );
        let at_least = if by_ndd.status == tslg_api::CampaignStatus::Converged {
            ""
        } else {
            "at least "
        };
        outln!(
            "acceleration ratio (NDD tests / library tests): {at_least}{} measured",
            crate::output::ratio(measured)
        );
        print_takeaway(views, None);
        return;
    };
    let exact = report.probability;
    outln!("\nexact P(A) by enumeration: {exact:.4e}");
    let misses = views.iter().any(|v| {
        let (lo, hi) = interval(v);
        !(lo <= exact && exact <= hi)
    });
    if misses {
        outln!(
            "note: a 90% interval misses the exact value in about one run in ten by design, \
             more often when a campaign stops at n_min; see docs/statistics.md"
        );
    }
    if report.library_tests > 10.0 * by_library.tests as f64 {
        outln!(
            "warning: the library's analytic variance needs about {:.0} tests and the campaign \
             stopped after {}: this vehicle fails mostly outside the surrogate's library, and \
             the heavy-weight tests that would correct the estimate have not come up yet. \
             Trust the adaptive campaign or the NDD baseline (see docs/models.md on the \
             surrogate's coverage).",
            report.library_tests,
            by_library.tests
        );
    }
    outln!(
        "acceleration ratio (NDD tests / library tests): {} measured, {} analytic ({:.0} / {:.0} expected tests)",
        crate::output::ratio(measured),
        crate::output::ratio(report.ratio()),
        report.ndd_tests,
        report.library_tests
    );
    print_takeaway(views, Some(exact));
}

/// The demo's last line: what a user should take away. Where an adaptive
/// campaign ran it is the answer the demo teaches (it learns where this
/// vehicle fails instead of trusting the surrogate); the library
/// campaign's speed-up is only as good as the library's cover, which the
/// line says when its interval missed the exact value.
fn print_takeaway(views: &[CampaignView], exact: Option<f64>) {
    let by_library = &views[0];
    let by_ndd = &views[views.len() - 1];
    let Some(adaptive) = views.iter().find(|v| v.method.in_stages()) else {
        return;
    };
    let holds = |v: &CampaignView| match (exact, v.ci_low, v.ci_high) {
        (Some(p), Some(lo), Some(hi)) => Some(lo <= p && p <= hi),
        _ => None,
    };
    let (lo, hi) = (
        adaptive.ci_low.unwrap_or(f64::NAN),
        adaptive.ci_high.unwrap_or(f64::NAN),
    );
    let verdict = match holds(adaptive) {
        Some(true) => ", and it holds the exact value",
        Some(false) => ", and it misses the exact value (one run in ten does, by design)",
        None => "",
    };
    let library = match holds(by_library) {
        Some(false) => {
            "; the library campaign's speed-up is not an answer here: its interval misses, \
             because the library does not hold this vehicle's failures"
        }
        _ => {
            "; the library campaign's speed-up holds only where the library holds the \
              vehicle's failures"
        }
    };
    // What the answer rests on, with what it would be without it.
    let rests = match adaptive.guarded_ci_high {
        Some(guarded) => {
            format!(" (if its search reached every failure; without that, up to {guarded:.3e})")
        }
        None => " (if its search reached every failure)".to_owned(),
    };
    outln!(
        "\ntake away: the adaptive campaign answered P(A) in [{lo:.3e}, {hi:.3e}]{rests} after \
         {} tests, {}× fewer than the NDD baseline{verdict}{library}.",
        adaptive.indices,
        crate::output::ratio(by_ndd.tests as f64 / adaptive.indices.max(1) as f64),
    );
}

/// The library campaign's outside bound, guarded interval and warnings
/// (grid cases; docs/statistics.md).
fn print_outside(by_library: &CampaignView, exact: Option<f64>) {
    if let (Some(upper), Some(lo), Some(high)) = (
        by_library.outside_upper,
        by_library.ci_low,
        by_library.guarded_ci_high,
    ) {
        let covers = match exact {
            Some(p) if lo <= p && p <= high => ", covers the exact value",
            Some(_) => ", misses the exact value",
            None => "",
        };
        outln!(
            "\nlibrary: failure mass outside the library ≤ {upper:.3e} ({} exploring tests, {} \
             events); guarded interval [{lo:.3e}, {high:.3e}]{covers}",
            by_library.outside_tests,
            by_library.outside_events
        );
    }
    for warning in &by_library.warnings {
        outln!("warning: {}", Dialect::Cli.translate(warning));
    }
}
