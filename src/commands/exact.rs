//! `tslg exact`: exact P(A) of each built-in vehicle by enumeration, and the
//! analytic number of tests a library campaign and the NDD baseline need.

use crate::inputs::{check_epsilon, load_case, parse_vehicle};
use crate::{CaseArgs, ExactArgs};
use anyhow::Context;
use tslg_method::case::Case;
use tslg_method::cases::cutin::CutIn;
use tslg_method::estimator::{z_for_confidence, StoppingRule};
use tslg_method::exact::exact_report;
use tslg_method::library::{build_library, LibraryRequest, SearchMethod, Threshold};
use tslg_method::sampling::{LibraryDistribution, OutsideSpread, Split};
use tslg_method::vehicle::{VehicleModel, BUILTIN_MODELS};

pub fn run(args: &ExactArgs) -> anyhow::Result<()> {
    check_epsilon(args.epsilon)?;
    // The ranges a campaign takes (the rule's other fields do not matter here).
    StoppingRule {
        beta: args.beta,
        confidence: args.confidence,
        ..StoppingRule::new(args.beta, tslg_method::estimator::MAX_TESTS_LIMIT)
    }
    .validate()
    .map_err(|e| anyhow::anyhow!("--{e}"))?;
    let surrogate = parse_vehicle(&args.surrogate, "surrogate")?;
    let builtin = load_case(&CaseArgs {
        ndd_table: None,
        ..args.case.clone()
    })?;
    print_table(&builtin, &surrogate, args)?;
    if args.case.ndd_table.is_some() {
        println!();
        print_table(&load_case(&args.case)?, &surrogate, args)?;
    }
    Ok(())
}

fn print_table(case: &CutIn, surrogate: &VehicleModel, args: &ExactArgs) -> anyhow::Result<()> {
    let library = build_library(
        case,
        surrogate,
        serde_json::to_value(surrogate)?,
        case.preset().name(),
        &LibraryRequest {
            threshold: Threshold::default(),
            search: SearchMethod::Exhaustive,
        },
    );
    let q = LibraryDistribution::new(
        &library,
        case.exposure(),
        args.epsilon,
        OutsideSpread::Uniform,
        // The analytic figures are the mixture's, `Var_q(P A/q)`.
        Split::Random,
    )
    .context("the surrogate's library is empty")?;
    let z = z_for_confidence(args.confidence);
    println!(
        "exposure {} | preset {} | library of {} ({} cells), epsilon {}, beta {}, confidence {}",
        case.exposure_name(),
        case.preset(),
        surrogate.name(),
        library.size(),
        args.epsilon,
        args.beta,
        args.confidence
    );
    println!(
        "{:<14} {:>12} {:>14} {:>14} {:>10}",
        "vehicle", "exact P(A)", "library tests", "NDD tests", "ratio"
    );
    for name in BUILTIN_MODELS {
        let vut = VehicleModel::builtin(name)?;
        let r = exact_report(case, &vut, &q, args.beta, z);
        println!(
            "{:<14} {:>12.4e} {:>14.1} {:>14.0} {:>10.1}",
            name,
            r.probability,
            r.library_tests,
            r.ndd_tests,
            r.ratio()
        );
    }
    Ok(())
}
