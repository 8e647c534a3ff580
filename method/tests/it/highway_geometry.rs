//! The highway-exit geometry pinned by hand-worked scenarios: a free road
//! whose zone is the whole reachable region, a single BV whose blocked
//! interval is worked out at one instant, a blocked scenario with an empty
//! zone, and the symmetry of the scenario in the BVs' labels.

use tslg_method::case::Case;
use tslg_method::cases::highway::simulation::run;
use tslg_method::cases::highway::zone::{reachable_area, zone, zone_area};
use tslg_method::cases::highway::{
    ExitOutcome, ExitVehicle, ExitWorld, HighwayExit, HighwayPreset, EXIT_MODELS,
};

fn vehicles() -> Vec<ExitVehicle> {
    EXIT_MODELS
        .iter()
        .map(|name| ExitVehicle::builtin(name).unwrap())
        .collect()
}

#[test]
fn with_both_bvs_far_behind_and_slow_the_zone_is_the_reachable_region() {
    let world = ExitWorld::paper();
    // By hand: the VUT's fastest path is 30t + t² to 5 s (175 m), then
    // 40 m/s, capped at L = 200 m from 5.625 s; its slowest 30t − 2t² to
    // 2.5 s (62.5 m), then 20 m/s, reaching L at 9.375 s. The area between:
    // ∫ upper = 416.667 + 117.188 + 750 = 1283.854, ∫ lower = 83.333 +
    // 902.344 = 985.677, so S = 298.177 m·s.
    let exact = 298.177;
    assert!(
        (reachable_area(&world) - exact).abs() < 0.01,
        "{}",
        reachable_area(&world)
    );
    // BVs at −60 and −100 m driving 20 m/s block at most up to
    // −45 + 20t, always behind the slowest VUT (≥ 20t).
    let x = [-60.0, 20.0, -100.0, 20.0];
    assert_eq!(zone_area(&world, x), reachable_area(&world));
    for vehicle in vehicles() {
        let r = run(&world, &vehicle, x);
        assert_eq!(r.outcome, ExitOutcome::Exited, "{}", vehicle.name());
        assert_eq!(
            r.lane_change,
            Some((0.0, 0.0)),
            "{} changes lanes at once",
            vehicle.name()
        );
    }
}

#[test]
fn a_bv_blocks_its_safe_time_gap_on_either_side() {
    let world = ExitWorld::paper();
    // BV 1 at 20 m, 30 m/s: at t = 2 s it is at 80 m and blocks
    // 80 ± (ℓ + t_min·u) = 80 ± 20 = (60, 100). The VUT can reach
    // [52, 64] then, so the zone is [52, 60]: 8 m.
    let slices = zone(&world, [20.0, 30.0, -100.0, 20.0]);
    let at_2s = &slices[20];
    assert!((at_2s.t - 2.0).abs() < 1e-12);
    assert_eq!(at_2s.pieces.len(), 1);
    let (a, b) = at_2s.pieces[0];
    assert!(
        (a - 52.0).abs() < 1e-9 && (b - 60.0).abs() < 1e-9,
        "{:?}",
        at_2s.pieces
    );
}

#[test]
fn a_slow_bv_just_ahead_of_a_near_exit_leaves_an_empty_zone_and_every_vehicle_fails() {
    // The exit 60 m ahead; BV 1 15 m ahead at 20 m/s blocks (20t, 30 + 20t).
    // The VUT can reach [30t − 2t², 30t + t²] ⊂ (20t, 30 + 20t) while
    // t² + 10t < 30 (t < 2.42 s), and passes 60 m by 2.38 s at the latest.
    // (On the paper's grid every scenario leaves some zone: the smallest
    // S(F) is about 10 m·s.)
    let world = ExitWorld {
        exit: 60.0,
        ..ExitWorld::paper()
    };
    let x = [15.0, 20.0, -100.0, 20.0];
    assert_eq!(zone_area(&world, x), 0.0);
    assert!(zone(&world, x).iter().all(|s| s.pieces.is_empty()));
    for vehicle in vehicles() {
        let r = run(&world, &vehicle, x);
        assert_eq!(
            r.outcome,
            ExitOutcome::FailedToExit,
            "{}: {r:?}",
            vehicle.name()
        );
        assert!(r.outcome.is_failure());
    }
}

#[test]
fn swapping_the_bvs_labels_changes_neither_the_zone_nor_any_outcome() {
    let case = HighwayExit::builtin(HighwayPreset::Coarse);
    let world = case.world();
    let vehicles = vehicles();
    let mut checked = 0;
    for cell in 0..case.grid().len() {
        let [p1, v1, p2, v2] = case.scenario(cell);
        if p1 == p2 {
            continue;
        }
        let swapped = [p2, v2, p1, v1];
        let (a, b) = (zone(world, [p1, v1, p2, v2]), zone(world, swapped));
        assert_eq!(a, b, "zone of {:?}", [p1, v1, p2, v2]);
        for vehicle in &vehicles {
            assert_eq!(
                run(world, vehicle, [p1, v1, p2, v2]),
                run(world, vehicle, swapped),
                "{} in {:?}",
                vehicle.name(),
                [p1, v1, p2, v2]
            );
        }
        checked += 1;
    }
    assert_eq!(checked, 16 * 15 * 6 * 6);
}

#[test]
fn the_exposure_is_car_following_with_the_documented_magnitudes() {
    let case = HighwayExit::builtin(HighwayPreset::Paper);
    let mass = case.exposure();
    let grid = case.grid();
    assert_eq!(grid.len(), 61 * 21 * 61 * 21);
    let (mut total, mut v1_mean, mut headway_below_1_6, mut range_rate_sd) = (0.0, 0.0, 0.0, 0.0);
    for cell in 0..grid.len() {
        let p = mass.p(cell);
        let [p1, v1, p2, v2] = case.scenario(cell);
        if p1 <= p2 {
            assert_eq!(p, 0.0, "BV 1 leads: {:?}", case.scenario(cell));
            continue;
        }
        total += p;
        v1_mean += p * v1;
        range_rate_sd += p * (v1 - v2) * (v1 - v2);
        if (p1 - p2) / v2 < 1.6 {
            headway_below_1_6 += p;
        }
    }
    assert!((total - 1.0).abs() < 1e-9);
    // N(29.5, 3.5²) truncated to [20, 40]: mean 29.6 m/s.
    assert!((v1_mean - 29.6).abs() < 0.2, "mean leader speed {v1_mean}");
    // The median headway is 1.6 s; on a 5 m grid about half lie below it.
    assert!(
        (0.4..0.6).contains(&headway_below_1_6),
        "{headway_below_1_6}"
    );
    // Range rate: standard deviation 1.5 m/s.
    assert!(
        (range_rate_sd.sqrt() - 1.5).abs() < 0.15,
        "{}",
        range_rate_sd.sqrt()
    );
}
