//! `tslg evaluate`: one campaign in this process.

use crate::inputs::{check_epsilon, load_case, parse_vehicle, read_library, stopping_rule};
use crate::{EvaluateArgs, MethodArg, OutsideArg};
use anyhow::Context;
use serde::Serialize;
use tslg_method::campaign::{run_campaign, CampaignResult};
use tslg_method::case::Case;
use tslg_method::exact::{event_cells, event_probability};
use tslg_method::registry::exploring_share;
use tslg_method::sampling::{LibraryDistribution, NddDistribution, TestDistribution};
use tslg_method::vehicle::VehicleModel;
use tslg_method::warnings::{warnings, Dialect, WarningContext};

#[derive(Serialize)]
struct Report {
    method: &'static str,
    vut: &'static str,
    #[serde(flatten)]
    result: CampaignResult,
    exact: f64,
    covers_exact: bool,
    warnings: Vec<String>,
}

pub fn run(args: &EvaluateArgs) -> anyhow::Result<()> {
    check_epsilon(args.exploration.epsilon)?;
    let library = match (args.method, &args.library) {
        (MethodArg::Library, None) => anyhow::bail!("--library is required with --method library"),
        (MethodArg::Library, Some(path)) => Some(read_library(path)?),
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
        exploring_share(
            &args.case.case,
            args.method == MethodArg::Library,
            args.exploration.epsilon,
        ),
    )?;
    let (distribution, surrogate) = match args.method {
        MethodArg::Ndd => (
            TestDistribution::Ndd(NddDistribution::new(case.exposure())),
            None,
        ),
        MethodArg::Library => {
            let library = library.as_ref().expect("read above for --method library");
            library.check_matches(&case)?;
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
    let result = run_campaign(
        &case,
        &vut,
        surrogate.as_ref(),
        &distribution,
        &rule,
        args.seed,
    );
    // Cut-in vehicles are deterministic on a 3,420-cell grid: the exact answer is cheap.
    let exact = event_probability(&case, &event_cells(&case, &vut));
    let report = Report {
        method: match args.method {
            MethodArg::Library => "library",
            MethodArg::Ndd => "ndd",
        },
        vut: vut.name(),
        result,
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
    println!("status             {:?}", result.status);
    println!("tests              {}", result.tests);
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
