//! `tslg evaluate`: one campaign in this process.

use crate::inputs::{check_epsilon, load_case, parse_vehicle, read_library, stopping_rule};
use crate::{EvaluateArgs, EvaluateMethodArg as MethodArg, OutsideArg};
use anyhow::Context;
use serde::Serialize;
use tslg_method::adaptive::{run_adaptive, AdaptiveSettings};
use tslg_method::campaign::{run_campaign, CampaignResult};
use tslg_method::case::Case;
use tslg_method::exact::{event_cells, event_probability};
use tslg_method::sampling::{LibraryDistribution, NddDistribution, TestDistribution};
use tslg_method::vehicle::VehicleModel;
use tslg_method::warnings::{warnings, Dialect, WarningContext};

#[derive(Serialize)]
struct Report {
    method: &'static str,
    vut: &'static str,
    #[serde(flatten)]
    result: CampaignResult,
    /// Adaptive campaigns: the tests spent finding the failures.
    #[serde(skip_serializing_if = "Option::is_none")]
    search: Option<Search>,
    exact: f64,
    covers_exact: bool,
    warnings: Vec<String>,
}

/// What an adaptive campaign spent finding the vehicle's failures, and
/// where its estimation stage sampled.
#[derive(Serialize)]
struct Search {
    library_tests: u64,
    search_tests: u64,
    stages: u64,
    /// Cells the last estimation stage sampled besides its exploring share.
    support_cells: usize,
    /// The cells of the support.
    #[serde(skip)]
    support: Vec<usize>,
}

pub fn run(args: &EvaluateArgs) -> anyhow::Result<()> {
    check_epsilon(args.exploration.epsilon)?;
    if args.case.case == "car-following" {
        return super::evaluate_follow::run(args);
    }
    if args.surrogate.is_some() {
        anyhow::bail!(
            "--surrogate is for car-following, whose policy is learned in this process; a {} \
             campaign takes the surrogate of its --library file",
            args.case.case
        );
    }
    let library = match (args.method, &args.library) {
        (MethodArg::Library | MethodArg::Adaptive, None) => {
            anyhow::bail!("--library is required with --method library and adaptive")
        }
        (MethodArg::Library | MethodArg::Adaptive, Some(path)) => Some(read_library(path)?),
        (MethodArg::Ndd, _) => None,
    };
    // The tests run on the simulation the library was built on: its preset,
    // unless --preset says the same.
    let mut case_args = args.case.clone();
    if let Some(library) = &library {
        match &case_args.preset {
            None => case_args.preset = Some(library.preset.clone()),
            Some(preset) if *preset != library.preset => anyhow::bail!(
                "--preset {preset}: the library was built on preset {}, and its criticality \
                 means nothing on another simulation; leave --preset out or build the library \
                 with --preset {preset}",
                library.preset
            ),
            Some(_) => {}
        }
    }
    let case = load_case(&case_args)?;
    let vut = parse_vehicle(&args.vut, "vehicle under test")?;
    let rule = stopping_rule(
        &args.rule,
        tslg_method::cases::descriptor(&args.case.case)?
            .exploring_share(args.method == MethodArg::Library, args.exploration.epsilon),
    )?;
    let (result, search) = if args.method == MethodArg::Adaptive {
        let library = library.as_ref().expect("read above for --method adaptive");
        library.check_matches(&case)?;
        let adaptive = run_adaptive(
            &case,
            &vut,
            library,
            args.exploration.epsilon,
            AdaptiveSettings::default(),
            &rule,
            args.seed,
        )?;
        let search = Search {
            library_tests: adaptive.library_tests,
            search_tests: adaptive.search_tests,
            stages: adaptive.stages,
            support_cells: adaptive.support.len(),
            support: adaptive.support,
        };
        (adaptive.result, Some(search))
    } else {
        (sampled(args, &case, &vut, &rule, library.as_ref())?, None)
    };
    report(args, &case, &vut, &rule, result, search)
}

/// A library or NDD campaign of `vut`.
fn sampled(
    args: &EvaluateArgs,
    case: &tslg_method::cases::cutin::CutIn,
    vut: &VehicleModel,
    rule: &tslg_method::estimator::StoppingRule,
    library: Option<&tslg_method::library::Library>,
) -> anyhow::Result<CampaignResult> {
    let (distribution, surrogate) = match args.method {
        MethodArg::Ndd | MethodArg::Adaptive => (
            TestDistribution::Ndd(NddDistribution::new(case.exposure())),
            None,
        ),
        MethodArg::Library => {
            let library = library.expect("read above for --method library");
            library.check_matches(case)?;
            let outside = args
                .exploration
                .outside
                .map_or(Default::default(), OutsideArg::spread);
            let surrogate: VehicleModel = serde_json::from_value(library.surrogate.clone())
                .context("the library's surrogate is not a built-in cut-in model")?;
            let distribution = TestDistribution::library(
                LibraryDistribution::new(
                    library,
                    case.exposure(),
                    args.exploration.epsilon,
                    outside,
                    args.exploration.split.split(),
                )
                .context("cannot sample from this library")?,
            );
            (distribution, Some(surrogate))
        }
    };
    Ok(run_campaign(
        case,
        vut,
        surrogate.as_ref(),
        &distribution,
        rule,
        args.seed,
    ))
}

fn report(
    args: &EvaluateArgs,
    case: &tslg_method::cases::cutin::CutIn,
    vut: &VehicleModel,
    rule: &tslg_method::estimator::StoppingRule,
    result: CampaignResult,
    search: Option<Search>,
) -> anyhow::Result<()> {
    // Cut-in vehicles are deterministic on a 3,420-cell grid: the exact answer is cheap.
    let events = event_cells(case, vut);
    let exact = event_probability(case, &events);
    let report = Report {
        method: match args.method {
            MethodArg::Library => "library",
            MethodArg::Adaptive => "adaptive",
            MethodArg::Ndd => "ndd",
        },
        vut: vut.name(),
        result,
        search,
        exact,
        covers_exact: result.covers(exact),
        warnings: warnings(
            &result,
            WarningContext {
                beta: rule.beta,
                guard_outside: rule.guard_outside,
                dialect: Dialect::Cli,
            },
        ),
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    println!("method             {}", report.method);
    println!("vehicle under test {}", report.vut);
    println!("status             {}", result.status.as_str());
    if let Some(search) = &report.search {
        println!(
            "tests              {} ({} library, {} searching, {} estimating; {} stages)",
            result.indices, search.library_tests, search.search_tests, result.tests, search.stages
        );
        let held: f64 = search
            .support
            .iter()
            .filter(|c| events.binary_search(c).is_ok())
            .map(|&c| case.exposure().p(c))
            .sum();
        println!(
            "sampled cells      {} holding {:.1}% of the exact P(A); the rest only the exploring \
             tests meet",
            search.support_cells,
            100.0 * held / exact
        );
        println!(
            "assumes            the vehicle's failures outside the library are reachable from the \
             scenarios its tests met through failures and near misses (docs/adaptive-design.md)"
        );
    } else {
        println!("tests              {}", result.tests);
    }
    print_estimate(&result, rule);
    println!(
        "exact P(A)         {:.4e} ({})",
        exact,
        if report.covers_exact {
            "inside the interval"
        } else {
            "OUTSIDE the interval"
        }
    );
    if let (Some(upper), Some(high)) = (result.outside_upper, result.guarded_ci_high) {
        println!(
            "outside library    {} exploring tests, {} events; failure mass there ≤ {upper:.4e}",
            result.outside_tests, result.outside_events
        );
        println!(
            "guarded interval   [{:.4e}, {high:.4e}] (exact {})",
            result.ci_low,
            if result.guarded_covers(exact) {
                "inside"
            } else {
                "OUTSIDE"
            }
        );
    }
    for warning in &report.warnings {
        println!("warning: {warning}");
    }
    Ok(())
}

/// The events, estimate, interval and relative half-width of `result`.
pub(super) fn print_estimate(result: &CampaignResult, rule: &tslg_method::estimator::StoppingRule) {
    println!("events             {}", result.events);
    println!("estimate           {:.4e}", result.estimate);
    println!(
        "{:.0}% interval       [{:.4e}, {:.4e}]",
        100.0 * rule.confidence,
        result.ci_low,
        result.ci_high
    );
    println!(
        "relative half-width {:.4} (beta {})",
        result.relative_half_width, rule.beta
    );
}
