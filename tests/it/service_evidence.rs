//! Every test is evidence (issue 67): a worker whose noisy program hides
//! a share of its events is flagged by its tests, paired with the other
//! workers' tests of the same campaign and stratum, early in one library
//! campaign at the default audit share; its honest partners are not
//! (docs/statistics.md, "Every test as evidence").

use crate::service_noise::{noisy_fvdm, worker_views};
use crate::support::*;
use std::time::{Duration, Instant};
use tslg_api::{CampaignStatus, Method};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_worker_whose_noisy_program_hides_events_is_flagged_by_its_tests_within_one_campaign() {
    let dir = scratch();
    // The default audit share (1 %) and leases.
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let start = |name: &str, extra: &str| {
        WorkerProcess::start_with(&server.url, 1, name, &["--vut-exec", &noisy_fvdm(extra)])
    };
    let runs = 10;
    let mut flagged_at = Vec::new();
    for run in 0..runs {
        // Three honest workers of the noisy FVDM (σ 1.5 m/s²) and one whose
        // program reports no event in 30 % of the tests that had one (the
        // issue's noisy liar), new names each run.
        let _fair: Vec<WorkerProcess> = (1..=3)
            .map(|k| start(&format!("fair-{run}-{k}"), ""))
            .collect();
        let hider = format!("hider-{run}");
        let _hider = start(&hider, "--drop-events 0.3");
        // A library campaign at β 0.05 as a user starts it: the guard on
        // by default (the program says it is noisy), seed `run`.
        let request = tslg_api::CreateCampaign {
            vut: serde_json::json!({"external": "rs-fvdm", "mode": "episode"}),
            vehicle_noise: true,
            guard_outside: None,
            ..campaign(Method::Library, library.id, "fvdm", 0.05, run)
        };
        let id = client.create_campaign(&request).await.unwrap().id;
        let started = Instant::now();
        let (caught, view) = loop {
            let view = client.campaign(id).await.unwrap();
            let workers = worker_views(&client).await;
            let this_run = |w: &&tslg_api::WorkerView| {
                w.name.ends_with(&format!("-{run}")) || w.name.contains(&format!("-{run}-"))
            };
            if let Some(caught) = workers
                .iter()
                .filter(this_run)
                .find(|w| w.flagged.is_some())
            {
                break (caught.clone(), view);
            }
            assert!(
                !view.status.is_final(),
                "run {run}: campaign {id} ended ({:?}, {} tests) with nobody flagged: {workers:?}",
                view.status,
                view.tests
            );
            assert!(
                started.elapsed() < Duration::from_secs(120),
                "run {run}: nobody flagged after 120 s ({} tests): {workers:?}",
                view.tests
            );
            tokio::time::sleep(Duration::from_millis(100)).await;
        };
        assert_eq!(caught.name, hider, "run {run}: {caught:?}");
        let detail = caught.flagged.clone().unwrap();
        assert!(
            detail.contains("paired with tests of 3 other workers"),
            "{detail}"
        );
        // Its test lacked the event in nearly every pair that differed.
        assert!(
            caught.test_own_events * 4 < caught.test_partner_events,
            "{caught:?}"
        );
        // The campaign runs again without the hider's results: its tests
        // before the flag are the hider's and the others' it was paired with.
        eprintln!(
            "run {run}: `{hider}` flagged after {} of its tests, campaign at {} ({} pairs, {} \
             differed: {} its events, {} its partners'; {} compared audits)",
            caught.tests,
            view.tests,
            caught.test_pairs_compared,
            caught.test_own_events + caught.test_partner_events,
            caught.test_own_events,
            caught.test_partner_events,
            caught.noisy_audits_compared
        );
        flagged_at.push(caught.tests);
        for worker in worker_views(&client).await {
            if worker.name != hider && !worker.name.starts_with("hider-") {
                assert!(worker.flagged.is_none(), "run {run}: {worker:?}");
                assert!(worker.test_evidence.unwrap_or(1.0) < 1e4, "{worker:?}");
            }
        }
        client.cancel_campaign(id).await.unwrap();
        let stopped = finished(&client, id, Duration::from_secs(30)).await;
        assert_eq!(stopped.status, CampaignStatus::Cancelled);
    }
    flagged_at.sort_unstable();
    eprintln!("the hider's tests at its flag, sorted: {flagged_at:?}");
}
