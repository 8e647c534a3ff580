//! Adaptive campaigns on cut-in: what planning a stage costs beside running
//! its tests. Prints a Markdown table; run with
//! `cargo bench -p tslg-method --bench adaptive`.
//!
//! A campaign of the FVDM on the IDM's library (built-in exposure, seed 1) is
//! replayed stage by stage on one thread. For each stage the table gives
//! the time to plan it from the knowledge so far (`Planner::next`: the
//! search frontier, or the estimation support and its alias tables) and
//! the time to run its tests on the built-in vehicle. The refit's share is
//! the plan's time over the tests'. Each figure is the median of several
//! repetitions.

mod common;

use std::hint::black_box;
use tslg_method::adaptive::{AdaptiveSettings, Observation, Planner, Stage};
use tslg_method::case::Case;
use tslg_method::cutin::{CutIn, CutInPreset};
use tslg_method::library::{build_library, LibraryRequest, SearchMethod, Threshold};
use tslg_method::vehicle::VehicleModel;

const REPEATS: usize = 7;

fn median_seconds(f: impl FnMut()) -> f64 {
    common::median_seconds(REPEATS, f)
}

fn main() {
    let case = CutIn::builtin(CutInPreset::PaperCode);
    let idm = VehicleModel::builtin("idm").expect("built-in");
    let fvdm = VehicleModel::builtin("fvdm").expect("built-in");
    let request = LibraryRequest {
        threshold: Threshold::default(),
        search: SearchMethod::Exhaustive,
    };
    let spec = serde_json::to_value(idm).expect("serialisable");
    let library = build_library(&case, &idm, spec, "paper-code", &request);
    let settings = AdaptiveSettings::default();
    let planner = Planner::new(&case, &library, 0.1, settings).expect("valid settings");
    let seed = 1;
    let run_stage = |stage: &Stage, from: u64, len: u64| -> Vec<Observation> {
        (from..from + len)
            .map(|i| {
                let cell = match stage {
                    Stage::Library(d) | Stage::Estimate(d) => d.draw(seed, i).cell,
                    Stage::Search(cells) => cells[(i - from) as usize],
                };
                let (event, criticality) = case.event_and_criticality(&fvdm, cell);
                Observation {
                    cell,
                    event,
                    criticality,
                }
            })
            .collect()
    };
    println!("| stage | kind | tests | plan (µs) | tests (µs) | plan / tests |");
    println!("|---|---|---|---|---|---|");
    let mut knowledge = planner.knowledge();
    let mut stage = planner.first();
    let (mut from, mut plan_total, mut tests_total) = (0u64, 0.0, 0.0);
    for k in 0..12 {
        let len = planner.len(&stage);
        let tests = median_seconds(|| {
            black_box(run_stage(&stage, from, len));
        });
        let observations = run_stage(&stage, from, len);
        for o in &observations {
            planner.observe(&mut knowledge, o);
        }
        from += len;
        let plan = median_seconds(|| {
            black_box(planner.next(&knowledge));
        });
        let kind = match stage {
            Stage::Library(_) => "library",
            Stage::Search(_) => "search",
            Stage::Estimate(_) => "estimate",
        };
        println!(
            "| {k} | {kind} | {len} | {:.1} | {:.1} | {:.3} |",
            plan * 1e6,
            tests * 1e6,
            plan / tests
        );
        plan_total += plan;
        tests_total += tests;
        stage = planner.next(&knowledge);
    }
    println!(
        "\nOver these stages: planning {:.0} µs, tests {:.0} µs on the built-in FVDM \
         (one thread), a share of {:.3}.",
        plan_total * 1e6,
        tests_total * 1e6,
        plan_total / tests_total
    );
}
