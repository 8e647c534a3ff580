//! Lease requests that wait for work (`wait_seconds`, long polling): a
//! campaign that starts while a worker waits is leased to it at once, as
//! is a lease another worker gives back; the waits end on shutdown; and a
//! wait out of range is refused with a precise problem.
//!
//! The coordinators here recheck only every 30 s (`--claim-recheck-seconds`),
//! longer than any wait the tests ask for, so a waiting request that gets a
//! lease was woken by the start it waited for, not by a recheck.

use crate::support::*;
use std::time::Duration;
use tslg_api::{CreateCampaign, LeaseFence, LeaseRequest, Method};
use tslg_client::CallError;

/// A request of worker `name` that waits up to `wait` seconds.
fn waiting(name: &str, wait: f64) -> LeaseRequest {
    LeaseRequest {
        wait_seconds: Some(wait),
        ..ask(name, &[])
    }
}

/// An NDD campaign of the IDM on cut-in with `max_tests` tests.
fn ndd(max_tests: u64) -> CreateCampaign {
    CreateCampaign {
        method: Method::Ndd,
        library_id: None,
        max_tests,
        ..campaign(Method::Ndd, 0, "idm", 0.01, 1)
    }
}

fn announce_only(dir: &tempfile::TempDir, extra: &[&str]) -> ServerProcess {
    let mut args = vec!["--claim-recheck-seconds", "30"];
    args.extend_from_slice(extra);
    ServerProcess::start(&dir.path().join("db.sqlite"), &args)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_waiting_request_gets_the_campaign_that_starts_meanwhile() {
    let dir = scratch();
    let server = announce_only(&dir, &[]);
    let client = server.client();
    // Nothing to do: a request with a short wait answers 204 when it ends.
    assert!(client.claim(&waiting("w1", 0.3)).await.unwrap().is_none());
    // A request that waits 20 s, and a campaign started while it waits.
    let waiter = {
        let client = client.clone();
        tokio::spawn(async move { client.claim(&waiting("w1", 20.0)).await })
    };
    tokio::time::sleep(Duration::from_millis(300)).await;
    let id = client.create_campaign(&ndd(1_000_000)).await.unwrap().id;
    let lease = waiter
        .await
        .unwrap()
        .unwrap()
        .expect("the campaign's first lease, before the wait's end");
    assert_eq!((lease.campaign_id, lease.start), (id, 0));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_waiting_request_gets_the_lease_another_worker_gives_back() {
    let dir = scratch();
    // One lease holds the whole campaign.
    let server = announce_only(&dir, &["--lease-size", "1000"]);
    let client = server.client();
    let id = client.create_campaign(&ndd(1000)).await.unwrap().id;
    let held = client.claim(&ask("w1", &[])).await.unwrap().expect("lease");
    assert_eq!((held.campaign_id, held.start, held.end), (id, 0, 1000));
    let waiter = {
        let client = client.clone();
        tokio::spawn(async move { client.claim(&waiting("w2", 20.0)).await })
    };
    tokio::time::sleep(Duration::from_millis(300)).await;
    let fence = LeaseFence {
        worker: "w1".into(),
        attempt: held.attempt,
        key: held.key.clone(),
    };
    client
        .release(held.id, &fence.release(Some("shutting down".into())))
        .await
        .unwrap();
    let again = waiter
        .await
        .unwrap()
        .unwrap()
        .expect("the released range, before the wait's end");
    assert_eq!(
        (again.campaign_id, again.start, again.end),
        (id, 0, 1000),
        "{again:?}"
    );
}

/// SIGTERM to the coordinator answers the waiting requests (204) and the
/// coordinator exits cleanly, without waiting out their 30 s.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shutdown_ends_the_waits() {
    let dir = scratch();
    let server = ServerProcess::start(
        &dir.path().join("db.sqlite"),
        &["--max-claim-wait-seconds", "30"],
    );
    let client = server.client();
    let waiters: Vec<_> = (0..3)
        .map(|k| {
            let client = client.clone();
            tokio::spawn(async move { client.claim(&waiting(&format!("w{k}"), 30.0)).await })
        })
        .collect();
    tokio::time::sleep(Duration::from_millis(500)).await;
    let exited = tokio::task::spawn_blocking(move || server.terminate());
    for waiter in waiters {
        // A hang guard, not a speed limit: the waits are 30 s.
        let answered = tokio::time::timeout(Duration::from_secs(20), waiter)
            .await
            .expect("the wait ended with the shutdown")
            .unwrap();
        assert!(matches!(answered, Ok(None)), "{answered:?}");
    }
    let exited = exited.await.unwrap();
    assert!(exited.success(), "{exited:?}");
}

/// A worker asking with a wait stops at once on shutdown (its request is
/// dropped, not waited out).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_waiting_worker_stops_at_once() {
    let dir = scratch();
    let server = ServerProcess::start(
        &dir.path().join("db.sqlite"),
        &["--max-claim-wait-seconds", "30"],
    );
    let config = tslg_worker::WorkerConfig {
        claim_wait_seconds: 30.0,
        ..tslg_worker::WorkerConfig::local(&server.url, 1, "w1")
    };
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let worker = tokio::spawn(tslg_worker::run(config, async move {
        let _ = stopped.await;
    }));
    tokio::time::sleep(Duration::from_millis(500)).await;
    let _ = stop.send(());
    let summary = tokio::time::timeout(Duration::from_secs(20), worker)
        .await
        .expect("the worker stopped without waiting out its 30 s")
        .unwrap()
        .unwrap();
    assert_eq!(summary.leases, 0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn waits_out_of_range_are_refused() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    let refused = |r: Result<Option<tslg_api::Lease>, CallError>| match r {
        Err(CallError::Refused { status, detail }) => (status, detail),
        other => panic!("not refused: {other:?}"),
    };
    for (wait, detail) in [
        (-1.0, "wait_seconds = -1 must be in [0, 30]"),
        (30.5, "wait_seconds = 30.5 must be in [0, 30]"),
    ] {
        let (status, got) = refused(client.claim(&waiting("w1", wait)).await);
        assert_eq!(status, 422);
        assert!(got.contains(detail), "{got}");
    }
    // A report's next lease is answered with the report: no wait there.
    let id = client.create_campaign(&ndd(1000)).await.unwrap().id;
    let lease = claim(&client, "w1").await.expect("lease");
    assert_eq!(lease.campaign_id, id);
    let events = real_events(&client, id, lease.start, lease.end).await;
    let report = tslg_api::ResultReport {
        next_lease: Some(waiting("w1", 5.0)),
        ..whole(&lease, "w1", events)
    };
    let (status, got) = match client.report(lease.id, &report).await {
        Err(CallError::Refused { status, detail }) => (status, detail),
        other => panic!("not refused: {other:?}"),
    };
    assert_eq!(status, 422);
    assert!(got.contains("next_lease.wait_seconds"), "{got}");
    // Nothing was recorded; the report without it stands.
    let plain = tslg_api::ResultReport {
        next_lease: None,
        ..report
    };
    let ack = client.report(lease.id, &plain).await.unwrap();
    assert_eq!(ack.accepted, lease.end - lease.start);
}
