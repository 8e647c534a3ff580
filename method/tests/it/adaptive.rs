//! Adaptive campaigns on cut-in against the exact answers: coverage and
//! cost across seeds, the assumption they rest on shown failing where it
//! fails, and the same answer on any number of threads.

use crate::common::{library, vehicle};
use tslg_method::adaptive::{run_adaptive, AdaptiveResult, AdaptiveSettings};
use tslg_method::case::Case;
use tslg_method::cases::cutin::{CutIn, CutInPreset};
use tslg_method::cases::highway::{ExitVehicle, HighwayExit, HighwayPreset};
use tslg_method::estimator::{z_for_confidence, Decision, StoppingRule};
use tslg_method::exact::{event_cells, event_probability};
use tslg_method::library::{build_library, LibraryRequest, SearchMethod, Threshold};
use tslg_method::registry::AdaptiveRun;
use tslg_testkit::CoverageCheck;

/// The campaigns of seeds `0..seeds` of `vut` on `surrogate`'s exhaustive
/// library, with `P(A)` and the NDD baseline's expected tests.
fn campaigns(
    case: &CutIn,
    surrogate: &str,
    vut: &str,
    seeds: u64,
) -> (Vec<AdaptiveResult>, f64, f64) {
    let library = library(case, surrogate, SearchMethod::Exhaustive);
    let v = vehicle(vut);
    let mu = event_probability(case, &event_cells(case, &v));
    let z = z_for_confidence(0.9);
    let ndd = z * z * (1.0 - mu) / (0.2f64.powi(2) * mu);
    (seeded_runs(case, &library, &v, seeds), mu, ndd)
}

/// The adaptive campaigns of seeds `0..seeds` of `vehicle` on `library`,
/// β 0.2, ε 0.1, the default settings.
fn seeded_runs(
    case: &CutIn,
    library: &tslg_method::library::Library,
    vehicle: &tslg_method::vehicle::VehicleModel,
    seeds: u64,
) -> Vec<AdaptiveResult> {
    seeded_runs_under(
        case,
        library,
        vehicle,
        seeds,
        &StoppingRule::new(0.2, 1_000_000),
    )
}

/// [`seeded_runs`] under `rule`.
fn seeded_runs_under(
    case: &CutIn,
    library: &tslg_method::library::Library,
    vehicle: &tslg_method::vehicle::VehicleModel,
    seeds: u64,
    rule: &StoppingRule,
) -> Vec<AdaptiveResult> {
    (0..seeds)
        .map(|seed| {
            run_adaptive(
                case,
                vehicle,
                library,
                0.1,
                AdaptiveSettings::default(),
                rule,
                seed,
            )
            .unwrap()
        })
        .collect()
}

/// The coverage tests' plan: 200 seeds (0..200), floor 170 = the largest
/// k with P(Bin(200, 0.90) < k) ≤ 0.01, so a campaign covering at the
/// nominal 0.90 passes on 99 % of seed sets, and one covering 0.80 fails
/// with probability 0.957 (`tslg_testkit::CoverageCheck`, which refuses a
/// plan below 0.95). A pairing that covers a little below nominal fails
/// more often on a fresh set of seeds: FVDM → IDM, at 0.883 over 1,000
/// seeds, on 6 % of them, one at the issue-21 target 0.87 on 17 %. The
/// seeds are fixed, so a change of the random streams can move a pairing
/// across the floor: then measure it over 1,000 seeds before anything
/// else (docs/adaptive-design.md).
static COVERAGE: std::sync::LazyLock<CoverageCheck> =
    std::sync::LazyLock::new(|| CoverageCheck::new(200, 0.9, 0.01));

/// The exposure of the failing cells (`events`) in a campaign's last
/// estimation support.
fn failure_mass_held(
    case: &CutIn,
    events: &std::collections::HashSet<usize>,
    r: &AdaptiveResult,
) -> f64 {
    r.support
        .iter()
        .filter(|c| events.contains(c))
        .map(|&c| case.exposure().p(c))
        .sum()
}

fn median_tests(runs: &[AdaptiveResult]) -> f64 {
    let mut tests: Vec<u64> = runs.iter().map(|r| r.result.indices).collect();
    tests.sort_unstable();
    tests[tests.len() / 2] as f64
}

#[test]
fn adaptive_campaigns_cover_where_the_search_reaches_every_failure() {
    // The IDM's library testing the IDM, the FVDM (83 % of its failure mass
    // outside the library), the ACC+AEB (34 %) and the switching ACC (15 %,
    // most of it in one cell walled off from the library's failures by
    // scenarios it passes easily: reached from the near misses that
    // exploring tests meet), and the FVDM's library testing the IDM
    // (docs/adaptive-design.md).
    let case = CutIn::builtin(CutInPreset::PaperCode);
    for (surrogate, vut, least_ratio) in [
        ("idm", "idm", 100.0),
        ("idm", "fvdm", 10.0),
        ("idm", "acc-aeb", 50.0),
        ("idm", "switching-acc", 10.0),
        ("fvdm", "idm", 100.0),
    ] {
        let (runs, mu, ndd) = campaigns(&case, surrogate, vut, COVERAGE.runs);
        let covered = runs.iter().filter(|r| r.result.covers(mu)).count() as u64;
        let coverage = covered as f64 / runs.len() as f64;
        let ratio = ndd / median_tests(&runs);
        // The share of campaigns whose estimation stage's support K holds
        // 95 % of the failure mass (the rest only its exploring share meets).
        let events: std::collections::HashSet<usize> =
            event_cells(&case, &vehicle(vut)).into_iter().collect();
        let held = |r: &AdaptiveResult| failure_mass_held(&case, &events, r);
        let found = runs.iter().filter(|r| held(r) > 0.95 * mu).count() as f64 / 200.0;
        eprintln!(
            "{surrogate} → {vut}: coverage {coverage}, median tests {} (NDD {ndd:.0}, \
             ratio {ratio:.0}), supports holding 95 % of the failure mass {found}",
            median_tests(&runs)
        );
        // COVERAGE's floor (170 of 200 at c = 0.9). FVDM → IDM, the
        // closest, covers 0.883 over 1,000 seeds (docs/adaptive-design.md);
        // a plain library campaign covers 0.05–0.36.
        COVERAGE.assert_covers(covered, &format!("{surrogate} → {vut}"));
        assert!(ratio >= least_ratio, "{surrogate} → {vut}: ratio {ratio}");
        assert!(found >= 0.85, "{surrogate} → {vut}: found {found}");
        // The estimate counts only estimation tests, each weighted by its
        // own stage's distribution; the search tests are the cost.
        for r in &runs {
            assert_eq!(
                r.result.indices,
                r.library_tests + r.search_tests + r.result.tests
            );
        }
    }
}

#[test]
fn an_adaptive_campaign_is_the_same_on_any_number_of_threads() {
    let case = CutIn::builtin(CutInPreset::PaperCode);
    let library = library(&case, "idm", SearchMethod::Exhaustive);
    let v = vehicle("fvdm");
    let rule = StoppingRule::new(0.1, 1_000_000);
    let run = || {
        run_adaptive(
            &case,
            &v,
            &library,
            0.1,
            AdaptiveSettings::default(),
            &rule,
            7,
        )
        .unwrap()
    };
    let many = run();
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(run);
    assert_eq!(many, one);
    assert!(many.stages > 3 && many.search_tests > 0, "{many:?}");
}

#[test]
fn adaptive_campaigns_cover_highway_exit_for_the_surrogate_and_the_gap_seeker() {
    // The coarse grid (9,216 scenarios, 80 neighbours a cell). The plain
    // library covers the gap-seeker about 1 % of the time
    // (docs/statistics.md); the search reaches all of its failures.
    let case = HighwayExit::builtin(HighwayPreset::Coarse);
    let mobil = ExitVehicle::builtin("mobil").unwrap();
    let spec = serde_json::to_value(mobil).unwrap();
    let request = LibraryRequest {
        threshold: Threshold::default(),
        search: SearchMethod::Exhaustive,
    };
    let library = build_library(&case, &mobil, spec, "coarse", &request);
    for (vut, least_ratio) in [("mobil", 100.0), ("gap-seeker", 10.0)] {
        let v = ExitVehicle::builtin(vut).unwrap();
        let events: Vec<usize> = (0..case.grid().len())
            .filter(|&c| case.is_event(&v, c))
            .collect();
        let mu = event_probability(&case, &events);
        let z = z_for_confidence(0.9);
        let ndd = z * z * (1.0 - mu) / (0.2f64.powi(2) * mu);
        let rule = StoppingRule::new(0.2, 1_000_000);
        let runs: Vec<_> = (0..COVERAGE.runs)
            .map(|seed| {
                let settings = AdaptiveSettings::default();
                run_adaptive(&case, &v, &library, 0.1, settings, &rule, seed).unwrap()
            })
            .collect();
        let covered = runs.iter().filter(|r| r.result.covers(mu)).count() as u64;
        let ratio = ndd / median_tests(&runs);
        eprintln!(
            "highway-exit mobil → {vut}: coverage {covered}/{}, NDD / median tests {ratio:.0}",
            runs.len()
        );
        COVERAGE.assert_covers(covered, &format!("highway-exit mobil → {vut}"));
        assert!(ratio >= least_ratio, "{vut}: ratio {ratio}");
    }
}

/// The coordinator's copy of a service campaign, resolved stage by stage
/// from what a worker's copy reports for the cells the stages name, runs
/// the campaign [`run_adaptive`] runs in one process, bit for bit, on both
/// grid cases; an invalid test teaches nothing and does not count.
#[test]
fn a_service_adaptive_campaign_resolved_from_workers_runs_is_the_in_process_one() {
    use tslg_method::adaptive::TestResult;
    use tslg_method::cases::open_case;
    use tslg_method::registry::ExposureSource;
    use tslg_method::sampling::{OutsideSpread, Split};
    for (case_name, preset, surrogate, vut, seeds) in [
        (
            "cut-in",
            "paper-code",
            serde_json::json!({"model": "idm"}),
            serde_json::json!({"model": "fvdm"}),
            0..6u64,
        ),
        (
            "cut-in",
            "paper-code",
            serde_json::json!({"model": "idm"}),
            serde_json::json!({"model": "switching-acc"}),
            0..3,
        ),
        (
            "highway-exit",
            "coarse",
            serde_json::json!({"model": "mobil"}),
            serde_json::json!({"model": "gap-seeker"}),
            0..2,
        ),
    ] {
        let case = open_case(case_name, Some(preset), &ExposureSource::Builtin).unwrap();
        let request = tslg_method::registry::BuildRequest {
            threshold: None,
            search: Some(tslg_method::registry::LibrarySearch::Cells(
                SearchMethod::Exhaustive,
            )),
        };
        let surrogate = case.normalise_vehicle(&surrogate).unwrap();
        let vut = case.normalise_vehicle(&vut).unwrap();
        let file = case.build_library(&surrogate, &request).unwrap().file;
        let rule = StoppingRule::new(0.2, 1_000_000);
        let settings = AdaptiveSettings::default();
        for seed in seeds {
            let in_process = case
                .adaptive_campaign(&file, &vut, 0.1, settings, &rule, seed)
                .unwrap();
            let coordinator = case
                .adaptive_tests(&file, &vut, 0.1, settings, &rule, seed)
                .unwrap();
            let worker = case
                .campaign(
                    Some(&file),
                    &vut,
                    0.1,
                    OutsideSpread::Uniform,
                    Split::Stratified,
                    seed,
                )
                .unwrap();
            let stages = coordinator.adaptive().unwrap();
            let mut records = Vec::new();
            while let Some((from, to)) = stages.running() {
                let results: Vec<TestResult> = (from..to)
                    .map(|i| {
                        let planned = coordinator.planned(i).unwrap();
                        let (event, criticality) = worker.run_cell(i, planned.cell, None).unwrap();
                        TestResult::Done {
                            event,
                            criticality: criticality.unwrap(),
                        }
                    })
                    .collect();
                // The first prefix of the stage within which the rule
                // stops the campaign: the coordinator resolves the stage
                // there, with any results after it (here: events, which
                // would move the estimate were they folded), and
                // must get the in-process campaign, stopped at that test.
                match (1..=results.len()).find(|&k| stages.stops_within(&results[..k])) {
                    Some(k) => {
                        let mut early = results[..k].to_vec();
                        early.resize(
                            results.len(),
                            TestResult::Done {
                                event: true,
                                criticality: 0.0,
                            },
                        );
                        records.push(stages.resolve(&early));
                        assert_eq!(stages.running(), None, "stopped");
                        assert_eq!(in_process.result.indices, from + k as u64);
                    }
                    None => {
                        records.push(stages.resolve(&results));
                        assert!(
                            stages.running().is_some()
                                || in_process.result.status != Decision::Converged,
                            "a campaign that converged stopped within its last stage"
                        );
                    }
                }
            }
            let done = stages.progress().finished.unwrap();
            stage_records_tell_the_campaign(&records, &done);
            assert_eq!(
                AdaptiveRun::from_grid(done),
                in_process,
                "{case_name} {vut} seed {seed}"
            );
        }
    }
}

/// What the dashboard draws of an adaptive campaign, its stages' records,
/// agrees with the campaign: the stages tile its tests from 0 to its stop,
/// library first; their tests add up to its library and search tests;
/// their events are counted only up to the stop (the test above fills the
/// tests after it with events); an estimation stage's course ends at the
/// estimate after it, and the last course ends at the campaign's estimate.
fn stage_records_tell_the_campaign(
    records: &[tslg_method::adaptive::StageRecord],
    done: &AdaptiveResult,
) {
    assert_eq!(records[0].kind, "library");
    assert_eq!(records[0].start, 0);
    for pair in records.windows(2) {
        assert_eq!(pair[0].end, pair[1].start, "stages tile the tests");
    }
    assert_eq!(records.last().unwrap().end, done.result.indices);
    assert_eq!(records.len() as u64, done.stages);
    let tests_of = |kind: &str| -> u64 {
        records
            .iter()
            .filter(|r| r.kind == kind)
            .map(|r| r.end - r.start)
            .sum()
    };
    assert_eq!(tests_of("library"), done.library_tests);
    assert_eq!(tests_of("search"), done.search_tests);
    let estimation = records.iter().filter(|r| r.kind == "estimate");
    assert_eq!(
        estimation.clone().map(|r| r.events).sum::<u64>(),
        done.result.events,
        "the estimate's events are the estimation stages' events up to the stop"
    );
    let mut tests = 0;
    for r in estimation {
        assert!(r.course.windows(2).all(|w| w[0].indices < w[1].indices));
        let last = r.course.last().expect("an estimation stage's course");
        assert_eq!(last.indices, r.end, "the course ends at the stage's end");
        assert!(r
            .course
            .iter()
            .all(|p| (r.start..=r.end).contains(&p.indices)));
        tests += r.end - r.start - r.invalid;
        assert_eq!(last.estimator.tests(), tests);
    }
    for r in records.iter().filter(|r| r.kind != "estimate") {
        assert!(r.course.is_empty());
    }
    let last = records
        .iter()
        .rev()
        .find_map(|r| r.course.last())
        .expect("a campaign that stopped by its rule estimated");
    assert_eq!(last.estimate(), done.result.estimate);
    assert_eq!(records.last().unwrap().support, done.support.len() as u64);
    // The failing cells found, each once: a deterministic vehicle's
    // failures all stay in the support.
    let found: u64 = records.iter().map(|r| r.new_failures).sum();
    assert!(
        (1..=done.support.len() as u64).contains(&found),
        "{found} failing cells found, support {}",
        done.support.len()
    );
}

#[test]
fn guarded_adaptive_campaigns_of_a_noisy_vehicle_cover_its_monte_carlo_rate() {
    // The IDM with noise σ 1.5 m/s² on every command: about 170 cells near
    // its failure boundary fail on some runs and not others, and its near
    // misses reach far past them. A noisy campaign runs under the guard
    // and answers with the guarded interval [ci_low, guarded_ci_high]; its
    // support grows by its failures and their neighbours, only failures
    // seed the search, and the guard's share is the one of fewest tests
    // (docs/statistics.md, "Noisy vehicles"). COVERAGE's 200 seeds:
    // coverage at the nominal 0.9 (its floor), no bias, and more than
    // three times cheaper than the NDD. Under the rule before (near misses
    // in the support, the guard exploring 95 % of its tests) the same
    // campaigns needed 444,230 tests, 7.5 times the NDD's; judging a cell
    // on its first run alone, as for a deterministic vehicle, gave the
    // unguarded interval coverage 0.34.
    use tslg_method::exact::{event_rates, rate_probability};
    let case = CutIn::builtin(CutInPreset::PaperCode);
    let library = library(&case, "idm", SearchMethod::Exhaustive);
    let noisy: tslg_method::vehicle::VehicleModel =
        serde_json::from_value(serde_json::json!({"model": "idm", "noise": 1.5})).unwrap();
    let mu = rate_probability(&case, &event_rates(&case, &noisy));
    let rule = StoppingRule {
        guard_outside: true,
        ..StoppingRule::new(0.2, 1_000_000)
    };
    let runs = seeded_runs_under(&case, &library, &noisy, COVERAGE.runs, &rule);
    let covered = runs.iter().filter(|r| r.result.guarded_covers(mu)).count() as u64;
    let mean = runs.iter().map(|r| r.result.estimate).sum::<f64>() / runs.len() as f64;
    let z = z_for_confidence(0.9);
    let ndd = z * z * (1.0 - mu) / (0.2f64.powi(2) * mu);
    COVERAGE.assert_covers(covered, "the noisy IDM");
    assert!((mean / mu - 1.0).abs() < 0.05, "mean {mean:e} vs {mu:e}");
    assert!(
        ndd / median_tests(&runs) > 3.0,
        "{} tests, NDD {ndd:.0}",
        median_tests(&runs)
    );
}

/// An adaptive campaign's bound on the failure mass its support leaves out
/// (`outside_upper`) and its guarded upper end are what its exploring tests
/// give, recounted here from the stages it planned: each estimation test
/// drawn again, whether it explored and whether the vehicle fails in its
/// cell by enumeration of the grid (`event_cells`), each stage's exposure
/// off its support summed over the grid's cells. And the bound holds: it
/// is at least the failure mass the final support leaves out, on every seed
/// (a model-free bound from a few exploring tests is wide).
#[test]
fn the_adaptive_outside_bound_is_what_its_exploring_tests_give_by_enumeration() {
    use tslg_method::adaptive::{Planner, Stage, TestResult};
    use tslg_method::outside::clopper_pearson_upper;
    use tslg_method::sampling::TestDistribution;
    let case = CutIn::builtin(CutInPreset::PaperCode);
    let rule = StoppingRule::new(0.2, 1_000_000);
    let mut failing_explorers = 0;
    // The default settings, and (nearly) no search with half of each estimation
    // stage exploring: its exploring tests meet the FVDM's failures that
    // the IDM's library leaves out (83 % of its failure mass).
    let blind = AdaptiveSettings {
        exposure_floor: 0.999,
        explore_every: 2,
        ..AdaptiveSettings::default()
    };
    for (surrogate, vut, settings, seeds) in [
        ("idm", "fvdm", AdaptiveSettings::default(), 0..8u64),
        ("idm", "acc-aeb", AdaptiveSettings::default(), 0..8),
        ("idm", "fvdm", blind, 0..8),
    ] {
        let library = library(&case, surrogate, SearchMethod::Exhaustive);
        let v = vehicle(vut);
        let events: std::collections::HashSet<usize> = event_cells(&case, &v).into_iter().collect();
        let p = |c: usize| case.exposure().p(c);
        let planner = Planner::new(&case, &library, 0.1, settings).unwrap();
        for seed in seeds {
            let mut state = planner.start(&rule, seed);
            while state.finished().is_none() {
                let stage = state.current();
                let results: Vec<TestResult> = (stage.start..stage.end())
                    .map(|i| {
                        let (event, criticality) =
                            case.test_run(&v, stage.test(seed, i).0, seed, i);
                        TestResult::Done { event, criticality }
                    })
                    .collect();
                planner.resolve(&mut state, &rule, &results);
            }
            let done = state.finished().unwrap().clone();
            let (mut tests, mut failed, mut s1) = (0u64, 0u64, 0.0);
            let (mut mass_max, mut mass_sum, mut valid) = (0.0f64, 0.0, 0u64);
            for planned in state.stages() {
                let Stage::Estimate(d) = &planned.stage else {
                    continue;
                };
                let TestDistribution::Support(support) = d.as_ref() else {
                    panic!("{vut} seed {seed}: a support");
                };
                let inside: f64 = (0..case.grid().len())
                    .filter(|&c| support.contains(c))
                    .map(p)
                    .sum();
                let off = if support.epsilon() > 0.0 {
                    1.0 - inside
                } else {
                    0.0
                };
                for i in planned.start..planned.end().min(done.result.indices) {
                    valid += 1;
                    mass_sum += off;
                    let draw = d.draw(seed, i);
                    if support.contains(draw.cell) {
                        continue;
                    }
                    tests += 1;
                    mass_max = mass_max.max(off);
                    if events.contains(&draw.cell) {
                        failed += 1;
                        s1 += draw.weight;
                    }
                }
            }
            let r = &done.result;
            assert_eq!(
                (r.outside_tests, r.outside_events),
                (tests, failed),
                "{vut} {seed}"
            );
            // m̄: the estimation tests' average exposure off their support.
            let average = mass_sum / valid as f64;
            let upper = (mass_max * clopper_pearson_upper(failed, tests, 0.9)).min(average);
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs().max(1e-300);
            assert!(close(r.outside_upper.unwrap(), upper), "{r:?} vs {upper}");
            let guarded = r.ci_high.max(r.ci_high - s1 / r.tests as f64 + upper);
            assert!(
                close(r.guarded_ci_high.unwrap(), guarded),
                "{r:?} vs {guarded}"
            );
            // The failure mass the final support leaves out, by enumeration.
            let support: std::collections::HashSet<usize> = done.support.iter().copied().collect();
            let left_out: f64 = events
                .iter()
                .filter(|c| !support.contains(c))
                .map(|&c| p(c))
                .sum();
            assert!(left_out <= upper, "{vut} seed {seed}: {left_out} > {upper}");
            failing_explorers += failed;
        }
    }
    // Some exploring test met a failure outside its stage's support, so
    // the recount of events was put to the test.
    assert!(failing_explorers > 0);
}

#[test]
fn a_widened_search_finds_the_failures_of_the_one_ring_search_in_fewer_stages() {
    // A fleet's stages of 640 tests widen the search to 128 cells a stage
    // (`AdaptiveSettings::fleet_search_width`): what several one-ring
    // searches would test, tested in one round of the fleet.
    let case = CutIn::builtin(CutInPreset::PaperCode);
    let rule = StoppingRule::new(0.2, 1_000_000);
    let one_ring = AdaptiveSettings {
        stage_tests: 640,
        ..AdaptiveSettings::default()
    };
    let widened = AdaptiveSettings {
        search_width: AdaptiveSettings::fleet_search_width(640),
        ..one_ring
    };
    assert_eq!(widened.search_width, 128);
    for vut in ["fvdm", "switching-acc", "acc-aeb"] {
        let library = library(&case, "idm", SearchMethod::Exhaustive);
        let v = vehicle(vut);
        let events: std::collections::HashSet<usize> = event_cells(&case, &v).into_iter().collect();
        let held = |r: &AdaptiveResult| failure_mass_held(&case, &events, r);
        let (mut stages, mut mass) = ([0u64; 2], [0.0f64; 2]);
        for seed in 0..20 {
            for (k, settings) in [one_ring, widened].into_iter().enumerate() {
                let r = run_adaptive(&case, &v, &library, 0.1, settings, &rule, seed).unwrap();
                stages[k] += r.stages;
                mass[k] += held(&r);
            }
        }
        eprintln!("idm → {vut}: stages {stages:?}, failure mass held {mass:?}");
        assert!(stages[1] * 2 < stages[0], "idm → {vut}: stages {stages:?}");
        assert!(
            mass[1] >= mass[0] * (1.0 - 1e-9),
            "idm → {vut}: mass {mass:?}"
        );
    }
}
