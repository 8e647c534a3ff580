//! Cut-in benchmark: simulations per second per core, library build times,
//! sampling speed. Prints a Markdown table; run with
//! `cargo bench -p tslg-method --bench cutin`. Each figure is the median of
//! several repetitions, so one noisy run does not decide it.

mod common;

use std::hint::black_box;
use tslg_method::campaign::run_campaign;
use tslg_method::case::Case;
use tslg_method::cases::cutin::{CutIn, CutInPreset};
use tslg_method::estimator::StoppingRule;
use tslg_method::library::{build_library, LibraryRequest, SearchMethod, Threshold};
use tslg_method::sampling::{
    LibraryDistribution, NddDistribution, OutsideSpread, Split, TestDistribution,
};
use tslg_method::vehicle::{VehicleModel, BUILTIN_MODELS};

const REPEATS: usize = 7;

fn median_seconds(f: impl FnMut()) -> f64 {
    common::median_seconds(REPEATS, f)
}

fn main() {
    println!("| measurement | value |");
    println!("|---|---|");
    for preset in [CutInPreset::PaperCode, CutInPreset::PaperTable] {
        let case = CutIn::builtin(preset);
        let cells = case.grid().len();
        for name in BUILTIN_MODELS {
            let vut = VehicleModel::builtin(name).unwrap();
            // One thread: every cell of the grid, `rounds` times.
            let rounds = if preset == CutInPreset::PaperCode {
                20
            } else {
                2
            };
            let secs = median_seconds(|| {
                for _ in 0..rounds {
                    for cell in 0..cells {
                        black_box(case.is_event(&vut, black_box(cell)));
                    }
                }
            });
            println!(
                "| {preset} simulations/s per core, {name} | {:.3e} |",
                (rounds * cells) as f64 / secs
            );
        }
    }
    // The batched path workers use (`Case::events`): the grid's cells in
    // batches of eight, outcomes only.
    for preset in [CutInPreset::PaperCode, CutInPreset::PaperTable] {
        let case = CutIn::builtin(preset);
        let cells: Vec<usize> = (0..case.grid().len()).collect();
        let mut events = vec![false; cells.len()];
        let rounds = if preset == CutInPreset::PaperCode {
            200
        } else {
            20
        };
        for name in ["idm", "fvdm"] {
            let vut = VehicleModel::builtin(name).unwrap();
            let secs = median_seconds(|| {
                for _ in 0..rounds {
                    case.events(&vut, black_box(&cells), &mut events);
                    black_box(&events);
                }
            });
            println!(
                "| {preset} batched simulations/s per core, {name} | {:.3e} ({:.0} ns each) |",
                (rounds * cells.len()) as f64 / secs,
                secs * 1e9 / (rounds * cells.len()) as f64
            );
        }
    }
    let case = CutIn::builtin(CutInPreset::PaperCode);
    let idm = VehicleModel::builtin("idm").unwrap();
    for (label, search) in [
        ("exhaustive", SearchMethod::Exhaustive),
        (
            "multistart (50 starts)",
            SearchMethod::Multistart {
                starts: 50,
                seed: 0,
            },
        ),
    ] {
        let request = LibraryRequest {
            threshold: Threshold::default(),
            search,
        };
        let secs = median_seconds(|| {
            black_box(build_library(
                &case,
                &idm,
                serde_json::Value::Null,
                "paper-code",
                &request,
            ));
        });
        println!(
            "| library build, IDM, {label}, all threads | {:.2} ms |",
            secs * 1e3
        );
    }
    let fvdm = VehicleModel::builtin("fvdm").unwrap();
    let library = build_library(
        &case,
        &fvdm,
        serde_json::Value::Null,
        "paper-code",
        &LibraryRequest {
            threshold: Threshold::default(),
            search: SearchMethod::Exhaustive,
        },
    );
    let q = LibraryDistribution::new(
        &library,
        case.exposure(),
        0.1,
        OutsideSpread::Uniform,
        Split::Random,
    )
    .unwrap();
    let draws = 1_000_000u64;
    print_draw_rates("library", &TestDistribution::library(q.clone()), draws);
    print_draw_rates(
        "NDD",
        &TestDistribution::Ndd(NddDistribution::new(case.exposure())),
        draws,
    );
    // The coordinator's replay on the result path: which reported tests
    // explored (one ChaCha8 number per test, for the outside bound).
    println!(
        "| exploring-test replay per core (coordinator, per reported test) | {:.3e} tests/s |",
        each_per_second(draws, |i| {
            black_box(q.explores(black_box(9), i));
        })
    );
    let distribution = TestDistribution::library(q);
    let rule = StoppingRule::new(0.2, 10_000_000);
    let secs = median_seconds(|| {
        black_box(run_campaign(&case, &idm, None, &distribution, &rule, 3));
    });
    let tests = run_campaign(&case, &idm, None, &distribution, &rule, 3).tests;
    println!(
        "| library campaign, IDM tested with the FVDM library, β 0.2: {tests} tests | {:.2} ms |",
        secs * 1e3
    );
}

/// Draws per second of `distribution` on one core: one test at a time
/// (`draw`), then several streams at a time (`draw_each`, as workers,
/// the in-process runner and the coordinator's replay draw).
fn print_draw_rates(label: &str, distribution: &TestDistribution, draws: u64) {
    println!(
        "| {label} draws/s per core (scenario + weight) | {:.3e} |",
        each_per_second(draws, |i| {
            black_box(distribution.draw(black_box(9), i));
        })
    );
    let secs = median_seconds(|| {
        distribution.draw_each(black_box(9), 0..draws, |_, draw| {
            black_box(draw);
        });
    });
    println!(
        "| {label} draws/s per core, {} streams at a time (`draw_each`) | {:.3e} |",
        tslg_method::test_stream::LANES,
        draws as f64 / secs
    );
}

/// Calls of `f(i)` per second over `i` in `0..n`, on one core.
fn each_per_second(n: u64, f: impl Fn(u64)) -> f64 {
    n as f64 / median_seconds(|| (0..n).for_each(&f))
}
