//! `tslg demo`: the whole method in one command, in this process. Builds the
//! paper's IDM library on the chosen exposure, then evaluates every built-in
//! vehicle with the library and with the NDD baseline and prints both beside
//! the exact answer.

use crate::inputs::load_case;
use crate::DemoArgs;
use std::time::Instant;
use tslg_method::campaign::run_campaign;
use tslg_method::case::Case;
use tslg_method::estimator::StoppingRule;
use tslg_method::exact::{event_cells, event_probability};
use tslg_method::library::{build_library, LibraryRequest, SearchMethod, Threshold};
use tslg_method::sampling::{
    LibraryDistribution, NddDistribution, OutsideSpread, TestDistribution,
};
use tslg_method::vehicle::{VehicleModel, BUILTIN_MODELS};

pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    let case = load_case(&args.case)?;
    let rule = StoppingRule::new(args.beta, 10_000_000);
    rule.validate()?;
    let surrogate = VehicleModel::builtin("idm")?;
    let started = Instant::now();
    let library = build_library(
        &case,
        &surrogate,
        serde_json::to_value(surrogate)?,
        case.preset().name(),
        &LibraryRequest {
            threshold: Threshold::default(),
            search: SearchMethod::Multistart {
                starts: 50,
                seed: 0,
            },
        },
    );
    println!(
        "cut-in, exposure {}, preset {}: IDM library of {} of {} scenarios, {} SM evaluations, {:.2} s",
        case.exposure_name(),
        case.preset(),
        library.size(),
        library.total_scenarios(),
        library.search.sm_evaluations,
        started.elapsed().as_secs_f64()
    );
    let by_library = TestDistribution::library(LibraryDistribution::new(
        &library,
        case.exposure(),
        0.1,
        OutsideSpread::Uniform,
    )?);
    let by_ndd = TestDistribution::Ndd(NddDistribution::new(case.exposure()));
    println!(
        "beta {}, confidence {}, epsilon 0.1, seed {}\n",
        rule.beta, rule.confidence, args.seed
    );
    println!(
        "{:<14} {:>11} {:>11} {:>25} {:>8} {:>11} {:>8} {:>7}",
        "vehicle", "exact P(A)", "library", "90% interval", "tests", "NDD", "tests", "ratio"
    );
    for name in BUILTIN_MODELS {
        let vut = VehicleModel::builtin(name)?;
        let exact = event_probability(&case, &event_cells(&case, &vut));
        let lib = run_campaign(&case, &vut, &by_library, &rule, args.seed);
        let ndd = run_campaign(&case, &vut, &by_ndd, &rule, args.seed);
        println!(
            "{:<14} {:>11.3e} {:>11.3e} {:>25} {:>8} {:>11.3e} {:>8} {:>7.0}{}",
            name,
            exact,
            lib.estimate,
            format!("[{:.2e}, {:.2e}]", lib.ci_low, lib.ci_high),
            lib.tests,
            ndd.estimate,
            ndd.tests,
            ndd.tests as f64 / lib.tests as f64,
            if lib.covers(exact) {
                ""
            } else {
                "  (library interval misses the exact value)"
            }
        );
    }
    Ok(())
}
