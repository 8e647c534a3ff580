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
    let (status, ack) = app
        .call(
            "POST",
            &format!("/api/v1/leases/{}/results", lease["id"]),
            Some(report),
        )
        .await;
    assert_eq!(status, StatusCode::OK, "{ack}");
    ack
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
        loop {
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

#[tokio::test]
async fn a_worker_giving_back_audits_owes_one_and_past_three_has_all_its_tests_audited() {
    let app = app(|c| {
        c.audit_share = 0.0;
        c.lease_size = Some(40);
    })
    .await;
    let id = app.external_campaign().await;
    // "d" holds the first range unreported: the prefix stays at 0, and
    // every later result is unresolved.
    let (_, _held) = app.claim("d", 40).await;
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
        // Owing, "a" is handed nothing: no range, no audit run.
        let (status, nothing) = app.claim("a", 40).await;
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
