//! The highway-exit case's batched runs ([`super::batch`]) against its runs one
//! by one, bit for bit.

use super::batch::run_all;
use crate::case::Case;
use crate::cases::highway::{simulation, ExitVehicle, ExitWorld, HighwayExit, HighwayPreset};

/// Each of `cells` in a batch against one by one: outcome, time and
/// lane-change point, bit for bit. Returns the failures.
fn batched_equals_scalar(case: &HighwayExit, vehicle: &ExitVehicle, cells: &[usize]) -> usize {
    let batched = case.runs(vehicle, cells);
    let mut events = vec![false; cells.len()];
    case.events(vehicle, cells, &mut events);
    let mut failures = 0;
    for ((&cell, run), event) in cells.iter().zip(&batched).zip(events) {
        let scalar = case.run(vehicle, cell);
        let bits = |r: &crate::cases::highway::ExitRun| {
            (
                r.outcome,
                r.time.to_bits(),
                r.lane_change.map(|(t, p)| (t.to_bits(), p.to_bits())),
            )
        };
        assert_eq!(bits(run), bits(&scalar), "cell {cell}, {vehicle:?}");
        assert_eq!(event, scalar.outcome.is_failure(), "cell {cell}");
        failures += usize::from(event);
    }
    failures
}

/// Every cell of the coarse preset for each vehicle; on the paper's
/// grid (1,640,961 cells) an eighth of the cells per vehicle, a
/// different eighth for each (the highway benchmark checks every cell
/// of it for the built-in vehicles in the release build).
#[test]
fn batched_runs_are_the_scalar_ones_on_both_grids_and_other_worlds() {
    let vehicles: Vec<ExitVehicle> = [
        r#"{"model": "mobil"}"#,
        r#"{"model": "gap-seeker"}"#,
        // A real exponent (powf) and other parameters.
        r#"{"model": "mobil", "delta": 3.5, "politeness": 0.5, "b_safe": 3}"#,
        r#"{"model": "gap-seeker", "v0": 30, "headway": 1.5, "front_gap": 1.2}"#,
    ]
    .iter()
    .map(|s| serde_json::from_str(s).expect("valid vehicle"))
    .collect();
    let coarse = HighwayExit::builtin(HighwayPreset::Coarse);
    let every: Vec<usize> = (0..coarse.grid().len()).collect();
    let paper = HighwayExit::builtin(HighwayPreset::Paper);
    for (j, vehicle) in vehicles.iter().enumerate() {
        let failures = batched_equals_scalar(&coarse, vehicle, &every);
        assert!(
            failures > 0 && failures < every.len(),
            "{failures} failures"
        );
        let eighth: Vec<usize> = (j..paper.grid().len()).step_by(8).collect();
        let failures = batched_equals_scalar(&paper, vehicle, &eighth);
        assert!(
            failures > 0 && failures < eighth.len(),
            "{failures} failures"
        );
    }
    // Other worlds: a time cap reached in the right lane, a farther
    // exit with a wider car-following threshold.
    let worlds = [
        ExitWorld {
            max_time: 3.0,
            ..ExitWorld::paper()
        },
        ExitWorld {
            exit: 400.0,
            d_cf: 6.0,
            ..ExitWorld::paper()
        },
    ];
    for world in &worlds {
        let scenarios: Vec<[f64; 4]> = every.iter().map(|&c| coarse.scenario(c)).collect();
        for vehicle in &vehicles[..2] {
            let mut batched = vec![None; scenarios.len()];
            run_all(world, vehicle, scenarios.iter().copied(), |i, run| {
                batched[i] = Some(run)
            });
            let mut capped = 0;
            for (x, run) in scenarios.iter().zip(batched) {
                let scalar = simulation::run(world, vehicle, *x);
                assert_eq!(run, Some(scalar), "{x:?} {vehicle:?} {world:?}");
                capped +=
                    usize::from(scalar.time == world.max_time && scalar.lane_change.is_some());
            }
            if world.max_time == 3.0 {
                assert!(capped > 0, "no run reached the time cap in the right lane");
            }
        }
    }
    // Off the grid: a stopped BV ahead that the VUT brakes to a stop
    // behind, where the braking cut at −v/Δt left the speed a rounding
    // error below 0 and a fractional δ made it NaN (the one-by-one run
    // panicked); and overlapping or equal BVs.
    let fractional: ExitVehicle =
        serde_json::from_str(r#"{"model": "mobil", "delta": 3.5, "alpha": 0.1, "b": 0.1}"#)
            .expect("valid vehicle");
    let scenarios = [
        [170.0, 0.0, 60.0, 30.0],
        [120.0, 0.0, -40.0, 20.0],
        [3.0, 25.0, 3.0, 25.0],
        [0.0, 30.0, 0.0, 35.0],
    ];
    for vehicle in [&fractional, &vehicles[0], &vehicles[1]] {
        let world = ExitWorld::paper();
        let mut batched = vec![None; scenarios.len()];
        run_all(&world, vehicle, scenarios.iter().copied(), |i, run| {
            batched[i] = Some(run)
        });
        for (x, run) in scenarios.iter().zip(batched) {
            assert_eq!(run, Some(simulation::run(&world, vehicle, *x)), "{x:?}");
        }
    }
    // Out of order, repeated, and fewer scenarios than lanes.
    let odd = [9_000, 3, 9_000, 17, 4_444];
    batched_equals_scalar(&coarse, &vehicles[0], &odd);
    batched_equals_scalar(&coarse, &vehicles[0], &[]);
}
