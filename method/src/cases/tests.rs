use super::*;
use crate::case::Case;
use crate::cases::carfollow::PolicySolver;
use crate::cases::cutin::{CutIn, CutInPreset};
use crate::exact::event_cells;
use crate::library::{Library, SearchMethod};
use crate::registry::{BuildRequest, LibraryBuilder, LibrarySearch};
use crate::sampling::{OutsideSpread, Split};
use serde_json::json;

#[test]
fn the_registered_cut_in_case_answers_like_the_typed_one() {
    let case = open_case("cut-in", None, &ExposureSource::Builtin).unwrap();
    let typed = CutIn::builtin(CutInPreset::default());
    let idm = crate::vehicle::VehicleModel::builtin("idm").unwrap();
    let events = event_cells(&typed, &idm);
    let p = case
        .exact_event_probability(&json!({"model": "idm"}))
        .unwrap();
    assert_eq!(p, crate::exact::event_probability(&typed, &events));
    let built = case
        .build_library(
            &json!({"model": "idm"}),
            &BuildRequest {
                threshold: None,
                search: Some(LibrarySearch::Cells(SearchMethod::Exhaustive)),
            },
        )
        .unwrap();
    assert_eq!(built.size, 286);
    assert_eq!(built.media_type, "application/json");
    let library = Library::from_json(std::str::from_utf8(&built.file).unwrap()).unwrap();
    assert_eq!(library.size(), 286);
    // A library campaign's tests: their cells are the library's draws and
    // their events the typed case's.
    let tests = case
        .campaign(
            Some(&built.file),
            &json!({"model": "idm"}),
            0.1,
            OutsideSpread::Uniform,
            Split::Stratified,
            3,
        )
        .unwrap();
    // Its picture: P(x) on the 45 × 76 grid beside q(x) = V(x)/W, which
    // is positive on exactly the library's cells.
    let picture = case.library_picture(&built.file).unwrap();
    assert_eq!(picture.len(), 2);
    let (exposure, q) = (&picture[0], &picture[1]);
    assert_eq!(
        (exposure.x_label.as_str(), exposure.y_label.as_str()),
        ("range R (m)", "range rate Ṙ (m/s)")
    );
    assert_eq!(exposure.values.len(), 45 * 76);
    assert!((exposure.values.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    for (cell, &p) in exposure.values.iter().enumerate() {
        assert_eq!(p, typed.exposure().p(cell));
    }
    assert_eq!(q.values.iter().filter(|&&v| v > 0.0).count(), 286);
    assert!((q.values.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    for c in &library.cells {
        assert_eq!(q.values[c.cell], c.criticality / library.w);
    }
    assert!(case.library_picture(b"{}").is_err());
    for index in 0..200 {
        let planned = tests.planned(index).unwrap();
        let outcome = tests.run(index);
        assert_eq!(outcome.weight, planned.weight);
        assert_eq!(outcome.event, events.binary_search(&planned.cell).is_ok());
        assert_eq!(tests.check_event(index, planned.weight), Ok(()));
        assert!(tests.check_event(index, planned.weight * 2.0).is_err());
    }
}

#[test]
fn bad_names_vehicles_requests_and_tables_get_precise_errors() {
    let err = open_case("lane-keep", None, &ExposureSource::Builtin)
        .err()
        .unwrap();
    assert_eq!(
        err.to_string(),
        "unknown case `lane-keep`; known cases: cut-in, highway-exit, car-following"
    );
    let err = open_case("cut-in", Some("fast"), &ExposureSource::Builtin)
        .err()
        .unwrap();
    assert!(err.to_string().contains("fast"), "{err}");
    let table = ExposureSource::Table {
        name: "t.csv".into(),
        text: "range,range_rate\n1,x".into(),
    };
    let err = open_case("cut-in", None, &table).err().unwrap();
    assert!(
        err.to_string()
            .starts_with("exposure table `t.csv` rejected: "),
        "{err}"
    );
    let case = open_case("cut-in", None, &ExposureSource::Builtin).unwrap();
    let err = case
        .normalise_vehicle(&json!({"model": "idm", "alpha": -1.0}))
        .unwrap_err();
    assert!(err.to_string().contains("alpha"), "{err}");
    let err = case
        .normalise_vehicle(&json!({"model": "tesla"}))
        .unwrap_err();
    assert!(err.to_string().contains("unknown variant `tesla`"), "{err}");
    let err = case
        .check_request(&BuildRequest {
            threshold: None,
            search: Some(LibrarySearch::Policy(PolicySolver::DynamicProgramming)),
        })
        .unwrap_err();
    assert!(
        err.to_string().contains("exhaustive or multistart"),
        "{err}"
    );
}

#[test]
fn the_highway_exit_case_opens_by_name_with_its_presets_and_only_its_own_exposure() {
    let coarse = open_case("highway-exit", Some("coarse"), &ExposureSource::Builtin).unwrap();
    assert_eq!(
        (coarse.name(), coarse.preset()),
        ("highway-exit", "coarse".into())
    );
    assert_eq!(coarse.total_scenarios(), 16 * 6 * 16 * 6);
    let ndd = coarse
        .campaign(
            None,
            &json!({"model": "mobil"}),
            0.1,
            OutsideSpread::Uniform,
            Split::Stratified,
            0,
        )
        .unwrap();
    let first = ndd.planned(0).unwrap();
    assert_eq!(first.scenario.len(), 4);
    assert_eq!(first.weight, 1.0);
    let spec = coarse
        .normalise_vehicle(&json!({"model": "gap-seeker"}))
        .unwrap();
    assert_eq!(spec["front_gap"], json!(0.8), "every parameter written out");
    let err = coarse
        .normalise_vehicle(&json!({"model": "mobil", "politeness": 2}))
        .unwrap_err();
    assert!(err.to_string().contains("politeness"), "{err}");
    assert!(coarse.normalise_vehicle(&json!({"model": "idm"})).is_err());
    let table = ExposureSource::Table {
        name: "t.csv".into(),
        text: "0,1\n1,1".into(),
    };
    // Its tables are P(v₁, R, v₂) blocks (docs/bring-your-own.md).
    let err = open_case("highway-exit", None, &table).err().unwrap();
    assert!(
        err.to_string().contains("a block starts with a header"),
        "{err}"
    );
    let err = open_case("highway-exit", Some("fine"), &ExposureSource::Builtin)
        .err()
        .unwrap();
    assert!(err.to_string().contains("presets are paper"), "{err}");
}

#[test]
fn the_car_following_case_learns_a_policy_file_and_replays_reported_accidents() {
    let case = open_case("car-following", Some("risky"), &ExposureSource::Builtin).unwrap();
    assert_eq!(
        (case.name(), case.preset()),
        ("car-following", "risky".into())
    );
    assert_eq!(case.total_scenarios(), 45_885);
    assert_eq!(case.default_outside(), OutsideSpread::Ndd);
    let err = case
        .check_request(&BuildRequest {
            threshold: Some(crate::library::Threshold::default()),
            search: None,
        })
        .unwrap_err();
    assert!(err.to_string().contains("takes no threshold"), "{err}");
    let err = case
        .check_request(&BuildRequest {
            threshold: None,
            search: Some(LibrarySearch::Cells(SearchMethod::Exhaustive)),
        })
        .unwrap_err();
    assert!(err.to_string().contains("dynamic-programming"), "{err}");
    let built = case
        .build_library(&json!({"model": "idm"}), &BuildRequest::default())
        .unwrap();
    assert!(built.size > 0 && built.mu_s > 0.0, "{built:?}");
    assert!(built.file.len() < 4 << 20, "{} bytes", built.file.len());
    let tests = case
        .campaign(
            Some(&built.file),
            &json!({"model": "acc-aeb"}),
            0.1,
            OutsideSpread::Ndd,
            Split::Stratified,
            5,
        )
        .unwrap();
    assert!(tests.planned(0).is_none());
    let (mut accidents, mut safe) = (0, 0);
    for index in 0..400 {
        let outcome = tests.run(index);
        let check = tests.check_event(index, outcome.weight);
        if outcome.event {
            accidents += 1;
            assert_eq!(check, Ok(()));
            assert!(tests.check_event(index, outcome.weight * 1.5).is_err());
        } else {
            safe += 1;
            let err = check.unwrap_err();
            assert!(err.contains("replaying it gives none"), "{err}");
        }
    }
    assert!(
        accidents > 0 && safe > 0,
        "{accidents} accidents, {safe} safe"
    );
    // Another preset's library is refused by fingerprint.
    let paper = open_case("car-following", None, &ExposureSource::Builtin).unwrap();
    let err = paper
        .campaign(
            Some(&built.file),
            &json!({"model": "idm"}),
            0.1,
            OutsideSpread::Ndd,
            Split::Stratified,
            0,
        )
        .err()
        .unwrap();
    assert!(err.to_string().contains("risky"), "{err}");
    let err = paper
        .exact_event_probability(&json!({"model": "idm"}))
        .unwrap_err();
    assert!(err.to_string().contains("no enumeration"), "{err}");
}

#[test]
fn the_coordinators_replay_gives_every_tests_outcome_and_nothing_for_programs() {
    let library = |case: &dyn LibraryBuilder, surrogate: &str| {
        case.build_library(
            &json!({ "model": surrogate }),
            &BuildRequest {
                threshold: None,
                search: Some(LibrarySearch::Cells(SearchMethod::Exhaustive)),
            },
        )
        .unwrap()
        .file
    };
    let cut_in = open_case("cut-in", None, &ExposureSource::Builtin).unwrap();
    let file = library(cut_in.as_ref(), "idm");
    for (vut, file) in [("fvdm", Some(&file[..])), ("idm", None)] {
        let tests = cut_in
            .campaign(
                file,
                &json!({ "model": vut }),
                0.1,
                OutsideSpread::Uniform,
                Split::Stratified,
                9,
            )
            .unwrap();
        // Twice: the first replay of a cell runs it, later ones remember it.
        for _ in 0..2 {
            for index in 0..3000 {
                let (run, replay) = (tests.run(index), tests.replay(index).unwrap());
                assert_eq!(
                    (run.event, run.weight.to_bits()),
                    (replay.event, replay.weight.to_bits()),
                    "{vut} test {index}"
                );
                let (_, explored) = tests.replay_explored(index).unwrap();
                assert_eq!(explored, tests.explores(index), "{vut} test {index}");
            }
        }
    }
    let program = cut_in
        .campaign(
            Some(&file),
            &json!({"external": "mine"}),
            0.1,
            OutsideSpread::Uniform,
            Split::Stratified,
            9,
        )
        .unwrap();
    assert_eq!(program.replay(0), None);
    let follow = open_case("car-following", Some("risky"), &ExposureSource::Builtin).unwrap();
    let tests = follow
        .campaign(
            None,
            &json!({"model": "idm"}),
            0.1,
            OutsideSpread::Ndd,
            Split::Stratified,
            2,
        )
        .unwrap();
    for index in 0..200 {
        let (run, replay) = (tests.run(index), tests.replay(index).unwrap());
        assert_eq!(
            (run.event, run.weight.to_bits()),
            (replay.event, replay.weight.to_bits())
        );
    }
}

#[test]
fn a_multistart_library_is_the_same_file_every_time_it_is_built() {
    // Built by workers in other processes, a library must not depend on
    // the order a hash map keeps its cells in (μ_S and γ are sums).
    let case = open_case("cut-in", None, &ExposureSource::Builtin).unwrap();
    let request = BuildRequest {
        threshold: None,
        search: Some(LibrarySearch::Cells(SearchMethod::Multistart {
            starts: 50,
            seed: 0,
        })),
    };
    let build = || {
        case.build_library(&json!({"model": "idm"}), &request)
            .unwrap()
    };
    let first = build();
    assert!(first.size > 100, "{}", first.size);
    for _ in 0..8 {
        assert!(build().file == first.file, "a rebuild differs");
    }
    // And a worker's upload of it passes the coordinator's check.
    let again = case
        .built_elsewhere(&first.file, &json!({"model": "idm"}), 64)
        .unwrap();
    assert_eq!((again.size, again.mu_s), (first.size, first.mu_s));
    let fvdm_file = case
        .build_library(&json!({"model": "fvdm"}), &request)
        .unwrap()
        .file;
    let err = case
        .built_elsewhere(&fvdm_file, &json!({"model": "idm"}), 64)
        .unwrap_err()
        .to_string();
    assert!(err.contains("the surrogate gives"), "{err}");
}

#[test]
fn a_span_of_tests_run_in_batches_is_the_tests_run_one_by_one() {
    let case = open_case("cut-in", None, &ExposureSource::Builtin).unwrap();
    let library = case
        .build_library(&json!({"model": "idm"}), &BuildRequest::default())
        .unwrap()
        .file;
    for vut in ["fvdm", "idm", "switching-acc"] {
        let vut = json!({ "model": vut });
        for file in [None, Some(library.as_slice())] {
            let tests = case
                .campaign(file, &vut, 0.1, OutsideSpread::Uniform, Split::Random, 7)
                .unwrap();
            let span = tests
                .run_span(100, 3_101)
                .expect("built-in vehicles run in spans");
            let one_by_one: Vec<_> = (100..3_101).map(|i| tests.run(i)).collect();
            assert_eq!(span, one_by_one, "{vut}, library: {}", file.is_some());
            assert!(span.iter().any(|o| o.event), "{vut}");
        }
    }
    // A program is run test by test by whoever hosts it.
    let program = case
        .campaign(
            None,
            &json!({"external": "py-idm"}),
            0.1,
            OutsideSpread::Uniform,
            Split::Random,
            7,
        )
        .unwrap();
    assert!(program.run_span(0, 10).is_none());
}

#[test]
fn car_following_tests_run_in_batches_are_the_tests_run_one_by_one() {
    for preset in ["risky", "paper"] {
        let case = open_case("car-following", Some(preset), &ExposureSource::Builtin).unwrap();
        let policy = case
            .build_library(&json!({"model": "idm"}), &BuildRequest::default())
            .unwrap()
            .file;
        for vut in ["idm", "fvdm", "acc-aeb"] {
            let vut = json!({ "model": vut });
            for file in [None, Some(policy.as_slice())] {
                let tests = case
                    .campaign(file, &vut, 0.1, OutsideSpread::Ndd, Split::Random, 3)
                    .unwrap();
                let Some(span) = tests.run_span(50, 2_051) else {
                    // A stateful follower runs one by one.
                    assert_eq!(vut["model"], "acc-aeb");
                    continue;
                };
                let one_by_one: Vec<_> = (50..2_051).map(|i| tests.run(i)).collect();
                assert_eq!(
                    span,
                    one_by_one,
                    "{preset}, {vut}, library: {}",
                    file.is_some()
                );
                // The coordinator's replay of scattered tests, in batches.
                let picks = [7, 3_000, 12, 12, 999, 5, 40_000, 1, 2, 3];
                let replayed: Vec<_> = picks.iter().map(|&i| tests.replay(i).unwrap()).collect();
                assert_eq!(tests.replay_many(&picks), Some(replayed));
                if file.is_some() || preset == "risky" {
                    assert!(span.iter().any(|o| o.event), "{preset} {vut}: no accident");
                }
            }
        }
    }
}

#[test]
fn a_noisy_vehicles_exact_answer_is_a_seeded_monte_carlo_with_its_error() {
    use crate::exact::{event_rates, rate_probability, NOISY_RUNS_PER_CELL};
    let typed = CutIn::builtin(CutInPreset::default());
    let idm = crate::vehicle::VehicleModel::builtin("idm").unwrap();
    let noisy: crate::vehicle::VehicleModel =
        serde_json::from_value(json!({"model": "idm", "noise": 1.5})).unwrap();
    // A deterministic vehicle's rates are its event cells, exactly.
    let plain = event_rates(&typed, &idm);
    assert!(plain.monte_carlo.is_none());
    assert_eq!(
        plain.cells.iter().map(|c| c.0).collect::<Vec<_>>(),
        event_cells(&typed, &idm)
    );
    let rates = event_rates(&typed, &noisy);
    let mc = rates
        .monte_carlo
        .expect("a noisy vehicle's rates are a Monte Carlo");
    assert_eq!(mc.runs_per_cell, NOISY_RUNS_PER_CELL);
    let p = rate_probability(&typed, &rates);
    let p_plain = rate_probability(&typed, &plain);
    // The noise moves outcomes near the boundary only: some cells vary, and
    // the rate stays of the plain model's order.
    assert!(mc.varying_cells > 0);
    assert!(rates.cells.iter().any(|&(_, r)| r > 0.0 && r < 1.0));
    assert!(mc.standard_error < 0.02 * p, "{mc:?} at {p:e}");
    assert!(
        p > 0.5 * p_plain && p < 2.0 * p_plain,
        "{p:e} vs {p_plain:e}"
    );
    // One fixed computation: the same again.
    assert_eq!(event_rates(&typed, &noisy), rates);
}
