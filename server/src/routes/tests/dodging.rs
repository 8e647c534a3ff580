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

#[tokio::test]
async fn a_worker_giving_back_audits_owes_one_and_past_three_has_all_its_tests_audited() {
    let app = app(|c| {
        c.audit_share = 0.0;
        c.lease_size = Some(40);
    })
    .await;
    let id = app.external_campaign().await;
    let (_, b_range) = app.claim("b", 40).await;
    let (_, a_range) = app.claim("a", 40).await;
    let (_, c_range) = app.claim("c", 40).await;
    // "b" reports an event, which as the campaign's first is audited (it
    // would carry the whole estimate) and holds the prefix; "a" reports
    // the next range quietly, unresolved behind it.
    let b_from = b_range["start"].as_u64().unwrap();
    report(
        &app,
        "b",
        &b_range,
        json!([{"index": b_from + 3, "weight": 1.0}]),
    )
    .await;
    report(&app, "a", &a_range, json!([])).await;
    let (_, view) = app
        .call("GET", &format!("/api/v1/campaigns/{id}"), None)
        .await;
    assert_eq!(view["audits"]["open"], 1, "{view}");

    // "a" is handed b's audit and gives it back: counted when the run is
    // handed out again (here to "a" itself, which gives it back again).
    let (_, audit) = app.claim("a", 40).await;
    assert_eq!(
        (span(&audit), audit["start"].as_u64()),
        (1, Some(b_from + 3))
    );
    give_back(&app, "a", &audit).await;
    assert_eq!(
        standing(&app, "a").await,
        (0, 0),
        "not counted before it is handed out again"
    );
    let (_, again) = app.claim("a", 40).await;
    assert_eq!(again["start"], audit["start"], "{again}");
    assert_eq!(standing(&app, "a").await, (1, 1));
    // It now owes an audit of one of its own 40 tests: one more is open.
    let (_, view) = app
        .call("GET", &format!("/api/v1/campaigns/{id}"), None)
        .await;
    assert_eq!(view["audits"]["open"], 2, "{view}");
    give_back(&app, "a", &again).await;
    // While it owes, "a" is handed audit runs or nothing, never a range.
    for _ in 0..3 {
        let (status, lease) = app.claim("a", 40).await;
        if status == StatusCode::NO_CONTENT {
            continue;
        }
        assert_eq!(
            span(&lease),
            1,
            "no range while the audit it owes is open: {lease}"
        );
        give_back(&app, "a", &lease).await;
    }
    let (all, in_row) = standing(&app, "a").await;
    assert!(in_row > 3 && all == in_row, "{all} {in_row}");

    // "c" runs the audits open (b's event and a's own test) and agrees.
    report(&app, "c", &c_range, json!([])).await;
    loop {
        let (status, lease) = app.claim("c", 40).await;
        assert_eq!(status, StatusCode::OK, "{lease}");
        if span(&lease) > 1 {
            break;
        }
        let index = lease["start"].as_u64().unwrap();
        let events = if index == b_from + 3 {
            json!([{"index": index, "weight": 1.0}])
        } else {
            json!([])
        };
        report(&app, "c", &lease, events).await;
    }
    let (_, view) = app
        .call("GET", &format!("/api/v1/campaigns/{id}"), None)
        .await;
    // Each run given back (the last one counted when "c" was handed it)
    // cost "a" an audit of one of its own tests, drawn at random (two
    // draws may be the same test).
    let (all, _) = standing(&app, "a").await;
    assert_eq!(view["audits"]["open"], 0, "{view}");
    let agreed = view["audits"]["agreed"].as_u64().unwrap();
    assert!(
        (2..=1 + all).contains(&agreed),
        "{agreed} agreed, {all} given back: {view}"
    );

    // The audit it owed is decided: "a" gets a range again, and with more
    // than three runs given back in a row, all of its 40 tests are audited.
    let (_, range) = app.claim("a", 40).await;
    assert_eq!(span(&range), 40, "{range}");
    report(&app, "a", &range, json!([])).await;
    let (_, view) = app
        .call("GET", &format!("/api/v1/campaigns/{id}"), None)
        .await;
    assert_eq!(view["audits"]["open"], 40, "{view}");
    // Running an audit ends the streak: "c" reports a heavy event, "a"
    // runs its audit and agrees.
    // ("c" is handed the 40 audits of a's tests first, and agrees.)
    let c_event = loop {
        let (_, lease) = app.claim("c", 40).await;
        if span(&lease) == 1 {
            report(&app, "c", &lease, json!([])).await;
            continue;
        }
        let event = lease["start"].as_u64().unwrap() + 7;
        report(&app, "c", &lease, json!([{"index": event, "weight": 1.0}])).await;
        break event;
    };
    let (_, audit) = app.claim("a", 40).await;
    assert_eq!(
        (span(&audit), audit["start"].as_u64()),
        (1, Some(c_event)),
        "{audit}"
    );
    report(
        &app,
        "a",
        &audit,
        json!([{"index": c_event, "weight": 1.0}]),
    )
    .await;
    let (all, in_row) = standing(&app, "a").await;
    assert_eq!(in_row, 0, "{all}");
    assert!(all > 3, "{all}");
}
