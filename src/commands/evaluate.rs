//! `tslg evaluate`: one campaign in this process, on any case, through its
//! descriptor and the registry: the NDD baseline, a library campaign, or an
//! adaptive one. On a grid case small enough to enumerate
//! ([`tslg_api::EXACT_MAX_SCENARIOS`]) the exact P(A) is printed beside it.

use crate::args::{
    search_for_method, search_parser, CaseArgs, ExplorationArgs, OutsideArg, RuleArgs,
};
use crate::commands::exact::exact_answer;
use crate::inputs::{
    case_of_library, check_epsilon, open, read_library_file, stopping_rule, vehicle_spec,
};
use clap::Args;
use serde::Serialize;
use std::path::PathBuf;
use tslg_api::{AdaptiveSearch, Method};
use tslg_method::campaign::{run_campaign_tests, Answer, AnswerContext, CampaignResult};
use tslg_method::estimator::{Interval, StoppingRule};
use tslg_method::registry::{AdaptiveRun, ScenarioCase};
use tslg_method::sampling::default_outside;
use tslg_method::warnings::{warnings, Dialect, WarningContext};

#[derive(Debug, Args)]
pub struct EvaluateArgs {
    #[command(flatten)]
    pub case: CaseArgs,
    /// The vehicle under test: a built-in name or a JSON specification.
    #[arg(long)]
    pub vut: String,
    /// How the campaign draws its tests (docs/statistics.md,
    /// docs/adaptive-design.md).
    #[arg(long, value_parser = crate::args::method_parser(), default_value = "library")]
    pub method: Method,
    /// The library file (methods `library` and `adaptive`), as `tslg
    /// library build` writes it: the campaign runs on its case and preset
    /// (with `ndd`, the baseline runs on them too).
    #[arg(long)]
    pub library: Option<PathBuf>,
    /// How an adaptive campaign searches: `grid` (the default) or
    /// `lattice` (a fine grid's coarser lattice, whole blocks into the
    /// support; docs/adaptive-design.md, "Fine grids").
    #[arg(long, value_parser = search_parser())]
    pub adaptive_search: Option<AdaptiveSearch>,
    /// Tests of an adaptive campaign's estimation stages (a multiple of 20,
    /// 20 to 100000): a service campaign's `stage_tests`, to replay it.
    #[arg(long, default_value_t = 100)]
    pub stage_tests: u64,
    #[command(flatten)]
    pub exploration: ExplorationArgs,
    #[command(flatten)]
    pub rule: RuleArgs,
    /// Campaign seed: test i is determined by (seed, i).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// A paired regression campaign: test this vehicle too (a built-in name
    /// or a JSON specification) on the same tests, and estimate the
    /// difference of the two rates (--vut's minus this one's) from the
    /// same draws (methods library and ndd; docs/statistics.md).
    #[arg(long, value_name = "VUT")]
    pub paired_with: Option<String>,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct Report {
    case: &'static str,
    #[serde(skip)]
    grid: bool,
    preset: String,
    method: &'static str,
    vut: serde_json::Value,
    #[serde(flatten)]
    result: CampaignResult,
    /// Adaptive campaigns: the tests spent finding the failures.
    #[serde(skip_serializing_if = "Option::is_none")]
    search: Option<Search>,
    /// The interval to report, and why ([`tslg_method::campaign::answer`]).
    answer: AnswerOut,
    /// The exact P(A) by enumeration, where the case has one this size.
    exact: Option<f64>,
    /// Whether the answer's interval holds it.
    covers_exact: Option<bool>,
    /// The vehicle sets parameters that differ from its model's defaults,
    /// and its exact P(A) on this preset equals the defaults' to the bit:
    /// they change no accident here (the README's `{"model": "idm",
    /// "v0": 25}` on paper-code). `None` where it was not checked.
    #[serde(skip_serializing_if = "Option::is_none")]
    parameters_inert: Option<bool>,
    warnings: Vec<String>,
}

/// The interval a campaign answers with, as JSON.
#[derive(Serialize)]
struct AnswerOut {
    interval: tslg_method::campaign::AnswerInterval,
    low: f64,
    high: f64,
    reason: &'static str,
}

impl From<Answer> for AnswerOut {
    fn from(a: Answer) -> Self {
        Self {
            interval: a.interval,
            low: a.low,
            high: a.high,
            reason: a.reason.text(),
        }
    }
}

/// What an adaptive campaign spent finding the vehicle's failures, and
/// where its estimation stage sampled.
#[derive(Serialize)]
struct Search {
    library_tests: u64,
    /// Search tests (grid cases) or states probed (car-following).
    search_tests: u64,
    stages: u64,
    /// The vehicle's driving in tests' worth (car-following counts its
    /// probes' decisions).
    driving: f64,
    /// Cells the last estimation stage sampled besides its exploring share
    /// (grid cases).
    support_cells: usize,
    #[serde(skip)]
    assumes: &'static str,
    #[serde(skip)]
    search_kind: &'static str,
    /// `grid` or `lattice` (`--adaptive-search`); grid cases only.
    #[serde(skip_serializing_if = "Option::is_none")]
    adaptive_search: Option<&'static str>,
}

/// What a campaign runs on, worked out from the arguments: the case (the
/// library's, where one is given), the vehicle, the rule, and the library
/// file the method samples from.
struct Setup {
    case: std::sync::Arc<dyn ScenarioCase>,
    descriptor: tslg_method::cases::CaseDescriptor,
    vut: serde_json::Value,
    rule: StoppingRule,
    outside: tslg_method::sampling::OutsideSpread,
    /// The library file, for methods `library` and `adaptive`.
    file: Option<Vec<u8>>,
}

/// Runs `tslg evaluate`.
pub fn run(args: &EvaluateArgs) -> anyhow::Result<()> {
    let setup = set_up(args)?;
    if let Some(other) = &args.paired_with {
        let file = setup.file.as_deref().filter(|_| args.method.uses_library());
        let plan = crate::commands::paired::Plan {
            case: setup.case.as_ref(),
            file,
            epsilon: args.exploration.epsilon,
            outside: setup.outside,
            split: args.exploration.split.split(),
            seed: args.seed,
        };
        return crate::commands::paired::run(&plan, &setup.vut, other, &setup.rule, args.json);
    }
    let (result, search) = run_campaign(args, &setup)?;
    let report = report(args, &setup, result, search);
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    print(&report, &setup.rule);
    Ok(())
}

/// The arguments checked and the case, vehicle, rule and library read.
fn set_up(args: &EvaluateArgs) -> anyhow::Result<Setup> {
    // What is wrong in a value is said before what is missing: a rule out
    // of range, or a case that does not exist, before `--library`.
    stopping_rule(&args.rule, None, false)?;
    if args.case.case.is_some() {
        crate::inputs::case_descriptor(&args.case)?;
    }
    check_epsilon(args.exploration.epsilon)?;
    search_for_method(args.adaptive_search, args.method)?;
    anyhow::ensure!(
        args.paired_with.is_none() || args.method.spec().pairs,
        "--paired-with runs library and ndd campaigns: an adaptive campaign's stages follow \
         one vehicle's failures"
    );
    let library = match (args.method.uses_library(), &args.library) {
        (true, None) => {
            anyhow::bail!("--library is required with --method {}", args.method)
        }
        // An NDD baseline beside a library runs on the library's case and
        // preset (it samples the exposure, not the library).
        (_, Some(path)) => Some(read_library_file(path)?),
        (false, None) => None,
    };
    // The tests run on the case and simulation the library was built on.
    let case_args = match &library {
        Some((_, head)) => case_of_library(&args.case, head)?,
        None => args.case.clone(),
    };
    let case = open(&case_args)?;
    let descriptor = case.descriptor().clone();
    let vut = vehicle_spec(case.as_ref(), &args.vut, "vehicle under test")?;
    let guardable =
        descriptor.is_grid() && args.method.spec().explores && args.rule.interval == Interval::Wald;
    let rule = stopping_rule(
        &args.rule,
        descriptor.exploring_share(
            args.method.spec().waits_for_explorers,
            args.exploration.epsilon,
        ),
        tslg_method::noise::guards_by_default(tslg_method::noise::spec_is_noisy(&vut), guardable),
    )?;
    anyhow::ensure!(
        rule.interval == Interval::Wald || (descriptor.is_grid() && args.method.spec().anytime),
        "--interval anytime applies to the library and ndd campaigns of the grid cases: {}",
        if descriptor.is_grid() {
            "an adaptive campaign's stages have no confidence sequence yet"
        } else {
            "a car-following test's weight has no known largest value to bet against"
        }
    );
    anyhow::ensure!(
        rule.interval == Interval::Wald
            || !args.method.spec().explores
            || args.exploration.split == crate::args::SplitArg::Stratified,
        "--interval anytime reads one sequence per stratum of a library campaign, which needs \
         --split stratified (the default): under the random split the outside has no bound \
         that holds at every n"
    );
    anyhow::ensure!(
        (20..=100_000).contains(&args.stage_tests) && args.stage_tests.is_multiple_of(20),
        "--stage-tests must be a multiple of 20 from 20 to 100000, not {}",
        args.stage_tests
    );
    anyhow::ensure!(
        args.stage_tests == 100 || (args.method.in_stages() && descriptor.is_grid()),
        "--stage-tests sets the length of a grid case's adaptive estimation stages; use it with \
         --method adaptive on cut-in or highway-exit"
    );
    anyhow::ensure!(
        args.adaptive_search.is_none() || descriptor.is_grid(),
        "--adaptive-search applies to the grid cases: a {} adaptive campaign probes states \
         from its policy, not neighbours on a grid",
        descriptor.name
    );
    anyhow::ensure!(
        !rule.guard_outside || descriptor.is_grid(),
        "--guard-outside applies to the grid cases: a {} campaign explores per decision, and \
         no bound on its outside mass is defined",
        descriptor.name
    );
    let outside = args.exploration.outside.map_or(
        default_outside(descriptor.default_outside, &rule),
        OutsideArg::spread,
    );
    let file = library
        .filter(|_| args.method.uses_library())
        .map(|(bytes, _)| bytes);
    Ok(Setup {
        case,
        descriptor,
        vut,
        rule,
        outside,
        file,
    })
}

/// Runs the campaign the method asks for: adaptive stages, or the library
/// or NDD campaign.
fn run_campaign(
    args: &EvaluateArgs,
    setup: &Setup,
) -> anyhow::Result<(CampaignResult, Option<Search>)> {
    let Setup {
        case,
        vut,
        rule,
        outside,
        ..
    } = setup;
    // The in-process campaign's tests: the one place here a method's
    // sampler is chosen.
    Ok(match (args.method, setup.file.as_deref()) {
        (Method::Adaptive, Some(file)) => {
            let search = args.adaptive_search.unwrap_or_default();
            let run = case.adaptive_campaign(
                file,
                vut,
                args.exploration.epsilon,
                tslg_client::wire::adaptive_settings(false, search, args.stage_tests),
                rule,
                args.seed,
            )?;
            let AdaptiveRun {
                result,
                library_tests,
                search_tests,
                stages,
                driving,
                support,
                assumes,
                search_kind,
            } = run;
            let search = Search {
                library_tests,
                search_tests,
                stages,
                driving,
                support_cells: support.len(),
                assumes,
                search_kind,
                adaptive_search: setup.descriptor.is_grid().then(|| search.as_str()),
            };
            (result, Some(search))
        }
        (_, file) => {
            let file = file.filter(|_| args.method.uses_library());
            let tests = case.campaign(
                file,
                vut,
                args.exploration.epsilon,
                *outside,
                args.exploration.split.split(),
                args.seed,
            )?;
            (run_campaign_tests(tests.as_ref(), rule, &|_| false), None)
        }
    })
}

/// What the campaign gave, beside the exact answer and with its warnings.
fn report(
    args: &EvaluateArgs,
    setup: &Setup,
    result: CampaignResult,
    search: Option<Search>,
) -> Report {
    let exact = exact_answer(setup.case.as_ref(), &setup.vut);
    let answer = tslg_method::campaign::answer(
        &result,
        AnswerContext {
            guard_outside: setup.rule.guard_outside,
            noisy: tslg_method::noise::spec_is_noisy(&setup.vut),
            adaptive: args.method.in_stages(),
        },
    );
    Report {
        case: setup.descriptor.name,
        grid: setup.descriptor.is_grid(),
        preset: setup.case.preset(),
        method: args.method.as_str(),
        vut: setup.vut.clone(),
        result,
        search,
        answer: answer.into(),
        exact,
        covers_exact: exact.map(|p| answer.covers(p)),
        parameters_inert: exact.and_then(|p| {
            tslg_method::registry::parameters_inert(setup.case.as_ref(), &setup.vut, p)
        }),
        warnings: warnings(
            &result,
            WarningContext {
                beta: setup.rule.beta,
                guard_outside: setup.rule.guard_outside,
                dialect: Dialect::Cli,
                unexplored: args.method.spec().waits_for_explorers
                    && args.exploration.epsilon == 0.0,
                uniform_spread: setup.outside == tslg_method::sampling::OutsideSpread::Uniform,
                adaptive: args.method.in_stages(),
                noisy: tslg_method::noise::spec_is_noisy(&setup.vut),
            },
        ),
    }
}

fn print(report: &Report, rule: &StoppingRule) {
    let result = &report.result;
    outln!("case               {} ({})", report.case, report.preset);
    outln!("method             {}", report.method);
    outln!(
        "vehicle under test {}",
        crate::inputs::vehicle_name(&report.vut, report.case)
    );
    if report.parameters_inert == Some(true) {
        outln!(
            "                   (these parameters change no accident of preset {}: the exact P(A) \
             equals the defaults', to the last bit)",
            report.preset
        );
    }
    outln!("status             {}", result.status.as_str());
    match &report.search {
        Some(search) => {
            if let Some(adaptive_search) = search.adaptive_search {
                outln!("search             {adaptive_search}");
            }
            outln!(
                "tests              {} ({} library, {} {}, {} estimating; {} stages)",
                result.indices,
                search.library_tests,
                search.search_tests,
                search.search_kind,
                result.tests,
                search.stages
            );
            if search.driving != result.indices as f64 {
                outln!(
                    "driving            {:.0} tests' worth (the probes' decisions counted)",
                    search.driving
                );
            }
            outln!("assumes            {}", search.assumes);
        }
        None => outln!("tests              {}", result.tests),
    }
    let answer = &report.answer;
    print_estimate(result, rule, answer.high > result.ci_high);
    outln!(
        "answer             [{:.4e}, {:.4e}]: {}",
        answer.low,
        answer.high,
        answer.reason
    );
    match (report.exact, report.covers_exact) {
        (Some(exact), Some(covers)) => outln!(
            "exact P(A)         {exact:.4e} ({} the answer)",
            if covers { "inside" } else { "OUTSIDE" }
        ),
        _ if report.grid => outln!(
            "exact P(A)         not computed: enumeration here stops at {} scenarios",
            tslg_api::EXACT_MAX_SCENARIOS
        ),
        _ => outln!("exact P(A)         none: no enumeration reaches this case's scenarios"),
    }
    if let (Some(upper), Some(high)) = (result.outside_upper, result.guarded_ci_high) {
        // An adaptive campaign's exploring tests sample off its support K.
        let region = if report.search.is_some() {
            "outside support K"
        } else {
            "outside library   "
        };
        outln!(
            "{region} {} exploring tests, {}; failure mass there ≤ {upper:.4e}",
            result.outside_tests,
            tslg_method::number::Count(result.outside_events, "event")
        );
        let covers = report
            .exact
            .map(|exact| {
                format!(
                    " (exact {})",
                    if result.guarded_covers(exact) {
                        "inside"
                    } else {
                        "OUTSIDE"
                    }
                )
            })
            .unwrap_or_default();
        outln!(
            "guarded interval   [{:.4e}, {high:.4e}]{covers}",
            result.ci_low
        );
    }
    for warning in &report.warnings {
        outln!("warning: {warning}");
    }
}

/// The events, estimate, interval and relative half-width of `result`.
/// With `assumes`, the interval is not the answer: it says that it holds
/// only if nothing fails where the tests barely looked (a guarded
/// campaign's interval can be exact inside and miss P(A)).
fn print_estimate(result: &CampaignResult, rule: &StoppingRule, assumes: bool) {
    outln!("events             {}", result.events);
    outln!("estimate           {:.4e}", result.estimate);
    let kind = match result.interval {
        Interval::Wald => "interval",
        // A confidence sequence: it holds at every number of tests at once.
        Interval::Anytime => "anytime",
    };
    let label = format!("{:.0}% {kind}", 100.0 * rule.confidence);
    outln!(
        "{label:<18} [{:.4e}, {:.4e}]{}",
        result.ci_low,
        result.ci_high,
        if assumes {
            " (if nothing fails outside what the tests sampled; the answer below does not \
             assume it)"
        } else {
            ""
        }
    );
    outln!(
        "rel. half-width    {:.4} (β {})",
        result.relative_half_width,
        rule.beta
    );
}
