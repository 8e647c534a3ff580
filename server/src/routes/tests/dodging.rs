//! Audits that cannot be dodged (issue 47, `report/dodging.rs`), driven
//! step by step: a worker that gives back an audit run owes an audit of
//! its own results and gets no new range until it is decided; past three
//! runs given back in a row, every test it reports is audited.

use super::*;

fn span(lease: &Value) -> u64 {
    lease["end"].as_u64().unwrap() - lease["start"].as_u64().unwrap()
}

async fn report(app: &App, worker: &str, lease: &Value, events: Value) -> Value {
    let mut report = quiet_report(worker, lease);
    report["events"] = events;
    accepted(app, lease, report).await
}

async fn give_back(app: &App, worker: &str, lease: &Value) {
    let fence = json!({"worker": worker, "attempt": lease["attempt"], "key": lease["key"]});
    let (status, problem) = app
        .call(
            "POST",
            &format!("/api/v1/leases/{}/release", lease["id"]),
            Some(fence),
        )
        .await;
    assert_eq!(status, StatusCode::NO_CONTENT, "{problem}");
}

async fn standing(app: &App, worker: &str) -> (u64, u64) {
    let (_, list) = app.call("GET", "/api/v1/workers", None).await;
    let w = list["workers"]
        .as_array()
        .unwrap()
        .iter()
        .find(|w| w["name"] == worker)
        .cloned()
        .unwrap();
    (
        w["audits_given_back"].as_u64().unwrap(),
        w["audits_given_back_in_row"].as_u64().unwrap(),
    )
}

/// "b" then "c" run every open audit they may (reporting `events` as
/// events, the rest quietly) until each is handed a range: "b" reports
/// its range quietly, "c" with one heavy event (audited: it would carry a
/// large share of the estimate), whose index is returned.
async fn run_audits_then_report_an_event(app: &App, events: &[u64]) -> u64 {
    for worker in ["b", "c"] {
        for turn in 0.. {
            assert!(turn < 1000, "{worker} was never handed a range");
            let (status, lease) = app.claim(worker, 40).await;
            assert_eq!(status, StatusCode::OK, "{lease}");
            let from = lease["start"].as_u64().unwrap();
            if span(&lease) == 1 {
                let outcome = match events.contains(&from) {
                    true => json!([{"index": from, "weight": 1.0}]),
                    false => json!([]),
                };
                report(app, worker, &lease, outcome).await;
                continue;
            }
            if worker == "c" {
                report(
                    app,
                    worker,
                    &lease,
                    json!([{"index": from + 7, "weight": 1.0}]),
                )
                .await;
                return from + 7;
            }
            report(app, worker, &lease, json!([])).await;
            break;
        }
    }
    unreachable!("c returns")
}

async fn open_audits(app: &App, id: i64) -> u64 {
    let (_, view) = app
        .call("GET", &format!("/api/v1/campaigns/{id}"), None)
        .await;
    view["audits"]["open"].as_u64().unwrap()
}

/// A campaign of the program `x` with leases of 40 tests and no sampled
/// audits (only those of heavy events and of runs given back), whose first
/// range "d" holds unreported: the prefix stays at 0, and every later
/// result is unresolved.
async fn held_campaign() -> (App, i64) {
    let app = app(|c| {
        c.audit_share = 0.0;
        c.lease_size = Some(40);
    })
    .await;
    let id = app.external_campaign().await;
    let (status, held) = app.claim("d", 40).await;
    assert_eq!((status, span(&held)), (StatusCode::OK, 40), "{held}");
    (app, id)
}

#[tokio::test]
async fn a_worker_giving_back_audits_owes_one_and_past_three_has_all_its_tests_audited() {
    let (app, id) = held_campaign().await;
    let (_, b_range) = app.claim("b", 40).await;
    let (_, a_range) = app.claim("a", 40).await;
    // "b" reports an event, which as the campaign's first is audited (it
    // would carry the estimate); "a" reports its range quietly.
    let b_event = b_range["start"].as_u64().unwrap() + 3;
    report(
        &app,
        "b",
        &b_range,
        json!([{"index": b_event, "weight": 1.0}]),
    )
    .await;
    report(&app, "a", &a_range, json!([])).await;
    assert_eq!(open_audits(&app, id).await, 1);
    let mut events = vec![b_event];

    for round in 1..=4u64 {
        // "a" is handed the open audit and gives it back: counted at once,
        // and one of its own unresolved tests is audited (all of them past
        // three in a row).
        let (_, audit) = app.claim("a", 40).await;
        let last = *events.last().unwrap();
        assert_eq!(
            (span(&audit), audit["start"].as_u64()),
            (1, Some(last)),
            "{audit}"
        );
        give_back(&app, "a", &audit).await;
        assert_eq!(standing(&app, "a").await, (round, round));
        // Owing, "a" is handed no range, also when its lease would list
        // its tests (such a claim takes no audit runs either).
        let inline = json!({"worker": "a", "threads": 1, "offers": ["x:cut-in:step"],
                            "include_tests": true, "max_tests": 40});
        let (status, nothing) = app.call("POST", "/api/v1/leases", Some(inline)).await;
        assert_eq!(status, StatusCode::NO_CONTENT, "round {round}: {nothing}");
        let open = open_audits(&app, id).await;
        if round < 4 {
            // The audit given back, and one test of a's.
            assert_eq!(open, 2, "round {round}");
        } else {
            // The audit given back, and a's 40 tests, less those audited
            // (and agreed) in rounds 1 to 3.
            assert!((37..=41).contains(&open), "{open} open");
        }
        // "b" and "c" run the open audits; "c" reports a range with a heavy
        // event: the next audit for "a".
        events.push(run_audits_then_report_an_event(&app, &events).await);
    }
    // Running an audit ends the streak.
    let (_, audit) = app.claim("a", 40).await;
    let last = *events.last().unwrap();
    assert_eq!(audit["start"].as_u64(), Some(last), "{audit}");
    report(&app, "a", &audit, json!([{"index": last, "weight": 1.0}])).await;
    assert_eq!(standing(&app, "a").await, (4, 0));
    // And the share is the base again (0 here): a new range of a's is not
    // audited.
    let (_, range) = app.claim("a", 40).await;
    assert_eq!(span(&range), 40, "{range}");
    report(&app, "a", &range, json!([])).await;
    assert_eq!(open_audits(&app, id).await, 0);
}

/// Two workers alone with a program, each giving back one audit run of
/// the other's: each owes an audit only the other may run. Owing blocks
/// ranges, not audit runs, so each runs the other's and both work again
/// (they blocked each other for good when owing blocked everything).
#[tokio::test]
async fn two_workers_owing_each_other_settle_by_running_the_audits() {
    let (app, id) = held_campaign().await;
    let (_, a_range) = app.claim("a", 40).await;
    let (_, b_range) = app.claim("b", 40).await;
    let a_event = a_range["start"].as_u64().unwrap() + 1;
    report(
        &app,
        "a",
        &a_range,
        json!([{"index": a_event, "weight": 1.0}]),
    )
    .await;
    let b_event = b_range["start"].as_u64().unwrap() + 2;
    report(
        &app,
        "b",
        &b_range,
        json!([{"index": b_event, "weight": 1.0}]),
    )
    .await;
    // Each is handed the other's event and gives it back.
    let (_, for_b) = app.claim("b", 40).await;
    let (_, for_a) = app.claim("a", 40).await;
    assert_eq!(
        (for_a["start"].as_u64(), for_b["start"].as_u64()),
        (Some(b_event), Some(a_event))
    );
    give_back(&app, "a", &for_a).await;
    give_back(&app, "b", &for_b).await;
    assert_eq!(
        (standing(&app, "a").await, standing(&app, "b").await),
        ((1, 1), (1, 1))
    );
    // Each runs what is open for it (the other's event and the other's
    // owed test) and agrees, until it is handed a range again.
    for worker in ["a", "b", "a", "b"] {
        let (status, lease) = app.claim(worker, 40).await;
        assert_eq!(status, StatusCode::OK, "{worker}: {lease}");
        if span(&lease) == 40 {
            continue;
        }
        let index = lease["start"].as_u64().unwrap();
        let events = match [a_event, b_event].contains(&index) {
            true => json!([{"index": index, "weight": 1.0}]),
            false => json!([]),
        };
        report(&app, worker, &lease, events).await;
    }
    assert_eq!(open_audits(&app, id).await, 0);
    let (_, range) = app.claim("a", 40).await;
    assert_eq!(span(&range), 40, "{range}");
    let (_, range) = app.claim("b", 40).await;
    assert_eq!(span(&range), 40, "{range}");
}

/// A worker's heartbeat keeps its audit runs alive with its range: a slow
/// program's worker that took an audit with a report runs it after the
/// chunk under way, and must not be counted as letting it expire. One
/// that stops heartbeating lets it expire, and is counted when the run is
/// handed out again.
#[tokio::test]
async fn heartbeats_keep_a_workers_audit_runs_and_an_expired_run_counts() {
    let app = app(|c| {
        c.audit_share = 0.0;
        c.lease_size = Some(40);
        // Heartbeats every 0.5 s keep it with 1.5 s to spare on a
        // stalled host.
        c.lease_ttl_seconds = 2.0;
    })
    .await;
    app.external_campaign().await;
    let (_, b_range) = app.claim("b", 40).await;
    let (_, a_range) = app.claim("a", 40).await;
    let b_event = b_range["start"].as_u64().unwrap() + 3;
    report(
        &app,
        "b",
        &b_range,
        json!([{"index": b_event, "weight": 1.0}]),
    )
    .await;
    let (_, audit) = app.claim("a", 40).await;
    assert_eq!(audit["start"].as_u64(), Some(b_event), "{audit}");
    let path = format!("/api/v1/leases/{}/heartbeat", a_range["id"]);
    let fence = json!({"worker": "a", "attempt": a_range["attempt"], "key": a_range["key"]});
    let heartbeat = || app.call("POST", &path, Some(fence.clone()));
    // Past the TTL, kept by heartbeats of the range: "c" gets no audit run.
    for _ in 0..6 {
        tokio::time::sleep(std::time::Duration::from_millis(500)).await;
        let (status, ack) = heartbeat().await;
        assert_eq!(status, StatusCode::OK, "{ack}");
    }
    let (_, for_c) = app.claim("c", 40).await;
    assert_eq!(span(&for_c), 40, "the audit run is a's: {for_c}");
    assert_eq!(standing(&app, "a").await, (0, 0));
    // Without heartbeats it expires; handed to "c", it counts against "a".
    // (a's range and c's expired too, and are handed out first.)
    tokio::time::sleep(std::time::Duration::from_millis(2400)).await;
    let mut taken = Vec::new();
    for _ in 0..3 {
        let (_, lease) = app.claim("c", 40).await;
        taken.push((lease["start"].as_u64().unwrap(), span(&lease)));
    }
    taken.sort_unstable();
    let (a_from, c_from) = (
        a_range["start"].as_u64().unwrap(),
        for_c["start"].as_u64().unwrap(),
    );
    assert_eq!(taken, [(b_event, 1), (a_from, 40), (c_from, 40)]);
    assert_eq!(standing(&app, "a").await, (1, 1));
}
