//! Adaptive campaigns on car-following (`tslg_method::cases::carfollow::adaptive`)
//! against the library campaign they repair, the ceiling of any adaptation
//! of the Q-values, and learning from the tests' trajectories alone.
//!
//! For each vehicle: a reference P(A) (risky preset: the NDD baseline,
//! which involves no library; paper preset, where the NDD would take 10⁸
//! tests: a run of the vehicle's own library, unbiased for any policy),
//! then seeded campaigns at β 0.2, c 0.9, ε 0.1:
//!
//! - **plain**: the IDM's library, n_min 30 (the service's default);
//! - **ceiling**: the vehicle's own library, by dynamic programming on its
//!   own transitions (what a perfect learner of Q-values reaches);
//! - **trajectories**: the IDM's transitions overwritten where the tests'
//!   decisions saw the vehicle, the policy recomputed after each stage of
//!   100 tests, three stages of learning before the estimate;
//! - **adaptive**: [`run_follow_adaptive`] with its defaults.
//!
//! Cost is the vehicle's driving in tests of 30 decisions: tests plus the
//! probes' decisions / 30.
//!
//! `cargo bench -p tslg-method --bench carfollow_adaptive`
//! (TSLG_COVERAGE_SEEDS campaigns per row, default 200; TSLG_NDD_TESTS the
//! risky reference's tests, default 2 × 10⁷).

use rayon::prelude::*;
use std::sync::Arc;
use std::time::Instant;
use tslg_method::campaign::{mean_weight, seeded_coverage};
use tslg_method::cases::carfollow::adaptive::{
    run_follow_adaptive, FollowAdaptiveSettings, FollowPlanner,
};
use tslg_method::cases::carfollow::case::DP_TOLERANCE;
use tslg_method::cases::carfollow::library::Next;
use tslg_method::cases::carfollow::{
    dynamic_programming, CarFollowing, FollowDecision, FollowPreset, FollowSampler, PolicyLibrary,
    PolicySolver, Transitions, Zone,
};
use tslg_method::estimator::{Decision, ImportanceEstimator, StoppingRule};
use tslg_method::sampling::OutsideSpread;
use tslg_method::vehicle::VehicleModel;

fn env(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

fn library_sampler(case: &CarFollowing, library: Arc<PolicyLibrary>) -> FollowSampler {
    FollowSampler::library(
        case.world,
        case.grid,
        &case.exposure,
        library,
        0.1,
        OutsideSpread::Ndd,
    )
    .expect("a library")
}

fn main() {
    let seeds = env("TSLG_COVERAGE_SEEDS", 200);
    let ndd_tests = env("TSLG_NDD_TESTS", 20_000_000);
    let rule = StoppingRule::new(0.2, 10_000_000);
    let z2 = rule.z() * rule.z();
    println!("| preset | vehicle | reference P(A) ± se (from) | method | campaigns | coverage | mean tests | median tests | mean estimate / reference | NDD tests | NDD / median |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for preset in [FollowPreset::Risky, FollowPreset::Paper] {
        let case = Arc::new(CarFollowing::new(preset));
        let vehicle = |spec: &str| {
            CarFollowing::vehicle(&serde_json::from_str(spec).expect("JSON")).expect("a vehicle")
        };
        let idm = vehicle(r#"{"model": "idm"}"#);
        let idm_library = Arc::new(
            case.learn(&idm, PolicySolver::DynamicProgramming)
                .expect("a library")
                .library,
        );
        let planner = FollowPlanner::new(
            Arc::clone(&case),
            &idm,
            Arc::clone(&idm_library),
            0.1,
            OutsideSpread::Ndd,
            FollowAdaptiveSettings::default(),
        )
        .expect("a planner");
        for (name, spec) in [
            ("idm", r#"{"model": "idm"}"#),
            ("acc-aeb", r#"{"model": "acc-aeb"}"#),
            (
                "acc-aeb, lag 0.3 s",
                r#"{"model": "acc-aeb", "actuator_lag": 0.3}"#,
            ),
        ] {
            let vut = vehicle(spec);
            let own = Arc::new(
                case.learn(&vut, PolicySolver::DynamicProgramming)
                    .expect("a library")
                    .library,
            );
            let started = Instant::now();
            let (truth, se, from) = match preset {
                FollowPreset::Risky => {
                    let ndd = case.ndd_sampler();
                    let (m, s) = mean_weight(
                        &|i| ndd.run(&vut, u64::MAX, i).accident.then_some(1.0),
                        ndd_tests,
                    );
                    (m, s, format!("NDD, {ndd_tests:.0e} tests"))
                }
                FollowPreset::Paper => {
                    let n = 4_000_000;
                    let sampler = library_sampler(&case, Arc::clone(&own));
                    let (m, s) = mean_weight(
                        &|i| {
                            let t = sampler.run(&vut, u64::MAX, i);
                            t.accident.then(|| t.weight())
                        },
                        n,
                    );
                    (m, s, format!("its own library, {n:.0e} tests"))
                }
            };
            eprintln!(
                "{} {name}: reference in {:.0} s",
                preset.name(),
                started.elapsed().as_secs_f64()
            );
            let ndd = z2 * (1.0 - truth) / (rule.beta * rule.beta * truth);
            let row = |method: &str, runs: &[(bool, f64, f64)]| {
                let n = runs.len() as f64;
                let covered = runs.iter().filter(|r| r.0).count() as f64 / n;
                let mut tests: Vec<f64> = runs.iter().map(|r| r.1).collect();
                tests.sort_by(f64::total_cmp);
                let median = tests[tests.len() / 2];
                let mean_tests = tests.iter().sum::<f64>() / n;
                let mean_estimate = runs.iter().map(|r| r.2).sum::<f64>() / n;
                println!(
                    "| {} | {name} | {truth:.4e} ± {se:.1e} ({from}) | {method} | {} | {covered:.3} | {mean_tests:.0} | {median:.0} | {:.3} | {ndd:.3e} | {:.0} |",
                    preset.name(),
                    runs.len(),
                    mean_estimate / truth,
                    ndd / median
                );
            };
            for (method, library) in [
                ("plain (IDM library)", &idm_library),
                ("ceiling (its own library)", &own),
            ] {
                let sampler = library_sampler(&case, Arc::clone(library));
                let weight = |seed, i| {
                    let t = sampler.run(&vut, seed, i);
                    t.accident.then(|| t.weight())
                };
                let runs: Vec<(bool, f64, f64)> = (0..seeds)
                    .map(|seed| {
                        let c = seeded_coverage(&|_, i| weight(seed, i), &rule, 1, truth);
                        (c.covered == 1, c.mean_tests, c.mean_estimate)
                    })
                    .collect();
                row(method, &runs);
            }
            let runs: Vec<(bool, f64, f64)> = (0..seeds)
                .into_par_iter()
                .map(|seed| {
                    trajectory_campaign(&case, &idm, &idm_library, &vut, seed, &rule, truth)
                })
                .collect();
            row("trajectories only", &runs);
            let started = Instant::now();
            let runs: Vec<(bool, f64, f64)> = (0..seeds)
                .map(|seed| {
                    let r = run_follow_adaptive(&planner, &vut, &rule, seed).expect("runs");
                    (
                        r.result.covers(truth),
                        r.test_equivalents(case.world.decisions),
                        r.result.estimate,
                    )
                })
                .collect();
            row("adaptive", &runs);
            eprintln!(
                "{} {name}: adaptive campaigns in {:.0} s",
                preset.name(),
                started.elapsed().as_secs_f64()
            );
        }
    }
}

/// The IDM's transitions overwritten where the tests saw the vehicle: three
/// stages of 100 tests learn, then stages of 100 estimate, the policy
/// recomputed after each. Returns (covered, tests, estimate).
fn trajectory_campaign(
    case: &CarFollowing,
    surrogate: &VehicleModel,
    first: &Arc<PolicyLibrary>,
    vut: &VehicleModel,
    seed: u64,
    rule: &StoppingRule,
    truth: f64,
) -> (bool, f64, f64) {
    const STAGE: u64 = 100;
    const LEARN: u64 = 3;
    let mut model = Transitions::compute(&case.world, case.grid, &case.exposure, surrogate);
    let mut library = Arc::clone(first);
    let mut estimator = ImportanceEstimator::default();
    let z = rule.z();
    let actions = case.world.actions;
    for k in 0.. {
        let sampler = library_sampler(case, Arc::clone(&library));
        for i in k * STAGE..(k + 1) * STAGE {
            let mut trace: Vec<FollowDecision> = Vec::new();
            let Ok(t) = sampler.run_traced(&mut vut.controller(), seed, i, |d| trace.push(d));
            for d in &trace {
                let Some(s) = case.grid.nearest(&d.from) else {
                    continue;
                };
                model.zones[s] = Zone::Dangerous;
                model.next[s * actions + d.action] = match d.to {
                    None => Next::Accident,
                    Some(x) => case.grid.nearest(&x).map_or(Next::Free, Next::State),
                };
            }
            if k >= LEARN {
                estimator.push(if t.accident { t.weight() } else { 0.0 }, t.accident);
                if rule.decide(&estimator, z) != Decision::Continue {
                    let (low, high) = estimator.interval(z);
                    return (
                        low <= truth && truth <= high,
                        (i + 1) as f64,
                        estimator.estimate(),
                    );
                }
            }
        }
        library = Arc::new(dynamic_programming(&model, DP_TOLERANCE));
    }
    unreachable!("the rule stops at max_tests")
}
