//! `tslg evaluate --case car-following`: one car-following campaign in this
//! process. The library is the policy of `--surrogate`, learned here by
//! dynamic programming (a fraction of a second); no exact answer exists for
//! 33-dimensional scenarios, so none is printed.

use crate::inputs::stopping_rule;
use crate::{EvaluateArgs, EvaluateMethodArg as MethodArg, OutsideArg};
use anyhow::Context;
use serde::Serialize;
use std::sync::Arc;
use tslg_method::campaign::{run_indexed_campaign, CampaignResult};
use tslg_method::cases::carfollow::adaptive::{
    run_follow_adaptive, FollowAdaptiveSettings, FollowPlanner,
};
use tslg_method::cases::carfollow::{CarFollowing, FollowPreset, FollowSampler, PolicySolver};
use tslg_method::sampling::OutsideSpread;
use tslg_method::vehicle::VehicleModel;
use tslg_method::warnings::{warnings, Dialect, WarningContext};

#[derive(Serialize)]
struct Report {
    method: &'static str,
    vut: serde_json::Value,
    #[serde(flatten)]
    result: CampaignResult,
    /// Adaptive campaigns: what learning the vehicle cost.
    #[serde(skip_serializing_if = "Option::is_none")]
    learning: Option<Learning>,
    warnings: Vec<String>,
}

#[derive(Serialize)]
struct Learning {
    library_tests: u64,
    probes: u64,
    probe_decisions: u64,
    dangerous_probed: u64,
    stages: u64,
    /// Library and estimation tests plus the probes' decisions in tests of
    /// 30 decisions: the vehicle's driving the campaign cost.
    test_equivalents: f64,
}

/// A car-following vehicle: a built-in name or a JSON specification, with
/// the case's defaults for what it leaves out ([`CarFollowing::vehicle`]).
fn follow_vehicle(text: &str, what: &str) -> anyhow::Result<VehicleModel> {
    let spec = if text.trim_start().starts_with('{') {
        serde_json::from_str(text).with_context(|| format!("invalid {what} specification"))?
    } else {
        serde_json::json!({ "model": text })
    };
    CarFollowing::vehicle(&spec).map_err(|e| anyhow::anyhow!("invalid {what}: {e}"))
}

pub fn run(args: &EvaluateArgs) -> anyhow::Result<()> {
    if args.case.ndd_table.is_some() {
        anyhow::bail!("--ndd-table: car-following has only its built-in exposure model");
    }
    if args.library.is_some() {
        anyhow::bail!(
            "--library: a car-following library is learned in this process from --surrogate \
             (default idm)"
        );
    }
    let preset: FollowPreset = match &args.case.preset {
        None => FollowPreset::Paper,
        Some(p) => p.parse().map_err(|e: String| anyhow::anyhow!(e))?,
    };
    let vut = follow_vehicle(&args.vut, "vehicle under test")?;
    let rule = stopping_rule(&args.rule, None)?;
    if rule.guard_outside {
        anyhow::bail!(
            "--guard-outside applies to the grid cases (cut-in, highway-exit): a car-following \
             campaign explores per decision, and no bound on its outside mass is defined"
        );
    }
    let case = Arc::new(CarFollowing::new(preset));
    let outside = args
        .exploration
        .outside
        .map_or(OutsideSpread::Ndd, OutsideArg::spread);
    let learn = || -> anyhow::Result<_> {
        let surrogate = follow_vehicle(args.surrogate.as_deref().unwrap_or("idm"), "surrogate")?;
        let learned = case
            .learn(&surrogate, PolicySolver::DynamicProgramming)
            .map_err(|e| anyhow::anyhow!("the library could not be learned: {e}"))?;
        Ok((surrogate, Arc::new(learned.library)))
    };
    let epsilon = args.exploration.epsilon;
    let sampled = |sampler: FollowSampler| {
        run_indexed_campaign(
            &|i| {
                let t = sampler.run(&vut, args.seed, i);
                t.accident.then(|| t.weight())
            },
            &rule,
        )
    };
    let (result, learning) = match args.method {
        MethodArg::Ndd => (sampled(case.ndd_sampler()), None),
        MethodArg::Library => {
            let (_, library) = learn()?;
            let sampler = FollowSampler::library(
                case.world,
                case.grid,
                &case.exposure,
                library,
                epsilon,
                outside,
            )
            .context("cannot sample from this library")?;
            (sampled(sampler), None)
        }
        MethodArg::Adaptive => {
            let (surrogate, library) = learn()?;
            let planner = FollowPlanner::new(
                Arc::clone(&case),
                &surrogate,
                library,
                epsilon,
                outside,
                FollowAdaptiveSettings::default(),
            )?;
            let r = run_follow_adaptive(&planner, &vut, &rule, args.seed)?;
            let learning = Learning {
                library_tests: r.library_tests,
                probes: r.probes,
                probe_decisions: r.probe_decisions,
                dangerous_probed: r.dangerous_probed,
                stages: r.stages,
                test_equivalents: r.test_equivalents(case.world.decisions),
            };
            (r.result, Some(learning))
        }
    };
    let report = Report {
        method: match args.method {
            MethodArg::Library => "library",
            MethodArg::Adaptive => "adaptive",
            MethodArg::Ndd => "ndd",
        },
        vut: serde_json::to_value(vut)?,
        result,
        learning,
        warnings: warnings(
            &result,
            WarningContext {
                beta: rule.beta,
                guard_outside: false,
                dialect: Dialect::Cli,
            },
        ),
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    print(&report, &rule, preset);
    Ok(())
}

fn print(report: &Report, rule: &tslg_method::estimator::StoppingRule, preset: FollowPreset) {
    let result = &report.result;
    println!("case               car-following, preset {}", preset.name());
    println!("method             {}", report.method);
    println!("vehicle under test {}", report.vut);
    println!("status             {}", result.status.as_str());
    match &report.learning {
        Some(l) => {
            println!(
                "tests              {} library, {} estimating; {} states probed ({} dangerous \
                 for the vehicle, {} decisions); {} stages",
                l.library_tests,
                result.tests,
                l.probes,
                l.dangerous_probed,
                l.probe_decisions,
                l.stages
            );
            println!(
                "driving            {:.0} tests' worth (probes' decisions / 30 added)",
                l.test_equivalents
            );
            println!(
                "assumes            the vehicle's failures lie in the region, connected to the \
                 accidents its tests met, where it is dangerous and unlike the surrogate \
                 (docs/adaptive-design.md)"
            );
        }
        None => println!("tests              {}", result.tests),
    }
    super::evaluate::print_estimate(result, rule);
    println!("exact P(A)         none: no enumeration reaches 33-dimensional scenarios");
    for warning in &report.warnings {
        println!("warning: {warning}");
    }
}
