//! Adaptive campaigns: what planning a stage costs beside running its
//! tests, on cut-in and on highway-exit's paper grid searched on its
//! lattice. Prints Markdown tables; run with
//! `cargo bench -p tslg-method --bench adaptive`.
//!
//! A campaign of the FVDM on the IDM's library (built-in exposure, seed 1) is
//! replayed stage by stage on one thread. For each stage the table gives
//! the time to plan the next stage from the knowledge so far
//! (`Planner::next`: the search frontier, or the estimation support and its
//! sampling tables) and the time to run its tests on the built-in vehicle.
//! The refit's share is the plan's time over the tests'. Each figure is the
//! median over repetitions of the whole replay, each with a fresh planner,
//! so a plan is timed as the campaign pays for it (once, with its cache as
//! the campaign left it).

mod common;

use std::hint::black_box;
use std::time::Instant;
use tslg_method::adaptive::{AdaptiveSettings, Observation, Planner, Stage};
use tslg_method::case::Case;
use tslg_method::cases::cutin::{CutIn, CutInPreset};
use tslg_method::cases::highway::{ExitVehicle, HighwayExit, HighwayPreset};
use tslg_method::library::{build_library, LibraryRequest, SearchMethod, Threshold};
use tslg_method::vehicle::VehicleModel;

const REPEATS: usize = 7;

fn median_seconds(f: impl FnMut()) -> f64 {
    common::median_seconds(REPEATS, f)
}

/// What `vehicle` does on the tests `indices` of `stage` under `seed`.
fn observed<C: Case>(
    case: &C,
    vehicle: &C::Vehicle,
    stage: &Stage,
    seed: u64,
    indices: std::ops::Range<u64>,
) -> Vec<Observation> {
    let from = indices.start;
    indices
        .map(|i| {
            let cell = match stage {
                Stage::Library(d) | Stage::Estimate(d) => d.draw(seed, i).cell,
                Stage::Search(cells) => cells[(i - from) as usize],
            };
            let (event, criticality) = case.event_and_criticality(vehicle, cell);
            Observation {
                cell,
                event,
                criticality,
            }
        })
        .collect()
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
    let seed = 1;
    let run_stage =
        |stage: &Stage, from: u64, len: u64| observed(&case, &fvdm, stage, seed, from..from + len);
    // Each repetition replays the campaign with a fresh planner and times
    // every plan once, as the campaign makes it: a plan that builds a new
    // estimation distribution is timed as such, not answered from the
    // cache a repeated call would hit.
    const STAGES: usize = 12;
    let mut plans = vec![Vec::new(); STAGES];
    let mut runs = vec![Vec::new(); STAGES];
    let mut shape = Vec::new();
    for _ in 0..REPEATS {
        let planner = Planner::new(&case, &library, 0.1, settings).expect("valid settings");
        let mut knowledge = planner.knowledge();
        let mut stage = planner.first();
        let mut from = 0u64;
        shape.clear();
        for k in 0..STAGES {
            let len = planner.len(&stage);
            let tests = median_seconds(|| {
                black_box(run_stage(&stage, from, len));
            });
            for o in &run_stage(&stage, from, len) {
                planner.observe(&mut knowledge, o);
            }
            from += len;
            let started = Instant::now();
            let next = planner.next(&knowledge);
            plans[k].push(started.elapsed().as_secs_f64());
            runs[k].push(tests);
            shape.push((stage.kind(), len));
            stage = next;
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    println!("| stage | kind | tests | plan (µs) | tests (µs) | plan / tests |");
    println!("|---|---|---|---|---|---|");
    let (mut plan_total, mut tests_total) = (0.0, 0.0);
    for k in 0..STAGES {
        let (plan, tests) = (median(&mut plans[k]), median(&mut runs[k]));
        let (kind, len) = shape[k];
        println!(
            "| {k} | {kind} | {len} | {:.1} | {:.1} | {:.3} |",
            plan * 1e6,
            tests * 1e6,
            plan / tests
        );
        plan_total += plan;
        tests_total += tests;
    }
    println!(
        "\nOver these stages: planning {:.0} µs, tests {:.0} µs on the built-in FVDM \
         (one thread), a share of {:.3}.",
        plan_total * 1e6,
        tests_total * 1e6,
        plan_total / tests_total
    );
    paper_lattice();
}

/// MOBIL on its own library of highway-exit's paper grid (1,640,961
/// scenarios), searched on the lattice (`AdaptiveSettings::lattice`), seed
/// 1, to its stop. "plan" is what the campaign's planning of the next stage
/// costs after each stage: observing its tests (a seed's block, 256 cells,
/// joins the support) and `Planner::next` (the frontier, or the estimation
/// stage's alias table on the support). It is set beside the stage's
/// tests at 1 ms each, a SUMO-like program (the built-in driver's 1–2 µs
/// a test would hide nothing).
fn paper_lattice() {
    let case = HighwayExit::builtin(HighwayPreset::Paper);
    let mobil = ExitVehicle::builtin("mobil").expect("built-in");
    let request = LibraryRequest {
        threshold: Threshold::default(),
        search: SearchMethod::Exhaustive,
    };
    let spec = serde_json::to_value(mobil).expect("serialisable");
    let library = build_library(&case, &mobil, spec, "paper", &request);
    let settings = AdaptiveSettings {
        lattice: true,
        ..AdaptiveSettings::default()
    };
    let seed = 1;
    let started = Instant::now();
    let planner = Planner::new(&case, &library, 0.1, settings).expect("valid settings");
    let built = started.elapsed().as_secs_f64();
    let started = Instant::now();
    black_box(Planner::new(&case, &library, 0.1, AdaptiveSettings::default()).expect("valid"));
    let built_on_grid = started.elapsed().as_secs_f64();
    let mut knowledge = planner.knowledge();
    let mut stage = planner.first();
    let mut from = 0u64;
    let mut rows = Vec::new();
    // To the campaign's size (2,400 tests: its median over 200 seeds).
    while from < 2_400 {
        let len = planner.len(&stage);
        let observations = observed(&case, &mobil, &stage, seed, from..from + len);
        let started = Instant::now();
        for o in &observations {
            planner.observe(&mut knowledge, o);
        }
        let next = planner.next(&knowledge);
        let plan = started.elapsed().as_secs_f64();
        rows.push((stage.kind(), len, plan, planner.support(&knowledge).len()));
        from += len;
        stage = next;
    }
    println!("\n| stage | kind | tests | support cells | plan (ms) | tests at 1 ms (ms) | plan / tests |");
    println!("|---|---|---|---|---|---|---|");
    let (mut plan_total, mut tests_total) = (0.0, 0.0);
    for (k, &(kind, len, plan, support)) in rows.iter().enumerate() {
        let tests = len as f64 * 1e-3;
        println!(
            "| {k} | {kind} | {len} | {support} | {:.2} | {:.0} | {:.4} |",
            plan * 1e3,
            tests * 1e3,
            plan / tests
        );
        plan_total += plan;
        tests_total += tests;
    }
    println!(
        "\nOver these stages: planning {:.1} ms, tests {:.0} ms at 1 ms a test, a share of {:.4}.",
        plan_total * 1e3,
        tests_total * 1e3,
        plan_total / tests_total
    );
    println!(
        "The planner itself, once a campaign: {:.1} ms ({:.1} ms without the lattice: the \
         exposure's alias table over the grid, the library's distribution).",
        built * 1e3,
        built_on_grid * 1e3
    );
}
