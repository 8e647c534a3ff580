//! Every test is evidence (issue 67): a worker whose noisy program differs
//! from the others' (it brakes harder, or hides a share of its events) is
//! flagged by its tests, paired with the other workers' tests of the same
//! campaign and cell, within one library campaign at the default audit
//! share; its honest partners are not (docs/statistics.md, "Every test as
//! evidence").

use crate::service_noise::{noisy_fvdm, noisy_idm, worker_views};
use crate::support::*;
use std::time::{Duration, Instant};
use tslg_api::{CampaignStatus, Method, WorkerView};
use tslg_client::Client;

/// One run of the fleet: three honest workers running `honest`
/// (a `--vut-exec`) and a fourth, `odd-{run}`, running `odd`, on a library
/// campaign of `vut` at β 0.05 as a user starts it (the guard on by
/// default: the program says it is noisy), seed `run`. Waits until a
/// worker of this run is flagged, checks it is the odd one, that its test
/// pairs lean its way, and that no honest worker is flagged, then cancels
/// the campaign. The odd worker's view when flagged.
async fn odd_one_flagged(
    server: &ServerProcess,
    client: &Client,
    library: i64,
    run: u64,
    (honest, odd): (&str, &str),
    vut: serde_json::Value,
) -> WorkerView {
    let start = |name: &str, exec: &str| {
        WorkerProcess::start_with(&server.url, 1, name, &["--vut-exec", exec])
    };
    let _honest: Vec<WorkerProcess> = (1..=3)
        .map(|k| start(&format!("fair-{run}-{k}"), honest))
        .collect();
    let odd_name = format!("odd-{run}");
    let _odd = start(&odd_name, odd);
    let request = tslg_api::CreateCampaign {
        vut,
        vehicle_noise: true,
        guard_outside: None,
        ..campaign(Method::Library, library, "idm", 0.05, run)
    };
    let id = client.create_campaign(&request).await.unwrap().id;
    let started = Instant::now();
    let of_this_run =
        |w: &&WorkerView| w.name == odd_name || w.name.starts_with(&format!("fair-{run}-"));
    let caught = loop {
        let view = client.campaign(id).await.unwrap();
        let workers = worker_views(client).await;
        if let Some(caught) = workers
            .iter()
            .filter(of_this_run)
            .find(|w| w.flagged.is_some())
        {
            break caught.clone();
        }
        assert!(
            !view.status.is_final(),
            "run {run}: campaign {id} ended ({:?}, {} tests) with nobody flagged: {workers:?}",
            view.status,
            view.tests
        );
        assert!(
            started.elapsed() < Duration::from_secs(300),
            "run {run}: nobody flagged after 300 s ({} tests): {workers:?}",
            view.tests
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    assert_eq!(caught.name, odd_name, "run {run}: {caught:?}");
    let detail = caught.flagged.clone().unwrap();
    assert!(
        detail.contains("paired with tests of 3 other workers"),
        "{detail}"
    );
    // Its test was the further from the event in most pairs that differed.
    assert!(
        caught.test_own_events < caught.test_partner_events,
        "{caught:?}"
    );
    eprintln!(
        "run {run}: `{odd_name}` flagged after {} of its tests ({} pairs, {} differed: {} its \
         test closer, {} its partners'; {} compared audits)",
        caught.tests,
        caught.test_pairs_compared,
        caught.test_own_events + caught.test_partner_events,
        caught.test_own_events,
        caught.test_partner_events,
        caught.noisy_audits_compared
    );
    for worker in worker_views(client).await.iter().filter(of_this_run) {
        if worker.name != odd_name {
            assert!(worker.flagged.is_none(), "run {run}: {worker:?}");
        }
    }
    client.cancel_campaign(id).await.unwrap();
    let stopped = finished(client, id, Duration::from_secs(30)).await;
    assert_eq!(stopped.status, CampaignStatus::Cancelled);
    caught
}

/// Ten runs of [`odd_one_flagged`] on one coordinator, the default audit
/// share (1 %) and leases: `honest` and `odd` programs, campaigns of
/// `vut`. The odd worker's tests at each flag, sorted.
async fn ten_runs(programs: (String, String), vut: serde_json::Value) -> Vec<u64> {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await.id;
    let mut tests = Vec::new();
    for run in 0..10 {
        let odd = (programs.0.as_str(), programs.1.as_str());
        let caught = odd_one_flagged(&server, &client, library, run, odd, vut.clone()).await;
        tests.push(caught.tests);
    }
    tests.sort_unstable();
    tests
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_worker_whose_noisy_program_brakes_harder_is_flagged_by_its_tests_within_one_campaign() {
    // The fleet: three workers of the noisy Python IDM (σ 1.5
    // m/s², step mode: the worker measures each test's criticality) and a
    // fourth whose IDM brakes 3 m/s² harder.
    let programs = (noisy_idm(""), noisy_idm("--brake-harder 3"));
    let tests = ten_runs(programs, serde_json::json!({"external": "py-idm"})).await;
    eprintln!("the harder-braking worker's tests at its flag, sorted: {tests:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_worker_whose_noisy_program_hides_events_is_flagged_by_its_tests_within_one_campaign() {
    // Three workers of the noisy FVDM (episode mode: no criticality, the
    // event alone) and a fourth whose program reports no event in 30 % of
    // the tests that had one (the noisy liar).
    let programs = (noisy_fvdm(""), noisy_fvdm("--drop-events 0.3"));
    let vut = serde_json::json!({"external": "rs-fvdm", "mode": "episode"});
    let tests = ten_runs(programs, vut).await;
    eprintln!("the hiding worker's tests at its flag, sorted: {tests:?}");
}
