//! Vehicles that are not bit-reproducible (issue 47): honest workers of a
//! noisy program are not flagged when their runs of one test differ, and
//! a worker whose program differs from the others' is, by the statistics
//! of its disagreements (docs/statistics.md, "Noisy vehicles").

use crate::support::*;
use std::path::Path;
use std::time::{Duration, Instant};
use tslg_api::{CampaignStatus, Method, WorkerView};
use tslg_client::Client;

/// `--vut-exec` for the Python IDM with actuator noise σ 1.5 m/s² (its
/// hello says `"deterministic": false`), and `extra` options.
pub(crate) fn noisy_idm(extra: &str) -> String {
    format!(
        "py-idm=python3 {} --noise 1.5 {extra}",
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("examples/python/idm_vut.py")
            .display()
    )
}

/// Workers `names` running the noisy Python IDM with `extra` options.
fn workers(url: &str, names: &[&str], extra: &str) -> Vec<WorkerProcess> {
    let exec = noisy_idm(extra);
    names
        .iter()
        .map(|name| WorkerProcess::start_with(url, 1, name, &["--vut-exec", &exec]))
        .collect()
}

/// A campaign of the Python IDM on `library`.
fn py_idm(
    method: Method,
    library: i64,
    seed: u64,
    vehicle_noise: bool,
) -> tslg_api::CreateCampaign {
    tslg_api::CreateCampaign {
        vut: serde_json::json!({"external": "py-idm"}),
        vehicle_noise,
        ..campaign(method, library, "idm", 0.2, seed)
    }
}

pub(crate) async fn worker_views(client: &Client) -> Vec<WorkerView> {
    client.workers().await.unwrap().workers
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn honest_workers_of_a_noisy_program_are_not_flagged_and_their_campaigns_converge() {
    let dir = scratch();
    // Every test is run again, so that honest runs differing is all but
    // certain (about one audit in a hundred differs, out of some 800).
    let server = ServerProcess::start(
        &dir.path().join("db.sqlite"),
        &["--lease-size", "40", "--audit-share", "1"],
    );
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let plain = client
        .create_campaign(&py_idm(Method::Library, library.id, 3, true))
        .await
        .unwrap()
        .id;
    let adaptive = client
        .create_campaign(&py_idm(Method::Adaptive, library.id, 4, true))
        .await
        .unwrap()
        .id;
    let _workers = workers(&server.url, &["noisy-1", "noisy-2", "noisy-3"], "");
    let mut differed = 0;
    for id in [plain, adaptive] {
        let view = finished(&client, id, Duration::from_secs(400)).await;
        assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
        assert!(view.vehicle_noise, "campaign {id} is not audited as noisy");
        // Run without the guard (as this test asks, to stay short), a
        // noisy campaign answers with the guarded interval and says why,
        // with the switch that makes that interval narrow.
        assert!(!view.guard_outside);
        let answer = view.answer.as_ref().expect("an answer");
        assert_eq!(answer.interval, tslg_api::AnswerInterval::Guarded);
        assert_eq!(Some(answer.high), view.guarded_ci_high);
        assert!(
            view.warnings
                .iter()
                .any(|w| w.starts_with("the vehicle is noisy")
                    && w.contains(r#""guard_outside": true"#)),
            "{:?}",
            view.warnings
        );
        let audits = view.audits.expect("an external program's audits");
        eprintln!("campaign {id}: {} tests, audits {audits:?}", view.tests);
        // Nobody was flagged for runs that differ.
        assert!(audits.agreed > 0, "{audits:?}");
        assert_eq!(audits.settled, 0, "{audits:?}");
        assert_eq!(audits.void, 0, "{audits:?}");
        differed += audits.undecided;
    }
    // Runs of one test did differ (at the knife edges the adaptive
    // search goes to), where exact audits would have flagged someone.
    assert!(differed > 0, "no audit differed");
    let workers = worker_views(&client).await;
    let compared: u64 = workers.iter().map(|w| w.noisy_audits_compared).sum();
    assert!(compared > 0, "{workers:?}");
    for worker in &workers {
        assert!(worker.flagged.is_none(), "{worker:?}");
        assert!(worker.noisy_evidence.unwrap_or(1.0) < 1e4, "{worker:?}");
        // Every test is evidence too, and nothing leans.
        assert!(worker.test_evidence.unwrap_or(1.0) < 1e4, "{worker:?}");
    }
    // (Whether the library campaign's tests paired at all depends on how
    // its few leases fell among the workers: tests/it/service_evidence.rs
    // checks the pairing.)
    // The program says in its hello that it is noisy; a campaign that
    // does not say so is told, and not switched by the workers' word.
    let unmarked = client
        .create_campaign(&py_idm(Method::Ndd, library.id, 5, false))
        .await
        .unwrap()
        .id;
    let view = wait_for(&client, unmarked, Duration::from_secs(60), |v| {
        v.warnings
            .iter()
            .any(|w| w.contains("says its runs of one test may differ"))
    })
    .await;
    assert!(!view.vehicle_noise, "{view:?}");
    client.cancel_campaign(unmarked).await.unwrap();
}

/// `--vut-exec` for the FVDM in Rust (`examples/fvdm_vut`) with actuator
/// noise σ 1.5 m/s² and `extra` options; campaigns run it in episode mode,
/// one message a test.
pub(crate) fn noisy_fvdm(extra: &str) -> String {
    let bin = example_binary("fvdm_vut");
    format!("rs-fvdm={} --noise 1.5 {extra}", bin.display())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_worker_whose_noisy_program_brakes_harder_is_flagged_by_its_disagreements() {
    let dir = scratch();
    let server = ServerProcess::start(
        &dir.path().join("db.sqlite"),
        &["--lease-size", "50", "--audit-share", "1"],
    );
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let start = |name: &str, extra: &str| {
        WorkerProcess::start_with(&server.url, 1, name, &["--vut-exec", &noisy_fvdm(extra)])
    };
    let _honest = [
        start("fair-1", ""),
        start("fair-2", ""),
        start("fair-3", ""),
    ];
    let _harder = start("harder", "--brake-harder 3");
    // Campaigns of 10,000 tests one after another, every test audited,
    // until the evidence against the worker that brakes harder is strong
    // enough: its runs differ from another's on about one test in a
    // hundred, and the flag needs some 25 of those.
    let started = Instant::now();
    let mut campaigns = 0;
    let harder = loop {
        assert!(
            started.elapsed() < Duration::from_secs(400) && campaigns < 10,
            "the worker that brakes harder was not flagged after {campaigns} campaigns: {:?}",
            worker_views(&client).await
        );
        let request = tslg_api::CreateCampaign {
            vut: serde_json::json!({"external": "rs-fvdm", "mode": "episode"}),
            vehicle_noise: true,
            max_tests: 10_000,
            ..campaign(Method::Library, library.id, "fvdm", 0.01, campaigns)
        };
        let id = client.create_campaign(&request).await.unwrap().id;
        campaigns += 1;
        let view = finished(&client, id, Duration::from_secs(300)).await;
        assert_eq!(view.status, CampaignStatus::Exhausted, "{view:?}");
        let workers = worker_views(&client).await;
        if let Some(harder) = workers.iter().find(|w| w.flagged.is_some()) {
            break harder.clone();
        }
    };
    assert_eq!(harder.name, "harder", "{harder:?}");
    let detail = harder.flagged.clone().unwrap();
    assert!(
        detail.contains("behaves unlike the other workers'"),
        "{detail}"
    );
    // It found the event on the wrong side of nearly every disagreement.
    assert!(
        harder.noisy_partner_events >= 17
            && harder.noisy_own_events * 4 < harder.noisy_partner_events,
        "{harder:?}"
    );
    eprintln!(
        "flagged after {campaigns} campaigns and {} compared audits ({} differed: {} its events, \
         {} its partners')",
        harder.noisy_audits_compared,
        harder.noisy_own_events + harder.noisy_partner_events,
        harder.noisy_own_events,
        harder.noisy_partner_events
    );
    for worker in worker_views(&client).await {
        if worker.name != "harder" {
            assert!(worker.flagged.is_none(), "{worker:?}");
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_noisy_builtin_vehicle_runs_as_in_process_and_both_vehicles_of_a_pair_share_its_noise() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let _workers = two_workers(&server.url);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let noisy = serde_json::json!({"model": "idm", "noise": 1.5});
    let request = tslg_api::CreateCampaign {
        vut: noisy.clone(),
        ..campaign(Method::Library, library.id, "idm", 0.2, 7)
    };
    let id = client.create_campaign(&request).await.unwrap().id;
    let view = finished(&client, id, Duration::from_secs(120)).await;
    assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
    // Each test's noise is its own stream: the workers, the coordinator's
    // replay and this process run the same tests to the last bit.
    assert_same(&view, &in_process(Some("idm"), &request));
    // The reference is the Monte Carlo P(A), not the plain IDM's.
    let reference = view.exact_probability.expect("a Monte Carlo reference");
    assert!((reference - exact("idm")).abs() > 1e-5, "{reference:e}");
    // A pair of the noisy IDM with itself: common random numbers give
    // both vehicles the same noise on every test, so no test differs.
    let pair = tslg_api::CreateCampaign {
        method: Method::Ndd,
        paired_with: Some(noisy.clone()),
        max_tests: 200_000,
        ..request.clone()
    };
    let id = client.create_campaign(&pair).await.unwrap().id;
    let view = finished(&client, id, Duration::from_secs(120)).await;
    let pair = view.pair.expect("a pair's view");
    assert!(pair.events_a > 0, "{pair:?}");
    assert_eq!(
        (pair.events_a, pair.discordant),
        (pair.events_b, 0),
        "{pair:?}"
    );
}
