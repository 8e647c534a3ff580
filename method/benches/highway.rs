//! Highway-exit benchmark and report (SPEC §5): simulations per second,
//! exhaustive and multistart library generation on the paper's grid
//! (1,640,961 scenarios), the multistart search's recall and surrogate
//! evaluations, and for each vehicle under test its exact `P(A)`, the share
//! of its failure mass inside the MOBIL library, and the analytic tests of a
//! library campaign and of the NDD baseline at β = 0.2. Prints a Markdown
//! table; run with `cargo bench -p tslg-method --bench highway`.

use std::hint::black_box;
use std::time::Instant;
use tslg_method::case::Case;
use tslg_method::cases::highway::{ExitVehicle, HighwayExit, HighwayPreset};
use tslg_method::exact::{event_cells, exact_report};
use tslg_method::library::{build_library, Library, LibraryRequest, SearchMethod, Threshold};
use tslg_method::sampling::{LibraryDistribution, OutsideSpread, Split};

const REPEATS: usize = 3;

/// Median wall time of `f` in seconds over [`REPEATS`] runs, and its last result.
fn median_seconds<T>(mut f: impl FnMut() -> T) -> (f64, T) {
    let mut last = None;
    let mut times: Vec<f64> = (0..REPEATS)
        .map(|_| {
            let t = Instant::now();
            last = Some(f());
            t.elapsed().as_secs_f64()
        })
        .collect();
    times.sort_by(f64::total_cmp);
    (times[REPEATS / 2], last.expect("REPEATS > 0"))
}

fn vehicle(spec: &str) -> ExitVehicle {
    serde_json::from_str(spec).expect("valid vehicle")
}

fn library(case: &HighwayExit, surrogate: &ExitVehicle, search: SearchMethod) -> Library {
    build_library(
        case,
        surrogate,
        serde_json::to_value(surrogate).expect("serialises"),
        case.preset().name(),
        &LibraryRequest {
            threshold: Threshold::default(),
            search,
        },
    )
}

fn main() {
    let case = HighwayExit::builtin(HighwayPreset::Paper);
    let cells: Vec<usize> = (0..case.grid().len())
        .filter(|&c| case.exposure().p(c) > 0.0)
        .collect();
    println!("| measurement | value |");
    println!("|---|---|");
    println!(
        "| paper grid: scenarios, with positive exposure | {}, {} |",
        case.grid().len(),
        cells.len()
    );
    let mobil = vehicle(r#"{"model":"mobil"}"#);
    for name in ["mobil", "gap-seeker"] {
        let v = ExitVehicle::builtin(name).expect("built-in");
        let sample: Vec<usize> = cells.iter().step_by(16).copied().collect();
        let (secs, _) = median_seconds(|| {
            for &c in &sample {
                black_box(case.is_event(&v, black_box(c)));
            }
        });
        let mut events = vec![false; sample.len()];
        let (batched, _) = median_seconds(|| case.events(&v, black_box(&sample), &mut events));
        println!(
            "| simulations/s per core, {name}: one by one; batched (right-lane steps side by side) | {:.3e} ({:.2} µs); {:.3e} ({:.2} µs) |",
            sample.len() as f64 / secs,
            secs * 1e6 / sample.len() as f64,
            sample.len() as f64 / batched,
            batched * 1e6 / sample.len() as f64,
        );
    }
    // The batched records are the scalar ones on every cell of the grid.
    let all: Vec<usize> = (0..case.grid().len()).collect();
    for name in ["mobil", "gap-seeker"] {
        let v = ExitVehicle::builtin(name).expect("built-in");
        let batched = case.runs(&v, &all);
        let differing = all
            .iter()
            .zip(&batched)
            .filter(|&(&c, run)| case.run(&v, c) != *run)
            .count();
        assert_eq!(
            differing, 0,
            "{name}: batched runs differ from the scalar ones"
        );
        println!(
            "| {name}: batched records equal to one by one, all {} cells | yes |",
            all.len()
        );
    }
    let (secs, exhaustive) = median_seconds(|| library(&case, &mobil, SearchMethod::Exhaustive));
    println!(
        "| exhaustive library of mobil, all threads: {} cells, {} surrogate runs | {secs:.2} s |",
        exhaustive.size(),
        exhaustive.search.sm_evaluations
    );
    // How library generation grows with the grid: the same search on the
    // coarse grid (steps 20 m, 4 m/s) and on the paper's.
    let coarse = HighwayExit::builtin(HighwayPreset::Coarse);
    let (coarse_secs, coarse_library) =
        median_seconds(|| library(&coarse, &mobil, SearchMethod::Exhaustive));
    for (scenarios, seconds, built) in [
        (coarse.grid().len(), coarse_secs, &coarse_library),
        (case.grid().len(), secs, &exhaustive),
    ] {
        println!(
            "| grid scaling, exhaustive mobil library: {scenarios} scenarios, {} surrogate runs | {seconds:.3} s, {:.2} µs per surrogate run |",
            built.search.sm_evaluations,
            seconds * 1e6 / built.search.sm_evaluations as f64
        );
    }
    for seed in [0, 1, 2] {
        let t = Instant::now();
        let multistart = library(
            &case,
            &mobil,
            SearchMethod::Multistart { starts: 100, seed },
        );
        println!(
            "| multistart (100 starts, seed {seed}): {} cells, {} surrogate runs, recall {:.3} | {:.2} s |",
            multistart.size(),
            multistart.search.sm_evaluations,
            multistart.recall_against(&exhaustive),
            t.elapsed().as_secs_f64()
        );
    }
    let q = LibraryDistribution::new(
        &exhaustive,
        case.exposure(),
        0.1,
        OutsideSpread::Uniform,
        Split::Random,
    )
    .expect("valid distribution");
    let in_library: std::collections::HashSet<usize> =
        exhaustive.cells.iter().map(|c| c.cell).collect();
    for spec in [
        r#"{"model":"mobil"}"#,
        r#"{"model":"mobil","politeness":0.3,"wait_cost":0.5}"#,
        r#"{"model":"mobil","b_safe":3.5}"#,
        r#"{"model":"gap-seeker"}"#,
    ] {
        let vut = vehicle(spec);
        let report = exact_report(&case, &vut, &q, 0.2, 0.9);
        let events = event_cells(&case, &vut);
        let covered: f64 = events
            .iter()
            .filter(|c| in_library.contains(c))
            .map(|&c| case.exposure().p(c))
            .sum();
        println!(
            "| VUT `{spec}`: P(A); failure mass in the mobil library; library / NDD tests at β 0.2 (ε 0.1); ratio | {:.3e}; {:.3}; {:.3e} / {:.3e}; {:.3} |",
            report.probability,
            covered / report.probability,
            report.library_tests,
            report.ndd_tests,
            report.ratio()
        );
    }
}
