//! Persistence and shutdown: a coordinator killed mid-campaign and
//! restarted on its database continues to the same answer; a worker told
//! to stop finishes its chunk and gives its lease back.

mod support;

use std::time::{Duration, Instant};
use support::*;
use tslg_api::{CampaignStatus, Method};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_coordinator_killed_mid_campaign_continues_from_its_database_to_the_same_answer() {
    let dir = scratch();
    let database = dir.path().join("db.sqlite");
    let server = ServerProcess::start(&database, &["--lease-size", "50000"]);
    let address = server.address.clone();
    let _worker = WorkerProcess::start(&server.url, 1, "w1");
    let client = server.client();
    let library = ready_library(&client, "idm", false).await;
    let request = campaign(Method::Ndd, library.id, "idm", 0.04, 9);
    let id = client.create_campaign(&request).await.unwrap().id;
    let started = Instant::now();
    let before = loop {
        let view = client.campaign(id).await.unwrap();
        if view.indices >= 200_000 {
            break view;
        }
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "no progress: {view:?}"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    };
    assert_eq!(
        before.status,
        CampaignStatus::Running,
        "killed too late to test anything"
    );
    server.kill();
    let server = ServerProcess::start_on(&database, &address, &["--lease-size", "50000"]);
    let client = server.client();
    let resumed = client.campaign(id).await.unwrap();
    assert!(
        resumed.indices >= before.indices,
        "acknowledged results survive the kill"
    );
    let view = finished(&client, id, Duration::from_secs(300)).await;
    assert_eq!(view.status, CampaignStatus::Converged);
    assert_same(&view, &in_process(None, &request));
    let history = client.history(id).await.unwrap();
    assert!(history.points.iter().any(|p| p.indices <= before.indices));
    assert_eq!(history.points.last().unwrap().indices, view.indices);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_worker_stopped_by_sigterm_gives_its_lease_back() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &["--lease-size", "50000000"]);
    let client = server.client();
    let library = ready_library(&client, "idm", false).await;
    let mut request = campaign(Method::Ndd, library.id, "idm", 0.001, 1);
    request.max_tests = 100_000_000;
    let id = client.create_campaign(&request).await.unwrap().id;
    let worker = WorkerProcess::start(&server.url, 1, "w1");
    let started = Instant::now();
    loop {
        let view = client.campaign(id).await.unwrap();
        if view.indices > 0 {
            break;
        }
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "the worker did no work"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let status = worker.terminate();
    assert!(status.success(), "worker exit status {status}");
    // Released, not left to expire (the TTL is 30 s): it is available at once,
    // from the first index the worker did not report.
    let lease = claim(&client, "w2").await.expect("the released lease");
    assert_eq!((lease.start, lease.attempt), (0, 2));
    let view = client.campaign(id).await.unwrap();
    assert_eq!(
        lease.resume_at, view.indices,
        "everything the worker ran was reported"
    );
    assert!(lease.resume_at > 0);
}
