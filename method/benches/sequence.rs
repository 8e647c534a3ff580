//! Anytime intervals: what a confidence sequence costs in tests and in
//! time beside the Wald interval. Prints a Markdown table; run with
//! `cargo bench -p tslg-method --bench sequence`.
//!
//! For NDD campaigns of rare Bernoulli outcomes (an NDD campaign of a
//! vehicle of rate μ) the table gives, over seeds 0..SEEDS, the median tests
//! to `β = 0.2` at 90 % for each interval and their ratio, and the time to
//! fold the campaign's outcomes (sparse: its events) with the stopping rule
//! read at every index (Wald) or at every event and settlement (anytime),
//! per million tests folded.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;
use std::time::Instant;
use tslg_method::anytime::{AnytimeFold, TermBounds};
use tslg_method::estimator::{Interval, StoppingRule};
use tslg_method::prefix::{PrefixFold, SparseOutcome};

const SEEDS: u64 = 15;

/// A campaign's events among `len` tests of rate `mu`, seeded `seed`.
fn events(mu: f64, len: u64, seed: u64) -> Vec<(u64, SparseOutcome)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..len)
        .filter(|_| rng.random::<f64>() < mu)
        .map(|i| (i, SparseOutcome::Event(1.0)))
        .collect()
}

/// Tests to the stop and seconds to fold, for one campaign.
fn campaign(rule: &StoppingRule, outcomes: &[(u64, SparseOutcome)], len: u64) -> (u64, f64) {
    let started = Instant::now();
    let stop = match rule.interval {
        Interval::Wald => {
            let mut fold = PrefixFold::default();
            fold.advance(rule, rule.z(), len, outcomes, None)
                .expect("valid");
            fold.indices
        }
        Interval::Anytime => {
            let mut fold = AnytimeFold::new(rule, None, TermBounds::Single(1.0));
            fold.advance(rule, len, outcomes, None).expect("valid");
            fold.fold.indices
        }
    };
    (black_box(stop), started.elapsed().as_secs_f64())
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

fn main() {
    println!("| μ | Wald tests (median) | anytime tests (median) | anytime / Wald | Wald fold, ms per 10⁶ tests | anytime fold, ms per 10⁶ tests |");
    println!("|---|---|---|---|---|---|");
    for mu in [1e-2, 1e-3, 1e-4] {
        // Wald stops near 68/μ, anytime near 300/μ: room for both.
        let len = (1000.0 / mu) as u64;
        let mut rows: Vec<[f64; 4]> = Vec::new();
        for seed in 0..SEEDS {
            let outcomes = events(mu, len, seed);
            let mut row = [0.0; 4];
            for (k, interval) in [Interval::Wald, Interval::Anytime].into_iter().enumerate() {
                let rule = StoppingRule {
                    interval,
                    ..StoppingRule::new(0.2, len)
                };
                let (tests, seconds) = campaign(&rule, &outcomes, len);
                row[k] = tests as f64;
                row[2 + k] = 1e3 * seconds / (tests as f64 / 1e6);
            }
            rows.push(row);
        }
        let column = |k: usize| median(rows.iter().map(|r| r[k]).collect());
        let ratio = median(rows.iter().map(|r| r[1] / r[0]).collect());
        println!(
            "| {mu:e} | {:.0} | {:.0} | {ratio:.2} | {:.3} | {:.3} |",
            column(0),
            column(1),
            column(2),
            column(3)
        );
    }
}
