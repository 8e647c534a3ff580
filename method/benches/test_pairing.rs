//! Every test as evidence: what the pairing walk costs the coordinator's
//! writer. Prints a Markdown table; run with
//! `cargo bench -p tslg-method --bench test_pairing`.
//!
//! A campaign of 200,000 tests over 3,000 cells (drawn with the skew of a
//! cut-in's exposure: a few cells often, most rarely), four workers in
//! leases of `LEASE` tests, a criticality on half of them: the time per
//! test of `Walk::step` and, at a fold every `LEASE` tests, of storing the
//! walk (its JSON), with the JSON's size.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::time::Instant;
use tslg_method::test_pairing::{cell_key, score, PairCounts, ResolvedRun, Walk};

const TESTS: u64 = 200_000;
const CELLS: u64 = 3_000;

fn main() {
    println!(
        "| lease (tests a fold) | walk, ns a test | stored walk, bytes | JSON a fold, µs | pairs |"
    );
    println!("|---|---|---|---|---|");
    for lease in [10u64, 100, 1_000] {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let workers = ["host-1", "host-2", "host-3", "host-4"];
        let mut walk = Walk::default();
        let mut pairs = PairCounts::new();
        let (mut walking, mut storing, mut bytes, mut folds) = (0.0f64, 0.0f64, 0usize, 0u32);
        let mut index = 0;
        while index < TESTS {
            let worker = workers[rng.random_range(0..workers.len())];
            let runs: Vec<ResolvedRun<'_>> = (0..lease)
                .map(|k| {
                    // Skewed cells: the square of a uniform puts most tests on few cells.
                    let u: f64 = rng.random();
                    let cell = (u * u * CELLS as f64) as u64;
                    let criticality = rng.random_bool(0.5).then(|| rng.random::<f64>());
                    ResolvedRun {
                        worker,
                        key: cell_key(cell),
                        score: score(rng.random_bool(0.001), criticality),
                        index: index + k,
                        tests: 1,
                    }
                })
                .collect();
            let started = Instant::now();
            for run in runs {
                walk.step(run, &mut pairs);
            }
            walking += started.elapsed().as_secs_f64();
            let started = Instant::now();
            let stored = serde_json::to_string(&walk).expect("serialises");
            storing += started.elapsed().as_secs_f64();
            bytes = stored.len();
            folds += 1;
            index += lease;
        }
        let compared: u64 = pairs.values().map(|t| t.compared).sum();
        println!(
            "| {lease} | {:.0} | {bytes} | {:.0} | {compared} |",
            walking / TESTS as f64 * 1e9,
            storing / f64::from(folds) * 1e6,
        );
    }
}
