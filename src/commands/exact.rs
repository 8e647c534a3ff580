//! `tslg exact`: exact P(A) of each built-in vehicle of a case by
//! enumeration, and the analytic number of tests a library campaign and the
//! NDD baseline need, for every grid case through its descriptor and the
//! registry.

#[derive(Debug, Args)]
pub struct ExactArgs {
    #[command(flatten)]
    pub case: CaseArgs,
    /// The surrogate whose library the expected library tests refer to
    /// (default: the case's).
    #[arg(long)]
    pub surrogate: Option<String>,
    /// ε of the library distribution.
    #[arg(long, default_value_t = 0.1, allow_negative_numbers = true)]
    pub epsilon: f64,
    /// Target relative half-width.
    #[arg(long, default_value_t = 0.2, allow_negative_numbers = true)]
    pub beta: f64,
    /// Confidence level.
    #[arg(long, default_value_t = 0.9, allow_negative_numbers = true)]
    pub confidence: f64,
    /// A vehicle to report beside the case's built-in ones (a name or a
    /// JSON specification, e.g. '{"model": "idm", "noise": 1.5}' for a
    /// noisy IDM, whose P(A|x) per cell is a Monte Carlo); repeatable.
    #[arg(long, value_name = "VUT")]
    pub vut: Vec<String>,
    /// A program to report beside them, started here as `tslg-worker
    /// --vut-exec` starts it (a built-in grid case): its P(A) from its
    /// outcomes on every cell with exposure, run `--program-runs` times
    /// each when its hello says it is not deterministic; repeatable.
    #[arg(long, value_name = "NAME=COMMAND")]
    pub program: Vec<String>,
    /// Runs of every cell of a noisy `--program`.
    #[arg(long, default_value_t = crate::commands::held_out::DEFAULT_PROGRAM_RUNS)]
    pub program_runs: usize,
}

/// P(A) by enumeration of the grid, where the case has one and it is
/// small enough to run here in a few seconds.
pub fn exact_answer(case: &dyn ExactAnswers, vut: &serde_json::Value) -> Option<f64> {
    let small = case.total_scenarios() <= tslg_api::EXACT_MAX_SCENARIOS;
    (case.descriptor().is_grid() && small)
        .then(|| case.exact_event_probability(vut).ok())
        .flatten()
}

use crate::args::CaseArgs;
use crate::inputs::{
    case_descriptor, check_epsilon, open, surrogate_or_default, vehicle_name, vehicle_spec,
};
use anyhow::Context;
use clap::Args;
use tslg_method::estimator::StoppingRule;
use tslg_method::guard_floor::GuardFloors;
use tslg_method::library::{LibrarySearch, SearchMethod};
use tslg_method::registry::{BuildRequest, ExactAnswers, ScenarioCase};

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
    let descriptor = case_descriptor(&args.case)?;
    anyhow::ensure!(
        descriptor.is_grid(),
        "case {}: no enumeration reaches its scenarios, so it has no exact answer (its \
         campaigns are checked against a high-precision reference: docs/statistics.md)",
        descriptor.name
    );
    // The user's table is read first: a wrong one is refused before the
    // built-in model's answers are worked out and printed (seconds on the
    // highway).
    let tabled = match args.case.ndd_table {
        Some(_) => Some(open(&args.case)?),
        None => None,
    };
    let builtin = open(&CaseArgs {
        ndd_table: None,
        ..args.case.clone()
    })?;
    print_table(builtin.as_ref(), args)?;
    if let Some(tabled) = tabled {
        outln!();
        print_table(tabled.as_ref(), args)?;
    }
    Ok(())
}

fn print_table(case: &dyn ScenarioCase, args: &ExactArgs) -> anyhow::Result<()> {
    let descriptor = case.descriptor();
    let surrogate = vehicle_spec(
        case,
        surrogate_or_default(&args.case, &args.surrogate)?,
        "surrogate",
    )?;
    let library = case.build_library(
        &surrogate,
        &BuildRequest {
            threshold: None,
            search: Some(LibrarySearch::Cells(SearchMethod::Exhaustive)),
        },
    )?;
    outln!(
        "case {} | exposure {} | preset {} | library of {} ({} cells), epsilon {}, beta {}, \
         confidence {}",
        descriptor.name,
        case.exposure_name(),
        case.preset(),
        vehicle_name(&surrogate, descriptor.name),
        library.size,
        args.epsilon,
        args.beta,
        args.confidence
    );
    outln!(
        "{:<14} {:>12} {:>14} {:>14} {:>10}",
        "vehicle",
        "exact P(A)",
        "library tests",
        "NDD tests",
        "ratio"
    );
    // A user-defined case's vehicles are its programs: its own, and those
    // of --vut-exec.
    let mut vehicles: Vec<String> = descriptor.vehicles.iter().map(|v| v.to_string()).collect();
    if vehicles.is_empty() {
        vehicles.push(descriptor.default_surrogate.to_owned());
        for exec in &args.case.vut_exec {
            vehicles.extend(exec.split_once('=').map(|(name, _)| name.to_owned()));
        }
    }
    vehicles.extend(args.vut.iter().cloned());
    let mut notes = Vec::new();
    for text in &vehicles {
        let vut = vehicle_spec(case, text, "vehicle")?;
        let name = vehicle_name(&vut, case.descriptor().name);
        let r = case
            .exact_report(
                &vut,
                &library.file,
                args.epsilon,
                descriptor.default_outside,
                args.beta,
                args.confidence,
            )
            .with_context(|| format!("the exact answer of {name}"))?;
        outln!(
            "{:<14} {:>12.4e} {:>14.1} {:>14.0} {:>10}",
            name,
            r.probability,
            r.library_tests,
            r.ndd_tests,
            crate::output::ratio(r.ratio())
        );
        if let Some(mc) = r.monte_carlo {
            let share = if r.probability > 0.0 {
                format!(" ({:.2}% of it)", 100.0 * mc.standard_error / r.probability)
            } else {
                String::new()
            };
            notes.push(format!(
                "{name}: its runs of one scenario differ, so P(A|x) per cell is a seeded Monte \
                 Carlo of {} runs ({} cells varied); P(A) has standard error {:.2e}{share}, \
                 cells whose runs all agreed taken as 0 or 1",
                mc.runs_per_cell, mc.varying_cells, mc.standard_error
            ));
        }
        if let Some(floors) = &r.guard_floors {
            notes.push(guard_floor_note(&name, floors, r.ndd_tests));
        }
    }
    for exec in &args.program {
        let z = StoppingRule {
            beta: args.beta,
            confidence: args.confidence,
            ..StoppingRule::new(args.beta, tslg_method::estimator::MAX_TESTS_LIMIT)
        }
        .z();
        let Some(table) = crate::commands::held_out::tabulate(case, exec, args.program_runs)?
        else {
            anyhow::bail!(
                "--program {exec}: the program does not drive case {}",
                descriptor.name
            );
        };
        let ndd = tslg_method::exact::expected_ndd_tests(table.probability, args.beta, z);
        outln!(
            "{:<14} {:>12.4e} {:>14} {:>14.0} {:>10}",
            table.name,
            table.probability,
            "–",
            ndd,
            "–"
        );
        let exposures = case.cell_exposures()?;
        if table.noisy() {
            let floors =
                GuardFloors::of(&table.cell_rates(&exposures), args.beta, z, args.confidence);
            notes.extend(floors.map(|f| guard_floor_note(&table.name, &f, ndd)));
        }
        let best = tslg_method::exact::expected_library_tests(
            table.best_sampling_variance(&exposures),
            table.probability,
            args.beta,
            z,
        );
        notes.push(if table.noisy() {
            format!(
                "{}: a noisy program, {} runs of every cell with exposure: P(A) has standard \
                 error {:.2e}; the best sampling of one run a test, were every cell's rate \
                 known (q ∝ P(x)√p̂(x)), would need about {:.0} tests, or more: a cell \
                 failing in fewer than 1 run in {} may count as never failing here",
                table.name, table.runs, table.standard_error, best, table.runs
            )
        } else {
            format!(
                "{}: a deterministic program, one run of every cell with exposure",
                table.name
            )
        });
    }
    for note in notes {
        outln!("{note}");
    }
    Ok(())
}

/// What a guarded campaign of a noisy vehicle can reach at best
/// ([`tslg_method::guard_floor`]): its tests told every cell's rate,
/// sampling the support by exposure as tslg does and by `P √p`, against
/// the NDD's `ndd` tests.
fn guard_floor_note(name: &str, floors: &GuardFloors, ndd: f64) -> String {
    let (exposure, root) = (&floors.exposure, &floors.root_rate);
    format!(
        "{name}: a guarded campaign (the answer that covers whatever the vehicle does off \
         its support) told every cell's rate would need about {:.0} tests ({:.1} times \
         fewer than the NDD) sampling its support by exposure as tslg does, {:.0} ({:.1} \
         times fewer) sampling it by P(x)√p(x): the support then holds {:.1}% of the \
         exposure and {:.0}% of the failures, and {:.0}% of the tests explore off it. A \
         campaign that must learn its support needs more",
        exposure.tests,
        ndd / exposure.tests,
        root.tests,
        ndd / root.tests,
        100.0 * root.support_exposure,
        100.0 * root.support_failure_share,
        100.0 * root.exploring_share,
    )
}
