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
                assert!(next.start >= lease.end, "each range is new: {next:?}");
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
    // Leases of 200,000 tests: a worker runs each in two chunks or more (its
    // first chunk is small), and the report of the last but one asks for
    // the next lease.
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

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_report_sent_again_brings_the_same_lease_and_a_refused_one_takes_none() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &["--lease-size", "100"]);
    let client = server.client();
    let id = client.create_campaign(&ndd_to(10_000)).await.unwrap().id;

    // The answer of a report that took a lease is lost; the worker sends
    // the report again and gets the same lease, not a second one that
    // nobody would hold.
    let first = client.claim(&ask("w1", &[])).await.unwrap().unwrap();
    let report = tslg_api::ResultReport {
        next_lease: Some(ask("w1", &[])),
        ..whole(&first, "w1", real_events(&client, id, 0, 100).await)
    };
    let taken = client.report(first.id, &report).await.unwrap();
    let next = taken.next_lease.expect("work left");
    assert_eq!((next.start, next.end), (100, 200));
    let again = client.report(first.id, &report).await.unwrap();
    assert_eq!((again.accepted, again.duplicate), (0, 100));
    assert_eq!(again.next_lease.as_ref(), Some(&next));
    assert_eq!(client.campaign(id).await.unwrap().leased, 200);
    // Sent again asking for fewer tests than the unstarted lease holds: a
    // new lease within what it asks, not the unstarted one (which expires
    // unused). The lease a report sent again may take is limited as a new
    // claim is, by the tests asked for and by the cap on listed tests.
    let smaller = tslg_api::ResultReport {
        next_lease: Some(tslg_api::LeaseRequest {
            max_tests: Some(40),
            ..ask("w1", &[])
        }),
        ..report.clone()
    };
    let cut = client.report(first.id, &smaller).await.unwrap();
    let cut = cut.next_lease.expect("work left");
    assert_eq!((cut.start, cut.end), (200, 240), "{cut:?}");
    // That one fits a request for its tests listed: handed out again,
    // listed (one that does not fit the cap on listed tests is the next
    // test's).
    let listed = tslg_api::ResultReport {
        next_lease: Some(tslg_api::LeaseRequest {
            include_tests: true,
            ..ask("w1", &[])
        }),
        ..report.clone()
    };
    let listed = client.report(first.id, &listed).await.unwrap();
    let listed = listed.next_lease.expect("work left");
    assert_eq!(listed.id, cut.id);
    assert_eq!(listed.tests.as_ref().map(Vec::len), Some(40), "{listed:?}");
    let part = tslg_api::ResultReport {
        to: 220,
        ..whole(&cut, "w1", real_events(&client, id, 200, 220).await)
    };
    client.report(cut.id, &part).await.unwrap();
    // Once it has started, a repeated report on the first lease takes a
    // new range.
    let part = tslg_api::ResultReport {
        to: 150,
        ..whole(&next, "w1", real_events(&client, id, 100, 150).await)
    };
    client.report(next.id, &part).await.unwrap();
    let third = client.report(first.id, &report).await.unwrap();
    let third = third.next_lease.expect("work left");
    assert_eq!((third.start, third.end), (240, 340));

    // A report the coordinator's own run contradicts is refused, its worker
    // flagged, and the next lease it asked for is not taken.
    let liar = client.claim(&ask("liar", &[])).await.unwrap().unwrap();
    let honest = real_events(&client, id, liar.start, liar.end).await;
    let quiet = (liar.start..liar.end)
        .find(|i| honest.iter().all(|e| e.index != *i))
        .unwrap();
    let mut forged = honest.clone();
    forged.push(tslg_api::EventResult {
        index: quiet,
        weight: 1.0,
    });
    forged.sort_by_key(|e| e.index);
    let leased = client.campaign(id).await.unwrap().leased;
    let lie = tslg_api::ResultReport {
        next_lease: Some(ask("liar", &[])),
        ..whole(&liar, "liar", forged)
    };
    match client.report(liar.id, &lie).await {
        Err(CallError::Refused { status, detail }) => {
            assert_eq!(status, 422, "{detail}");
            assert!(detail.contains("flagged"), "{detail}");
        }
        other => panic!("a forged report must be refused: {other:?}"),
    }
    assert_eq!(client.campaign(id).await.unwrap().leased, leased);
    // Its every lease request is refused now, giving a lease back as well
    // (403, saying why; docs/api.md); its leases expired when it was
    // flagged (a release answered 204 once).
    let release = tslg_api::LeaseRelease {
        worker: "liar".into(),
        attempt: liar.attempt,
        key: liar.key.clone(),
        reason: Some("shutting down".into()),
    };
    match client.release(liar.id, &release).await {
        Err(CallError::Refused { status, detail }) => {
            assert_eq!(status, 403, "{detail}");
            assert!(detail.contains("is flagged"), "{detail}");
        }
        other => panic!("a flagged worker's release must be refused: {other:?}"),
    }
}

/// A report sent again asking for its next lease's tests listed does not
/// take the unstarted lease of the first sending when that one is larger
/// than a listed lease may be (10,000 tests): it takes a new one, within
/// the cap.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_report_sent_again_for_listed_tests_takes_a_lease_within_their_cap() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &["--lease-size", "20000"]);
    let client = server.client();
    let id = client.create_campaign(&ndd_to(100_000)).await.unwrap().id;
    let first = client.claim(&ask("w1", &[])).await.unwrap().unwrap();
    assert_eq!((first.start, first.end), (0, 20_000));
    let report = tslg_api::ResultReport {
        next_lease: Some(ask("w1", &[])),
        ..whole(&first, "w1", real_events(&client, id, 0, 20_000).await)
    };
    let taken = client.report(first.id, &report).await.unwrap();
    let next = taken.next_lease.expect("work left");
    assert_eq!((next.start, next.end), (20_000, 40_000));
    let listed = tslg_api::ResultReport {
        next_lease: Some(tslg_api::LeaseRequest {
            include_tests: true,
            ..ask("w1", &[])
        }),
        ..report.clone()
    };
    let again = client.report(first.id, &listed).await.unwrap();
    assert_eq!((again.accepted, again.duplicate), (0, 20_000));
    let listed = again.next_lease.expect("work left");
    assert_ne!(listed.id, next.id, "the unstarted lease of 20,000 tests");
    assert_eq!((listed.start, listed.end), (40_000, 50_000));
    assert_eq!(listed.tests.as_ref().map(Vec::len), Some(10_000));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn work_is_charged_whether_or_not_the_report_moves_the_prefix() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &["--lease-size", "100"]);
    let client = server.client();
    let id = client.create_campaign(&ndd_to(10_000)).await.unwrap().id;
    let a = client.claim(&ask("w1", &[])).await.unwrap().unwrap();
    let b = client.claim(&ask("w2", &[])).await.unwrap().unwrap();
    let charged = |lease: &tslg_api::Lease, worker: &str, seconds: f64| {
        let (client, lease, worker) = (client.clone(), lease.clone(), worker.to_owned());
        async move {
            let events = real_events(&client, id, lease.start, lease.end).await;
            let report = tslg_api::ResultReport {
                compute_seconds: seconds,
                ..whole(&lease, &worker, events)
            };
            client.report(lease.id, &report).await.unwrap();
            client.campaign(id).await.unwrap()
        }
    };
    // The second range first: the prefix cannot move, the work counts.
    let view = charged(&b, "w2", 0.5).await;
    assert_eq!((view.indices, view.worker_seconds), (0, 0.5));
    // The first range: the prefix moves over both, the work adds up.
    let view = charged(&a, "w1", 0.25).await;
    assert_eq!((view.indices, view.worker_seconds), (200, 0.75));
}

/// An audit's one-test run goes only to a request that may run audits
/// (one that offers programs and takes its tests unlisted): a report sent
/// again whose next lease asks for listed tests does not take the audit
/// run its first sending took.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_report_sent_again_for_listed_tests_leaves_the_audit_run_it_took() {
    let dir = scratch();
    let server = ServerProcess::start(
        &dir.path().join("db.sqlite"),
        &["--lease-size", "5", "--audit-share", "1"],
    );
    let client = server.client();
    let request = CreateCampaign {
        vut: serde_json::json!({"external": "py-idm"}),
        ..ndd_to(1_000)
    };
    client.create_campaign(&request).await.unwrap();
    let offer = "py-idm:cut-in:step";
    let first = client.claim(&ask("w1", &[offer])).await.unwrap().unwrap();
    let second = client.claim(&ask("w2", &[offer])).await.unwrap().unwrap();
    assert_eq!((first.start, second.start), (0, 5));
    // Every test w1 reports is to be run again by another worker.
    client
        .report(first.id, &whole(&first, "w1", Vec::new()))
        .await
        .unwrap();
    let report = tslg_api::ResultReport {
        next_lease: Some(ask("w2", &[offer])),
        ..whole(&second, "w2", Vec::new())
    };
    let audit = client
        .report(second.id, &report)
        .await
        .unwrap()
        .next_lease
        .expect("an audit's run");
    assert_eq!(audit.end - audit.start, 1, "{audit:?}");
    assert!(audit.start < 5, "one of w1's tests: {audit:?}");
    let listed = tslg_api::ResultReport {
        next_lease: Some(tslg_api::LeaseRequest {
            include_tests: true,
            ..ask("w2", &[offer])
        }),
        ..report.clone()
    };
    let again = client.report(second.id, &listed).await.unwrap();
    assert_eq!((again.accepted, again.duplicate), (0, 5));
    let lease = again.next_lease.expect("work left");
    assert_ne!(lease.id, audit.id, "the audit's run went to listed tests");
    assert_eq!((lease.start, lease.end), (10, 15), "a new range");
    assert_eq!(lease.tests.as_ref().map(Vec::len), Some(5));
}
