//! The car-following library (SPEC §6): the state grid, the zones, the
//! Q-values by dynamic programming and by TD(0), the shape of the learned
//! action distribution, and the weights of tests sampled from it.

use std::sync::{Arc, OnceLock};
use tslg_method::campaign::{mean_weight, run_indexed_campaign, seeded_coverage};
use tslg_method::cases::carfollow::library::Next;
use tslg_method::cases::carfollow::*;
use tslg_method::estimator::StoppingRule;
use tslg_method::sampling::OutsideSpread;

struct Built {
    transitions: Transitions,
    dp: PolicyLibrary,
}

/// The IDM surrogate's transitions and DP library on the paper's grid, built once.
fn built() -> &'static Built {
    static BUILT: OnceLock<Built> = OnceLock::new();
    BUILT.get_or_init(|| {
        let idm = highway_vehicle("idm").unwrap();
        let (world, grid) = (FollowWorld::paper(), StateGrid::paper());
        let exposure = FollowExposure::from_model(&FollowExposureModel::default(), &world, &grid);
        let transitions = Transitions::compute(&world, grid, &exposure, &idm);
        let dp = dynamic_programming(&transitions, 1e-13);
        Built { transitions, dp }
    })
}

fn state(v: f64, r: f64, rr: f64) -> FollowState {
    FollowState {
        bv_speed: v,
        range: r,
        range_rate: rr,
    }
}

#[test]
fn the_state_grid_has_the_papers_45885_states_and_finds_the_nearest() {
    let grid = StateGrid::paper();
    assert_eq!(grid.len(), 45_885);
    for s in (0..grid.len()).step_by(97) {
        assert_eq!(grid.nearest(&grid.state(s)), Some(s));
    }
    let s = grid.nearest(&state(38.2, 5.6, -2.4)).unwrap();
    assert_eq!(grid.state(s), state(38.0, 6.0, -2.0));
    // Beyond the grid's range the VUT is not following; speeds clamp.
    assert_eq!(grid.nearest(&state(30.0, 115.6, 0.0)), None);
    let edge = grid.nearest(&state(43.0, 50.0, -12.0)).unwrap();
    assert_eq!(grid.state(edge), state(40.0, 50.0, -10.0));
}

#[test]
fn zones_collision_safe_and_dangerous() {
    let b = built();
    let grid = StateGrid::paper();
    let zone = |v, r, rr| b.transitions.zones[grid.nearest(&state(v, r, rr)).unwrap()];
    assert_eq!(zone(30.0, 1.0, 0.0), Zone::Collision);
    // Far behind and falling back: nothing the BV does can reach the VUT.
    assert_eq!(zone(25.0, 100.0, 5.0), Zone::Safe);
    // 5 m behind and closing at 4 m/s: the BV braking at −4 m/s² is hit.
    assert_eq!(zone(30.0, 5.0, -4.0), Zone::Dangerous);
    let share = b.transitions.dangerous_share();
    assert!((0.03..0.2).contains(&share), "dangerous share {share}");
}

#[test]
fn dynamic_programming_solves_the_bellman_equation_and_td_reaches_the_same_q() {
    let b = built();
    let t = &b.transitions;
    let challenge = |next: Next| match next {
        Next::Accident => 1.0,
        Next::Free => 0.0,
        Next::State(s) if t.zones[s] == Zone::Collision => 1.0,
        Next::State(s) => b.dp.challenge[s],
    };
    let mut dangerous = 0;
    for s in 0..t.zones.len() {
        let row = &b.dp.q[s * t.actions..(s + 1) * t.actions];
        if t.zones[s] != Zone::Dangerous {
            assert!(row.iter().all(|&q| q == 0.0));
            continue;
        }
        dangerous += 1;
        // Q(s, u) = P(u|s) P(S|T(s, u)) and P(S|s) = Σ_u Q(s, u).
        for (k, q) in row.iter().enumerate() {
            let i = s * t.actions + k;
            let expected = t.action_probability[i] * challenge(t.next[i]);
            assert!((q - expected).abs() < 1e-12, "state {s} action {k}");
        }
        let total: f64 = row.iter().sum();
        assert!((total - b.dp.challenge[s]).abs() < 1e-12);
    }
    assert!(dangerous > 1000);
    let td = temporal_difference(t, 0.1, 1e-11, 5);
    let gap = b.dp.max_difference(&td);
    assert!(gap < 1e-9, "DP and TD differ by {gap}");
    assert!(td.iterations > 1_000_000, "{} TD updates", td.iterations);
}

#[test]
fn at_the_papers_example_state_the_library_shifts_mass_to_hard_braking() {
    let b = built();
    let world = FollowWorld::paper();
    let s = StateGrid::paper().nearest(&state(38.0, 6.0, -2.0)).unwrap();
    let library = b.dp.action_distribution(s).expect("a dangerous state");
    let ndd = FollowExposureModel::default().actions(&world, 38.0);
    let hard = |p: &[f64]| -> f64 {
        (0..world.actions)
            .filter(|&k| world.action(k) <= -3.0 + 1e-9)
            .map(|k| p[k])
            .sum()
    };
    assert!(
        hard(&library) > 0.9,
        "library P(u ≤ −3) = {}",
        hard(&library)
    );
    assert!(hard(&ndd) < 0.01, "NDD P(u ≤ −3) = {}", hard(&ndd));
    // It peaks at a hard but not the hardest braking: −4 m/s² is rarer than
    // the braking that already causes the accident (the paper: −3.4).
    let peak = (0..world.actions)
        .max_by(|&a, &b| library[a].total_cmp(&library[b]))
        .map(|k| world.action(k))
        .unwrap();
    assert!(peak > -4.0 + 1e-9 && peak <= -3.0, "peak at {peak}");
}

/// The `risky` preset (frequent hard braking, so that NDD campaigns converge
/// in seconds and can check the library's weights) and the IDM's library on
/// it, built once.
fn risky() -> &'static (CarFollowing, Arc<PolicyLibrary>) {
    static RISKY: OnceLock<(CarFollowing, Arc<PolicyLibrary>)> = OnceLock::new();
    RISKY.get_or_init(|| {
        let case = CarFollowing::new(FollowPreset::Risky);
        let idm = highway_vehicle("idm").unwrap();
        let library = Arc::new(
            case.learn(&idm, PolicySolver::DynamicProgramming)
                .expect("a library")
                .library,
        );
        (case, library)
    })
}

fn risky_library_sampler() -> FollowSampler {
    let (case, library) = risky();
    FollowSampler::library(
        case.world,
        case.grid,
        &case.exposure,
        Arc::clone(library),
        0.1,
        OutsideSpread::Ndd,
    )
    .unwrap()
}

#[test]
fn library_and_ndd_campaigns_agree_and_the_library_needs_far_fewer_tests() {
    // The surrogate, and the ACC+AEB: another controller, whose failures
    // the IDM's library covers (docs/statistics.md).
    for vut in ["idm", "acc-aeb"] {
        let vut = highway_vehicle(vut).unwrap();
        let by_library = risky_library_sampler();
        let by_ndd = risky().0.ndd_sampler();
        let run = |sampler: &FollowSampler, seed| {
            let rule = StoppingRule::new(0.2, 5_000_000);
            run_indexed_campaign(
                &|i| {
                    let t = sampler.run(&vut, seed, i);
                    t.accident.then(|| t.weight())
                },
                &rule,
            )
        };
        let (l, n) = (run(&by_library, 3), run(&by_ndd, 4));
        assert!(
            l.ci_low <= n.ci_high && n.ci_low <= l.ci_high,
            "{l:?} vs {n:?}"
        );
        assert!(l.tests * 1000 < n.tests, "{} vs {} tests", l.tests, n.tests);
    }
}

#[test]
fn library_weights_average_one_and_tests_are_reproducible() {
    let b = built();
    let world = FollowWorld::paper();
    let grid = StateGrid::paper();
    let exposure = FollowExposure::from_model(&FollowExposureModel::default(), &world, &grid);
    let sampler = FollowSampler::library(
        world,
        grid,
        &exposure,
        Arc::new(b.dp.clone()),
        0.1,
        OutsideSpread::Ndd,
    )
    .unwrap();
    let idm = highway_vehicle("idm").unwrap();
    // E_q[P/q] = 1 for the whole path, whatever the vehicle does.
    let n = 40_000;
    let mean: f64 = (0..n)
        .map(|i| sampler.run(&idm, 1, i).weight())
        .sum::<f64>()
        / n as f64;
    assert!((mean - 1.0).abs() < 0.05, "mean weight {mean}");
    assert_eq!(sampler.run(&idm, 1, 17), sampler.run(&idm, 1, 17));
    assert_ne!(sampler.run(&idm, 1, 17), sampler.run(&idm, 2, 17));
}

#[test]
fn the_binary_library_file_round_trips_and_rejects_damage() {
    use tslg_method::cases::carfollow::file::{PolicyFileError, PolicyHeader, VERSION};
    let b = built();
    let file = PolicyLibraryFile {
        header: PolicyHeader {
            version: VERSION,
            case: "car-following".into(),
            preset: "paper".into(),
            surrogate: serde_json::json!({"model": "idm"}),
            exposure: tslg_method::library::ExposureRef {
                name: "builtin".into(),
                fingerprint: "0".into(),
            },
            solver: PolicySolver::DynamicProgramming,
            iterations: b.dp.iterations,
            states: b.dp.challenge.len(),
            actions: b.dp.actions,
            mu_s: 0.0,
            library_states: 0,
            library_exposure: 0.0,
            sm_evaluations: 0,
        },
        library: b.dp.clone(),
    };
    let bytes = file.to_bytes();
    // Only the dangerous rows are stored: far below the dense 11 MB.
    let rows = b.dp.challenge.iter().filter(|&&c| c > 0.0).count();
    assert!(bytes.len() < 1_200_000, "{} bytes", bytes.len());
    assert!(bytes.len() > rows * (4 + 8 * 31), "{} bytes", bytes.len());
    let read = PolicyLibraryFile::from_bytes(&bytes).unwrap();
    assert_eq!(read, file, "every Q-value read back bit for bit");
    let cut = PolicyLibraryFile::from_bytes(&bytes[..bytes.len() - 3]).unwrap_err();
    assert!(
        cut.to_string().contains("ends inside the Q-values"),
        "{cut}"
    );
    let mut longer = bytes.clone();
    longer.push(0);
    assert!(PolicyLibraryFile::from_bytes(&longer)
        .unwrap_err()
        .to_string()
        .contains("1 bytes follow"));
    // A negative Q-value in the last row.
    let mut bad = bytes.clone();
    let at = bad.len() - 8;
    bad[at..].copy_from_slice(&(-0.5f64).to_le_bytes());
    assert!(matches!(
        PolicyLibraryFile::from_bytes(&bad),
        Err(PolicyFileError::BadRow { .. })
    ));
    assert!(PolicyLibraryFile::from_bytes(b"{\"format\":\"tslg-library\"}").is_err());
    // A reader that knows its grid refuses another table size before
    // allocating it.
    let err = PolicyLibraryFile::from_bytes_for(&bytes, b.dp.challenge.len(), 30).unwrap_err();
    assert!(err.to_string().contains("× 31 actions"), "{err}");
    // A file whose header declares 2²⁸ values and holds none: the case
    // (what the coordinator reads a worker's upload with) refuses it from
    // its header, before allocating 2 GiB for the table.
    let mut huge = file.header.clone();
    (huge.states, huge.actions) = (1 << 28, 1);
    let header = serde_json::to_vec(&huge).unwrap();
    let mut crafted = bytes[..8].to_vec();
    crafted.extend_from_slice(&(header.len() as u32).to_le_bytes());
    crafted.extend_from_slice(&header);
    crafted.extend_from_slice(&0u32.to_le_bytes());
    let case = tslg_method::cases::open_case(
        "car-following",
        Some("paper"),
        &tslg_method::registry::ExposureSource::Builtin,
    )
    .unwrap();
    let err = case.library_summary(&crafted).unwrap_err().to_string();
    assert!(
        err.contains("its table has 268435456 states × 1 actions; this case has 45885 × 31"),
        "{err}"
    );
    assert!(case.library_summary(&bytes).is_ok());
    // Another version is named as such, whatever its header holds.
    let mut future = file.clone();
    future.header.version = 2;
    let err = PolicyLibraryFile::from_bytes(&future.to_bytes()).unwrap_err();
    assert_eq!(err, PolicyFileError::Version(2));
}

#[test]
fn library_intervals_cover_a_high_precision_reference_across_seeds() {
    // The IDM on the risky preset: a reference from 400,000 library tests
    // (standard error ≈ 0.3%), then 200 seeded campaigns at β = 0.2.
    let sampler = risky_library_sampler();
    let idm = highway_vehicle("idm").unwrap();
    let weight = |seed, i| {
        let t = sampler.run(&idm, seed, i);
        t.accident.then(|| t.weight())
    };
    let (truth, _) = mean_weight(&|i| weight(u64::MAX, i), 400_000);
    // 200 seeds, floor 170 (tslg_testkit::CoverageCheck: P(Bin(200, 0.90)
    // < 170) ≤ 0.01, and coverage 0.80 fails with probability 0.957).
    let check = tslg_testkit::CoverageCheck::new(200, 0.9, 0.01);
    let c = seeded_coverage(
        &weight,
        &StoppingRule::new(0.2, 1_000_000),
        check.runs,
        truth,
    );
    let (covered, mean) = (c.covered, c.mean_estimate);
    // docs/statistics.md: 0.900 over 1,000 campaigns.
    check.assert_covers(covered, &format!("the IDM (reference {truth:e})"));
    assert!(
        (mean / truth - 1.0).abs() < 0.05,
        "mean {mean:e} vs {truth:e}"
    );
}
