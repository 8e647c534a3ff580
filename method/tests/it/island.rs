//! The adaptive campaign's failure mode, measured (issue 52): a vehicle
//! whose failures include an island that no failure or near miss leads to.
//! The search cannot reach it, so the plain adaptive interval misses it;
//! its guarded upper end (the bound from its exploring tests) still covers
//! the exact answer, and a guarded adaptive campaign, which explores until
//! that bound is within β, finds the island and covers with its interval,
//! in fewer tests than the NDD baseline.
//!
//! The vehicle is this crate's IDM with an island of two neighbouring
//! cut-in scenarios where it always fails, as the perception bug of
//! `examples/python/idm_vut.py --blind` makes the IDM fail there: far from
//! every scenario where the IDM fails or comes within the search's near
//! miss, with an exposure near the IDM's own P(A), so that half the
//! failure mass lies on the island.

use crate::common::{library, vehicle};
use std::collections::HashSet;
use tslg_method::adaptive::{run_adaptive, AdaptiveResult, AdaptiveSettings};
use tslg_method::case::{Case, SurrogateEvaluation};
use tslg_method::cases::cutin::{CutIn, CutInPreset};
use tslg_method::estimator::{z_for_confidence, StoppingRule};
use tslg_method::exact::{event_cells, event_probability};
use tslg_method::external::{DriverError, ExternalVehicle};
use tslg_method::library::SearchMethod;
use tslg_method::mass::GridMass;
use tslg_method::vehicle::VehicleModel;

/// Cut-in, where the vehicle also fails on `island`.
struct WithIsland {
    base: CutIn,
    island: HashSet<usize>,
}

impl Case for WithIsland {
    type Vehicle = VehicleModel;

    fn name(&self) -> &'static str {
        "cut-in"
    }

    fn exposure(&self) -> &GridMass {
        self.base.exposure()
    }

    fn exposure_name(&self) -> &str {
        self.base.exposure_name()
    }

    fn is_event(&self, vehicle: &VehicleModel, cell: usize) -> bool {
        self.island.contains(&cell) || self.base.is_event(vehicle, cell)
    }

    fn event_and_criticality(&self, vehicle: &VehicleModel, cell: usize) -> (bool, f64) {
        if self.island.contains(&cell) {
            (true, 0.0)
        } else {
            self.base.event_and_criticality(vehicle, cell)
        }
    }

    fn external_world(&self) -> serde_json::Value {
        self.base.external_world()
    }

    fn external_step_event_and_criticality(
        &self,
        vut: &mut dyn ExternalVehicle,
        cell: usize,
    ) -> Result<(bool, Option<f64>), DriverError> {
        self.base.external_step_event_and_criticality(vut, cell)
    }

    fn evaluate_surrogate(&self, surrogate: &VehicleModel, cell: usize) -> SurrogateEvaluation {
        self.base.evaluate_surrogate(surrogate, cell)
    }
}

/// The island: the cut-in scenarios where the lead appears 42.5–43.5 m
/// ahead closing at 3.1–3.7 m/s, the window of `examples/python/idm_vut.py
/// --blind 42.5,43.5,-3.7,-3.1` (which `tslg validate --vut-exec` runs,
/// docs/statistics.md). Each of them, and each of their neighbours, is far
/// from a failure of the IDM: more than twice the search's near miss.
fn island(case: &CutIn, idm: &VehicleModel, near_miss: f64) -> HashSet<usize> {
    let grid = case.grid();
    let island: HashSet<usize> = (0..grid.len())
        .filter(|&c| {
            let v = grid.values(c);
            case.exposure().p(c) > 0.0
                && (42.5..=43.5).contains(&v[0])
                && (-3.7..=-3.1).contains(&v[1])
        })
        .collect();
    for &c in &island {
        for n in std::iter::once(c).chain(grid.neighbours(c)) {
            let criticality = case.event_and_criticality(idm, n).1;
            assert!(criticality > 2.0 * near_miss, "cell {n}: {criticality}");
        }
    }
    island
}

#[test]
fn an_island_the_search_cannot_reach_is_covered_by_the_guarded_end_and_found_by_the_guard() {
    let base = CutIn::builtin(CutInPreset::PaperCode);
    let idm = vehicle("idm");
    let settings = AdaptiveSettings::default();
    let island = island(&base, &idm, settings.near_miss);
    let library = library(&base, "idm", SearchMethod::Exhaustive);
    assert_eq!(island.len(), 2, "{island:?}");
    let case = WithIsland { base, island };
    for &c in &case.island {
        eprintln!(
            "island cell {c}: {:?} p {:e}",
            case.grid().values(c),
            case.exposure().p(c)
        );
    }
    let events = event_cells(&case, &idm);
    let mu = event_probability(&case, &events);
    let on_island: f64 = case.island.iter().map(|&c| case.exposure().p(c)).sum();
    assert!(
        on_island > 0.3 * mu && on_island < 0.7 * mu,
        "{on_island} of {mu}"
    );
    let z = z_for_confidence(0.9);
    let ndd = z * z * (1.0 - mu) / (0.04 * mu);
    // 200 seeds, floor 170: P(Bin(200, 0.90) < 170) ≤ 0.01, and a guarded
    // campaign covering 0.80 fails with probability 0.957.
    let check = tslg_testkit::CoverageCheck::new(200, 0.9, 0.01);
    let seeds = check.runs;
    let runs = |guard_outside: bool| -> Vec<AdaptiveResult> {
        let rule = StoppingRule {
            guard_outside,
            ..StoppingRule::new(0.2, 1_000_000)
        };
        (0..seeds)
            .map(|seed| run_adaptive(&case, &idm, &library, 0.1, settings, &rule, seed).unwrap())
            .collect()
    };
    let share = |runs: &[AdaptiveResult], f: &dyn Fn(&AdaptiveResult) -> bool| {
        runs.iter().filter(|r| f(r)).count() as f64 / runs.len() as f64
    };
    let median = |runs: &[AdaptiveResult]| {
        let mut t: Vec<u64> = runs.iter().map(|r| r.result.indices).collect();
        t.sort_unstable();
        t[t.len() / 2]
    };
    let guarded_covers =
        |r: &AdaptiveResult| r.result.ci_low <= mu && mu <= r.result.guarded_ci_high.unwrap();
    let plain = runs(false);
    let guarded = runs(true);
    let (plain_covers, plain_guarded) = (
        share(&plain, &|r| r.result.covers(mu)),
        share(&plain, &guarded_covers),
    );
    let (guard_covers, guard_guarded) = (
        share(&guarded, &|r| r.result.covers(mu)),
        share(&guarded, &guarded_covers),
    );
    let found = share(&guarded, &|r| {
        case.island.iter().all(|c| r.support.contains(c))
    });
    eprintln!(
        "island {:?} of mass {on_island:.3e}, P(A) {mu:.3e}, NDD {ndd:.0}: plain adaptive \
         covers {plain_covers}, its guarded end {plain_guarded}, median {} tests; guarded \
         adaptive covers {guard_covers}, its guarded end {guard_guarded}, found the island \
         {found}, median {} tests",
        case.island,
        median(&plain),
        median(&guarded)
    );
    // The plain adaptive interval rests on the search reaching every
    // failure: here it does not, and it misses in most runs.
    assert!(plain_covers < 0.5, "{plain_covers}");
    // Its guarded upper end holds what its exploring tests cannot rule out.
    assert!(plain_guarded >= 0.95, "{plain_guarded}");
    // The guard explores until that is within β: the island is found and
    // the interval covers (the check's floor), in fewer tests than the NDD.
    let covered = guarded.iter().filter(|r| r.result.covers(mu)).count() as u64;
    check.assert_covers(covered, "guarded adaptive campaigns of the island");
    assert!(found >= 0.95, "the island found in {found} of the runs");
    assert!(
        (median(&guarded) as f64) < ndd,
        "{} vs {ndd:.0}",
        median(&guarded)
    );
}
