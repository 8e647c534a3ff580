//! Coverage of the car-following library campaign's 90% interval (SPEC §6):
//! many seeded in-process campaigns at β = 0.2 against a high-precision
//! reference value, a library run of millions of tests (no enumeration
//! exists for 33-dimensional scenarios). Prints a Markdown table for
//! docs/statistics.md. Run with
//! `cargo bench -p tslg-method --bench carfollow_coverage` (set
//! TSLG_COVERAGE_SEEDS to change the number of campaigns; default 1000).

use std::sync::Arc;
use std::time::Instant;
use tslg_method::campaign::{mean_weight, seeded_coverage};
use tslg_method::cases::carfollow::{
    highway_vehicle, CarFollowing, FollowPreset, FollowSampler, PolicySolver,
};
use tslg_method::estimator::StoppingRule;
use tslg_method::sampling::OutsideSpread;

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
        let library = Arc::new(
            case.learn(&idm, PolicySolver::DynamicProgramming)
                .expect("a library")
                .library,
        );
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
            let started = Instant::now();
            let weight = |seed, i| {
                let t = sampler.run(&vut, seed, i);
                t.accident.then(|| t.weight())
            };
            let (truth, se) = mean_weight(&|i| weight(u64::MAX, i), n_ref);
            eprintln!(
                "{} {name}: reference in {:.1} s",
                preset.name(),
                started.elapsed().as_secs_f64()
            );
            for n_min in n_mins {
                // Long campaigns: as many as 10⁷ tests allow, at least 100.
                let campaigns = seeds.min((10_000_000 / n_min).max(100));
                let mut rule = StoppingRule::new(0.2, 10_000_000);
                rule.n_min = n_min;
                let c = seeded_coverage(&weight, &rule, campaigns, truth);
                println!(
                    "| {} | {name} | {truth:.4e} ± {se:.1e} ({n_ref:.0e}) | {n_min} | {campaigns} | {:.3} | {mean_tests:.0} | {mean_ratio:.3} |",
                    preset.name(),
                    c.coverage(),
                    mean_tests = c.mean_tests,
                    mean_ratio = c.mean_estimate / truth,
                );
            }
        }
    }
}
