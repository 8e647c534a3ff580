//! Lease requests that wait for work (`wait_seconds`, long polling), end
//! to end over HTTP: a campaign that starts while a worker waits is leased
//! to it within the wait, as is a lease another worker gives back; the
//! waits end on shutdown, the coordinator's and the worker's; and a wait
//! out of range is refused with a precise problem. Which requests wake the
//! waits is tested on the router (`server/src/routes/tests.rs`), and when
//! a wait asks again, in virtual time (`server/src/work_signal.rs`).

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

fn coordinator(dir: &tempfile::TempDir, extra: &[&str]) -> ServerProcess {
    ServerProcess::start(&dir.path().join("db.sqlite"), extra)
}

/// A coordinator whose waiting requests ask the store again after 30 to
/// 60 s (`--claim-recheck-seconds 60`, the longest; a worker whose last
/// wait found nothing starts there): within a test's 20 s wait, only a
/// wake-up can answer one with work.
fn coordinator_without_rechecks(dir: &tempfile::TempDir, extra: &[&str]) -> ServerProcess {
    let mut args = vec!["--claim-recheck-seconds", "60"];
    args.extend(extra);
    coordinator(dir, &args)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_waiting_request_gets_the_campaign_that_starts_meanwhile() {
    let dir = scratch();
    let server = coordinator_without_rechecks(&dir, &[]);
    let client = server.client();
    // Nothing to do: a request with a short wait answers 204 when it ends.
    assert!(client.claim(&waiting("w1", 0.3)).await.unwrap().is_none());
    // A request that waits 20 s, and a campaign started while it waits:
    // without the wake-up it would end empty at 20 s (its first recheck
    // comes after 30 s at the earliest).
    let waiter = {
        let client = client.clone();
        tokio::spawn(async move { client.claim(&waiting("w1", 20.0)).await })
    };
    until_waiting(&server.url, 1.0).await;
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
    let server = coordinator_without_rechecks(&dir, &["--lease-size", "1000"]);
    let client = server.client();
    let id = client.create_campaign(&ndd(1000)).await.unwrap().id;
    let held = client.claim(&ask("w1", &[])).await.unwrap().expect("lease");
    assert_eq!((held.campaign_id, held.start, held.end), (id, 0, 1000));
    // w2 found nothing in its last wait, so its next one's rechecks start
    // at the 60 s ceiling: only the release's wake-up can answer it.
    assert!(client.claim(&waiting("w2", 0.3)).await.unwrap().is_none());
    let waiter = {
        let client = client.clone();
        tokio::spawn(async move { client.claim(&waiting("w2", 20.0)).await })
    };
    until_waiting(&server.url, 1.0).await;
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
    // All three held; a fixed sleep could send the signal before a
    // loaded host delivered them.
    until_waiting(&server.url, 3.0).await;
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
    // The worker's request is held: the stop comes during its wait.
    until_waiting(&server.url, 1.0).await;
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

/// A coordinator that does not hold lease requests (its cap 0): the worker
/// asking with a wait sees its 204s come at once and polls with backoff
/// instead of asking again at once: a handful of requests in a second and
/// a half, not the hundreds a worker asking again at once would send.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_worker_polls_with_backoff_when_the_coordinator_does_not_hold() {
    let dir = scratch();
    let server = coordinator(&dir, &["--max-claim-wait-seconds", "0"]);
    let config = tslg_worker::WorkerConfig {
        claim_wait_seconds: 10.0,
        ..tslg_worker::WorkerConfig::local(&server.url, 1, "w1")
    };
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let worker = tokio::spawn(tslg_worker::run(config, async move {
        let _ = stopped.await;
    }));
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let _ = stop.send(());
    worker.await.unwrap().unwrap();
    let asked = scraped(
        &server.url,
        r#"tslg_http_request_duration_seconds_count{method="POST",route="/api/v1/leases",status="204"}"#,
    )
    .await;
    // The backoff's pauses are uniform up to 0.05, 0.1, 0.2, 0.4, then
    // 0.5 s: about a dozen requests in 1.5 s, and forty would need 35
    // pauses of 0.25 s on average to fit in 1.5 s.
    assert!((1.0..=40.0).contains(&asked), "{asked} requests");
}

/// The time a request was held for work is the workers' idle time, not
/// the coordinator's latency: `/metrics` counts it apart, so an alert on
/// the lease route's latency is not set off by idle workers.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_time_held_is_counted_apart_from_the_latency() {
    let dir = scratch();
    let server = coordinator(&dir, &[]);
    let client = server.client();
    let started = std::time::Instant::now();
    assert!(client.claim(&waiting("w1", 1.0)).await.unwrap().is_none());
    // A request without a wait is not held.
    assert!(client.claim(&ask("w2", &[])).await.unwrap().is_none());
    let round_trips = started.elapsed().as_secs_f64();
    let url = &server.url;
    let latency = |part: &str| {
        format!(
            "tslg_http_request_duration_seconds_{part}\
             {{method=\"POST\",route=\"/api/v1/leases\",status=\"204\"}}"
        )
    };
    let latency_count = scraped(url, &latency("count")).await;
    let latency = scraped(url, &latency("sum")).await;
    let held_count = scraped(url, "tslg_lease_request_held_seconds_count").await;
    let held = scraped(url, "tslg_lease_request_held_seconds_sum").await;
    assert_eq!((latency_count, held_count), (2.0, 1.0));
    // Together they are the time the coordinator took, at least the wait
    // and at most the round trips; the wait is in the held time only.
    assert!(
        (1.0..=round_trips).contains(&(held + latency)),
        "held {held} s, latency {latency} s, round trips {round_trips} s"
    );
    assert!(latency < held, "held {held} s, latency {latency} s");
}
