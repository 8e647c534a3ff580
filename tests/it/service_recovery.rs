//! Persistence and shutdown: a coordinator killed mid-campaign and
//! restarted on its database continues to the same answer, with the
//! workers reconnecting by themselves; every result it acknowledged before
//! the kill is on disk; a worker killed mid-lease costs only time (its lease
//! expires and is handed out again) and not the answer; a worker told to
//! stop finishes its chunk and gives its lease back.

use crate::support::*;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tslg_api::{CampaignStatus, Lease, Method, ResultReport};
use tslg_client::Client;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_coordinator_killed_mid_campaign_continues_from_its_database_to_the_same_answer() {
    let dir = scratch();
    let database = dir.path().join("db.sqlite");
    let server = ServerProcess::start(&database, &["--lease-size", "50000"]);
    let address = server.address.clone();
    let _worker = WorkerProcess::start(&server.url, 1, "w1");
    let client = server.client();
    let library = ready_library(&client, "idm", false).await;
    let request = disturbed_ndd(library.id);
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
    // The worker is left alone: it retries until the coordinator is back.
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
    let workers = client.workers().await.unwrap().workers;
    assert!(
        workers.iter().any(|w| w.name == "w1" && w.tests > 0),
        "the same worker reconnected and reported to the new coordinator: {workers:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_worker_killed_mid_lease_changes_neither_the_stop_index_nor_the_estimate() {
    let dir = scratch();
    let options = ["--lease-size", "40000", "--lease-ttl-seconds", "1"];
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &options);
    let client = server.client();
    let library = ready_library(&client, "idm", false).await;
    let request = disturbed_ndd(library.id);
    let id = client.create_campaign(&request).await.unwrap().id;
    let doomed = WorkerProcess::start(&server.url, 1, "doomed");
    let view = wait_for(&client, id, Duration::from_secs(120), |v| {
        v.indices >= 60_000
    })
    .await;
    assert_eq!(view.status, CampaignStatus::Running, "killed too late");
    // SIGKILL in the middle of its second (or later) lease: no release.
    doomed.kill();
    let _rescuer = WorkerProcess::start(&server.url, 1, "rescuer");
    let view = finished(&client, id, Duration::from_secs(300)).await;
    assert_eq!(view.status, CampaignStatus::Converged);
    assert_same(&view, &in_process(None, &request));
    let reclaimed = scraped(&server.url, "tslg_leases_reclaimed_total").await;
    assert!(
        reclaimed >= 1.0,
        "the killed worker's lease was handed out again"
    );
}

/// Claims a lease and reports all of it as `worker`, each test run here.
async fn claim_and_report(
    client: &Client,
    tests: &dyn tslg_method::registry::CampaignTests,
    worker: &str,
) -> Option<(Lease, ResultReport)> {
    // Errors (the coordinator is gone) end the simulated worker.
    let lease = client.claim(&ask(worker, &[])).await.ok()??;
    let report = ResultReport {
        compute_seconds: 0.01,
        ..whole(&lease, worker, honest_events(tests, &lease))
    };
    client.report(lease.id, &report).await.ok()?;
    Some((lease, report))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_acknowledged_result_survives_a_coordinator_kill_and_counts_once() {
    let dir = scratch();
    let database = dir.path().join("db.sqlite");
    let server = ServerProcess::start(&database, &["--lease-size", "100"]);
    let address = server.address.clone();
    let client = server.client();
    let library = ready_library(&client, "idm", false).await;
    let mut request = campaign(Method::Ndd, library.id, "idm", 0.001, 4);
    request.max_tests = 1_000_000_000;
    let id = client.create_campaign(&request).await.unwrap().id;
    // Eight simulated workers report as fast as they can; the coordinator
    // is killed while they do, so some requests are cut off mid-flight.
    let acked = Arc::new(Mutex::new(Vec::new()));
    let prepared = tslg_worker::prepared::Cache::default()
        .get(&client, id)
        .await
        .unwrap()
        .tests()
        .unwrap();
    let tasks: Vec<_> = (0..8)
        .map(|w| {
            let (client, acked) = (client.clone(), Arc::clone(&acked));
            let prepared = Arc::clone(&prepared);
            tokio::spawn(async move {
                let name = format!("s{w}");
                while let Some((lease, report)) =
                    claim_and_report(&client, prepared.tests.as_ref(), &name).await
                {
                    acked.lock().unwrap().push((lease, report));
                }
            })
        })
        .collect();
    let deadline = Instant::now() + Duration::from_secs(120);
    while acked.lock().unwrap().len() < 200 {
        assert!(
            Instant::now() < deadline,
            "{} reports acknowledged after two minutes, not 200",
            acked.lock().unwrap().len()
        );
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    server.kill();
    for task in tasks {
        task.await.unwrap();
    }
    let acked = std::mem::take(&mut *acked.lock().unwrap());
    let _server = ServerProcess::start_on(&database, &address, &["--lease-size", "100"]);
    // The same client, with the workers' secrets: credentials are stored.
    let client = client.clone();
    // Each acknowledged report is on disk: sent again, all of it is a
    // duplicate, none of it new.
    for (lease, report) in &acked {
        let ack = client.report(lease.id, report).await.unwrap();
        assert_eq!(
            (ack.accepted, ack.duplicate),
            (0, report.to - report.from),
            "lease {} lost or changed its acknowledged results",
            lease.id
        );
    }
    // The resolved prefix covers at least the acknowledged leases that
    // form a prefix, and no test was counted twice.
    let mut ranges: Vec<_> = acked.iter().map(|(_, r)| (r.from, r.to)).collect();
    ranges.sort();
    let mut prefix = 0;
    for &(from, to) in &ranges {
        if from != prefix {
            break;
        }
        prefix = to;
    }
    let view = client.campaign(id).await.unwrap();
    assert!(view.indices >= prefix, "{} < {prefix}", view.indices);
    assert!(
        prefix >= 100 * 150,
        "most acknowledged leases form the prefix"
    );
    assert_eq!(view.tests, view.indices, "no invalid tests");
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

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_backup_taken_while_running_restores_to_the_same_answer() {
    let dir = scratch();
    let database = dir.path().join("db.sqlite");
    let options = ["--lease-size", "50000", "--lease-ttl-seconds", "2"];
    let MidCampaign {
        server,
        worker,
        request,
        id,
        view: before,
    } = MidCampaign::start(&database, &options).await;
    let backup = dir.path().join("backup.sqlite");
    let tslg = |out: &std::path::Path| {
        std::process::Command::new(env!("CARGO_BIN_EXE_tslg"))
            .args(["backup", "--database-url"])
            .arg(format!("sqlite://{}", database.display()))
            .arg("--out")
            .arg(out)
            .output()
            .unwrap()
    };
    let done = tslg(&backup);
    assert!(done.status.success(), "{done:?}");
    let again = tslg(&backup);
    assert!(clean_refusal(&again));
    assert!(String::from_utf8_lossy(&again.stderr).contains("never overwrites"));
    drop(worker);
    server.kill();

    // A new coordinator on the backup continues the campaign from it.
    let server = ServerProcess::start(&backup, &options);
    let client = server.client();
    let restored = client.campaign(id).await.unwrap();
    assert!(restored.indices >= before.indices, "{restored:?}");
    let _worker = WorkerProcess::start(&server.url, 1, "w2");
    let view = finished(&client, id, Duration::from_secs(300)).await;
    assert_eq!(view.status, CampaignStatus::Converged);
    assert_same(&view, &in_process(None, &request));
}

/// A worker restarted with its `--credential-file` is the same worker:
/// its name (not `NAME.2`), so its results, flags and audit standing stay
/// its own. The file is written at the first start, mode 0600.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_worker_restarted_with_its_credential_file_keeps_its_name() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    let file = dir.path().join("node.credential");
    let args = ["--credential-file", file.to_str().unwrap()];
    let names = || async {
        let mut names: Vec<String> = client
            .workers()
            .await
            .unwrap()
            .workers
            .into_iter()
            .map(|w| w.name)
            .collect();
        names.sort();
        names
    };
    let first = WorkerProcess::start_with(&server.url, 1, "node", &args);
    let deadline = Instant::now() + Duration::from_secs(60);
    while names().await != ["node"] {
        assert!(Instant::now() < deadline, "the worker never came");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert_eq!(first.terminate().code(), Some(0));
    let stored: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
    assert_eq!(stored["name"], "node");
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&file).unwrap().permissions().mode();
        assert_eq!(mode & 0o777, 0o600);
    }
    // Restarted: it works a campaign as "node" (a second registration
    // would have made it "node.2", listed beside the first).
    let mut request = campaign(Method::Ndd, 0, "idm", 0.5, 1);
    request.library_id = None;
    let id = client.create_campaign(&request).await.unwrap().id;
    let _second = WorkerProcess::start_with(&server.url, 1, "node", &args);
    let view = finished(&client, id, Duration::from_secs(120)).await;
    assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
    assert_eq!(names().await, ["node"]);
}
