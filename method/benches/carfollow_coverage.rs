//! Coverage of the car-following library campaign's 90% interval (SPEC §6):
//! many seeded in-process campaigns at β = 0.2 against a high-precision
//! reference value, a library run of millions of tests (no enumeration
//! exists for 33-dimensional scenarios). Prints a Markdown table for
//! docs/statistics.md. Run with
//! `cargo bench -p tslg-method --bench carfollow_coverage` (set
//! TSLG_COVERAGE_SEEDS to change the number of campaigns; default 1000).

use rayon::prelude::*;
use std::sync::Arc;
use std::time::Instant;
use tslg_method::campaign::run_indexed_campaign;
use tslg_method::carfollow::{
    highway_vehicle, CarFollowing, FollowPreset, FollowSampler, PolicySolver,
};
use tslg_method::estimator::StoppingRule;
use tslg_method::sampling::OutsideSpread;

/// Mean and standard error of the library estimator over `n` tests.
fn reference(
    sampler: &FollowSampler,
    vut: &tslg_method::vehicle::VehicleModel,
    n: u64,
) -> (f64, f64) {
    let (s1, s2) = (0..n)
        .into_par_iter()
        .map(|i| {
            let t = sampler.run(vut, u64::MAX, i);
            if t.accident {
                let w = t.weight();
                (w, w * w)
            } else {
                (0.0, 0.0)
            }
        })
        .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    let mean = s1 / n as f64;
    let var = s2 / n as f64 - mean * mean;
    (mean, (var / n as f64).sqrt())
}

fn main() {
    let seeds: u64 = std::env::var("TSLG_COVERAGE_SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1000);
    println!("| preset | VUT | reference P(A) ± se (tests) | n_min | campaigns | coverage of the 90% interval | mean tests | mean estimate / reference |");
    println!("|---|---|---|---|---|---|---|---|");
    let idm = highway_vehicle("idm").expect("built-in");
    for preset in [FollowPreset::Paper, FollowPreset::Risky] {
        let case = CarFollowing::new(preset);
        let library = Arc::new(case.learn(&idm, PolicySolver::DynamicProgramming).library);
        let sampler = FollowSampler::library(
            case.world,
            case.grid,
            &case.exposure,
            library,
            0.1,
            OutsideSpread::Ndd,
        )
        .expect("a library");
        // The surrogate; the ACC+AEB, a different controller whose failures
        // the IDM's library covers; the ACC+AEB with a 0.3 s actuator lag,
        // which fails where the IDM does not (docs/models.md).
        for (name, spec, n_ref, n_mins) in [
            ("idm", r#"{"model": "idm"}"#, 4_000_000, vec![30, 1_000]),
            (
                "acc-aeb",
                r#"{"model": "acc-aeb"}"#,
                4_000_000,
                vec![30, 1_000],
            ),
            (
                "acc-aeb, lag 0.3 s",
                r#"{"model": "acc-aeb", "actuator_lag": 0.3}"#,
                20_000_000,
                vec![30, 20_000, 100_000],
            ),
        ] {
            let vut = CarFollowing::vehicle(&serde_json::from_str(spec).expect("JSON"))
                .expect("a valid vehicle");
            let t = Instant::now();
            let (truth, se) = reference(&sampler, &vut, n_ref);
            eprintln!(
                "{} {name}: reference in {:.1} s",
                preset.name(),
                t.elapsed().as_secs_f64()
            );
            for n_min in n_mins {
                // Long campaigns: as many as 10⁷ tests allow, at least 100.
                let campaigns = seeds.min((10_000_000 / n_min).max(100));
                let mut rule = StoppingRule::new(0.2, 10_000_000);
                rule.n_min = n_min;
                let runs: Vec<_> = (0..campaigns)
                    .map(|seed| {
                        run_indexed_campaign(
                            &|i| {
                                let t = sampler.run(&vut, seed, i);
                                t.accident.then(|| t.weight())
                            },
                            &rule,
                        )
                    })
                    .collect();
                let covered = runs
                    .iter()
                    .filter(|r| r.ci_low <= truth && truth <= r.ci_high)
                    .count();
                let mean_tests =
                    runs.iter().map(|r| r.tests as f64).sum::<f64>() / runs.len() as f64;
                let mean_ratio =
                    runs.iter().map(|r| r.estimate / truth).sum::<f64>() / runs.len() as f64;
                println!(
                    "| {} | {name} | {truth:.4e} ± {se:.1e} ({n_ref:.0e}) | {n_min} | {campaigns} | {:.3} | {mean_tests:.0} | {mean_ratio:.3} |",
                    preset.name(),
                    covered as f64 / runs.len() as f64,
                );
            }
        }
    }
}
