//! A report that asks for the worker's next lease (`next_lease`): the
//! lease comes with the acknowledgement, a bad request for one refuses the
//! report and records nothing, and the real worker takes its leases this
//! way (one request per lease fewer).

use crate::support::*;
use std::time::Duration;
use tslg_api::{CampaignStatus, CreateCampaign, Method};
use tslg_client::CallError;

/// A cut-in NDD campaign of the IDM that runs to `max_tests` (β too small
/// to stop it first).
fn ndd_to(max_tests: u64) -> CreateCampaign {
    CreateCampaign {
        library_id: None,
        max_tests,
        ..campaign(Method::Ndd, 0, "idm", tslg_method::estimator::MIN_BETA, 7)
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_report_brings_the_next_lease_and_a_bad_request_for_one_records_nothing() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &["--lease-size", "100"]);
    let client = server.client();
    let id = client.create_campaign(&ndd_to(250)).await.unwrap().id;
    let first = client.claim(&ask("w1", &[])).await.unwrap().unwrap();
    assert_eq!((first.start, first.end), (0, 100));
    let honest = |lease: &tslg_api::Lease| {
        let (client, lease) = (client.clone(), lease.clone());
        async move { real_events(&client, id, lease.resume_at, lease.end).await }
    };

    // Refused before anything is recorded: a next lease for another worker,
    // and one that asks for no threads.
    let events = honest(&first).await;
    for (next, wanted) in [
        (
            ask("w2", &[]),
            "next_lease.worker `w2` is not the reporting worker `w1`",
        ),
        (
            tslg_api::LeaseRequest {
                threads: 0,
                ..ask("w1", &[])
            },
            "next_lease: threads = 0 must be in 1..=",
        ),
    ] {
        let report = tslg_api::ResultReport {
            next_lease: Some(next),
            ..whole(&first, "w1", events.clone())
        };
        match client.report(first.id, &report).await {
            Err(CallError::Refused { status, detail }) => {
                assert_eq!(status, 422, "{detail}");
                assert!(detail.contains(wanted), "{detail}");
            }
            other => panic!("a bad next lease must be refused: {other:?}"),
        }
        assert_eq!(client.campaign(id).await.unwrap().indices, 0);
    }

    // Each report takes the next range; the last finds no work left.
    let mut lease = first;
    let mut ranges = vec![(lease.start, lease.end)];
    let mut reported = 0;
    loop {
        let events = honest(&lease).await;
        reported += events.len() as u64;
        let report = tslg_api::ResultReport {
            next_lease: Some(ask("w1", &[])),
            ..whole(&lease, "w1", events)
        };
        let ack = client.report(lease.id, &report).await.unwrap();
        assert_eq!(ack.accepted, lease.end - lease.start);
        match ack.next_lease {
            Some(next) => {
                assert_eq!(next.campaign_id, id);
                assert_eq!(next.resume_at, next.start);
                ranges.push((next.start, next.end));
                lease = next;
            }
            None => break,
        }
    }
    assert_eq!(ranges, [(0, 100), (100, 200), (200, 250)]);
    let view = client.campaign(id).await.unwrap();
    assert_eq!(view.status, CampaignStatus::Exhausted);
    assert_eq!((view.indices, view.events), (250, reported));

    // A repeated report counts once and, with no work left, brings none.
    let again = tslg_api::ResultReport {
        next_lease: Some(ask("w1", &[])),
        ..whole(&lease, "w1", honest(&lease).await)
    };
    let ack = client.report(lease.id, &again).await.unwrap();
    assert_eq!((ack.accepted, ack.next_lease), (0, None));
    assert_eq!(client.campaign(id).await.unwrap().indices, 250);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_worker_takes_its_next_lease_with_a_report() {
    let dir = scratch();
    // Leases of 200,000 tests: a worker runs each in two chunks (its first
    // chunk is small), and the first chunk's report asks for the next lease.
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &["--lease-size", "200000"]);
    let client = server.client();
    let id = client.create_campaign(&ndd_to(1_000_000)).await.unwrap().id;
    let worker = WorkerProcess::start(&server.url, 1, "w1");
    let view = finished(&client, id, Duration::from_secs(120)).await;
    worker.kill();
    assert_eq!(view.status, CampaignStatus::Exhausted);
    assert_eq!(view.indices, 1_000_000);
    // Five leases; only the first was asked for on its own (without the
    // reports' requests, all five would be).
    let claims = scraped(
        &server.url,
        "tslg_http_request_duration_seconds_count{method=\"POST\",route=\"/api/v1/leases\",status=\"200\"}",
    )
    .await;
    assert_eq!(
        claims, 1.0,
        "leases taken with a request of their own, of 5"
    );
}
