//! The lease and result protocol, driven by hand as a worker would:
//! idempotent results, conflicts, fencing on the attempt, expiry and
//! re-issue, weight checks, inline test lists; and precise problem
//! responses for bad requests, with the server still serving after them.

use crate::support::*;
use reqwest::StatusCode;
use serde_json::{json, Value};
use std::time::Duration;
use tslg_api::{
    CampaignStatus, EventResult, Lease, LeaseFence, LeaseRequest, Method, ResultAck, ResultReport,
};
use tslg_method::cases::open_case;
use tslg_method::library::SearchMethod;
use tslg_method::registry::{BuildRequest, ExposureSource, LibrarySearch};

/// `worker`'s report on `lease` (its attempt and key) of `from..to`.
fn report(worker: &str, lease: &Lease, from: u64, to: u64, events: &[EventResult]) -> ResultReport {
    ResultReport {
        next_lease: None,
        near_misses: Vec::new(),
        worker: worker.into(),
        attempt: lease.attempt,
        key: lease.key.clone(),
        from,
        to,
        events: events
            .iter()
            .copied()
            .filter(|e| (from..to).contains(&e.index))
            .collect(),
        packed_events: None,
        invalid: vec![],
        compute_seconds: 1.0,
        threads: 1,
    }
}

async fn post(
    http: &reqwest::Client,
    url: &str,
    body: &impl serde::Serialize,
) -> (StatusCode, Value) {
    let response = http.post(url).json(body).send().await.unwrap();
    let status = response.status();
    let body = response.json().await.unwrap_or(Value::Null);
    (status, body)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn results_are_idempotent_fenced_on_the_attempt_and_leases_expire_and_return() {
    let dir = scratch();
    let server = ServerProcess::start(
        &dir.path().join("db.sqlite"),
        &["--lease-ttl-seconds", "1", "--lease-size", "100"],
    );
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    // β small enough that 100 tests do not stop the campaign.
    let request = campaign(Method::Library, library.id, "idm", 0.01, 3);
    let id = client.create_campaign(&request).await.unwrap().id;

    let lease = client
        .claim(&LeaseRequest {
            worker: "w1".into(),
            threads: 1,
            include_tests: true,
            offers: Vec::new(),
            unhealthy: Vec::new(),
            max_tests: None,
            wait_seconds: None,
            audits_only: false,
            noisy: Vec::new(),
        })
        .await
        .unwrap()
        .expect("a lease");
    assert_eq!(
        (lease.campaign_id, lease.start, lease.end, lease.attempt),
        (id, 0, 100, 1)
    );
    // Reports by hand, in w1's name with w1's secret.
    let http = worker_http(&client, "w1");
    // The inline tests are the campaign's draws, and we run them here.
    let case = open_case("cut-in", None, &ExposureSource::Builtin).unwrap();
    let lib = case
        .build_library(
            &json!({"model": "idm"}),
            &BuildRequest {
                threshold: None,
                search: Some(LibrarySearch::Cells(SearchMethod::Exhaustive)),
            },
        )
        .unwrap();
    let campaign = case
        .campaign(
            Some(&lib.file),
            &json!({"model": "idm"}),
            0.1,
            Default::default(),
            Default::default(),
            3,
        )
        .unwrap();
    let tests = lease.tests.clone().expect("inline tests");
    assert_eq!(tests.len(), 100);
    let mut events = Vec::new();
    for t in &tests {
        let planned = campaign.planned(t.index).unwrap();
        assert_eq!(
            (t.cell, t.weight.to_bits()),
            (planned.cell as u64, planned.weight.to_bits())
        );
        assert_eq!(t.scenario, planned.scenario);
        let outcome = campaign.run(t.index);
        if outcome.event {
            events.push(EventResult {
                index: t.index,
                weight: outcome.weight,
            });
        }
    }
    assert!(
        events.len() > 50,
        "an IDM library testing IDM has mostly events"
    );
    let results = |lease: &Lease| format!("{}/api/v1/leases/{}/results", server.url, lease.id);

    // First half, then the same report again: acknowledged once.
    let first: ResultAck = client
        .report(lease.id, &report("w1", &lease, 0, 50, &events))
        .await
        .unwrap();
    assert_eq!(
        (
            first.accepted,
            first.duplicate,
            first.resume_at,
            first.proceed
        ),
        (50, 0, 50, true)
    );
    let again: ResultAck = client
        .report(lease.id, &report("w1", &lease, 0, 50, &events))
        .await
        .unwrap();
    assert_eq!((again.accepted, again.duplicate), (0, 50));
    let view = client.campaign(id).await.unwrap();
    assert_eq!(view.indices, 50, "the prefix is exactly the reported range");
    assert_eq!(
        view.worker_seconds, 1.0,
        "1 s on 1 thread, charged once though reported twice"
    );

    // A conflicting outcome for a recorded test: 409, nothing changes.
    let mut flipped = events.clone();
    let dropped = flipped.remove(0);
    let (status, body) = post(
        &http,
        &results(&lease),
        &report("w1", &lease, 0, 50, &flipped),
    )
    .await;
    assert_eq!(status, StatusCode::CONFLICT);
    let detail = body["detail"].as_str().unwrap();
    assert!(
        detail.contains(&format!("conflicting result for test {}", dropped.index)),
        "{detail}"
    );
    assert!(detail.contains("now reported as no_event"), "{detail}");
    // (A wrong weight is refused and flags the worker:
    // tests/it/service_trust.rs.)
    // A gap: 422.
    let (status, body) = post(
        &http,
        &results(&lease),
        &report("w1", &lease, 60, 100, &events),
    )
    .await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(
        body["detail"]
            .as_str()
            .unwrap()
            .contains("has results up to 50"),
        "{body}"
    );
    // Another attempt's report: fenced.
    let (status, _) = post(
        &http,
        &results(&lease),
        &ResultReport {
            near_misses: Vec::new(),
            attempt: 2,
            ..report("w1", &lease, 50, 100, &events)
        },
    )
    .await;
    assert_eq!(status, StatusCode::CONFLICT);
    assert_eq!(client.campaign(id).await.unwrap().indices, 50);

    // The lease expires; it is handed out again from where it stopped.
    tokio::time::sleep(Duration::from_millis(1300)).await;
    let again = claim(&client, "w2").await.expect("the expired lease");
    assert_eq!(
        (again.id, again.attempt, again.resume_at),
        (lease.id, 2, 50)
    );
    let (status, body) = post(
        &http,
        &results(&lease),
        &report("w1", &lease, 50, 100, &events),
    )
    .await;
    assert_eq!(status, StatusCode::CONFLICT, "the old holder is fenced out");
    assert!(
        body["detail"].as_str().unwrap().contains("attempt 2"),
        "{body}"
    );
    let done = client
        .report(again.id, &report("w2", &again, 50, 100, &events))
        .await
        .unwrap();
    assert_eq!((done.accepted, done.lease_done), (50, true));

    let view = client.campaign(id).await.unwrap();
    assert_eq!((view.indices, view.events), (100, events.len() as u64));
    // The campaign's own estimate: stratified, its exploring tests known
    // from the index alone.
    let mut fold = tslg_method::prefix::PrefixFold::with_strata(campaign.strata());
    assert_eq!(campaign.strata(), Some(0.1));
    let rule = tslg_method::estimator::StoppingRule {
        beta: 0.01,
        confidence: 0.9,
        n_min: 30,
        min_events: 10,
        max_tests: 10_000_000,
        guard_outside: false,
        interval: Default::default(),
    };
    let sparse: Vec<_> = events
        .iter()
        .map(|e| (e.index, tslg_method::prefix::SparseOutcome::Event(e.weight)))
        .collect();
    let explored: Vec<u64> = (0..100).filter(|&i| campaign.explores(i)).collect();
    assert_eq!(explored, (0..10).map(|k| 10 * k + 9).collect::<Vec<u64>>());
    let exploration = tslg_method::prefix::Exploration {
        explored: &explored,
        mass: campaign.outside_mass().unwrap(),
        surrogate_misses: &|i| campaign.surrogate_misses(i),
    };
    fold.advance(&rule, rule.z(), 100, &sparse, Some(exploration))
        .unwrap();
    assert_eq!(view.estimate.unwrap().to_bits(), fold.estimate().to_bits());

    // Cancelled: later results are acknowledged and ignored.
    let next = claim(&client, "w2").await.expect("a new lease");
    client.cancel_campaign(id).await.unwrap();
    let late = client
        .report(next.id, &report("w2", &next, 100, 200, &[]))
        .await
        .unwrap();
    assert_eq!((late.accepted, late.ignored, late.proceed), (0, 100, false));
    assert_eq!(client.campaign(id).await.unwrap().indices, 100);
    let (status, _) = post(
        &http,
        &format!("{}/api/v1/campaigns/{id}/cancel", server.url),
        &json!({}),
    )
    .await;
    assert_eq!(status, StatusCode::CONFLICT, "cancelling twice");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_requests_get_precise_problems_and_the_server_keeps_serving() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    let http = reqwest::Client::new();
    let library = ready_library(&client, "idm", true).await;
    let good = json!({"case": "cut-in", "method": "library", "library_id": library.id,
                      "vut": {"model": "idm"}, "max_tests": 1000});
    let with = |key: &str, value: Value| {
        let mut v = good.clone();
        v[key] = value;
        v
    };
    let campaigns = format!("{}/api/v1/campaigns", server.url);
    let cases: Vec<(Value, StatusCode, &str)> = vec![
        (
            with("beta", json!(1.5)),
            StatusCode::UNPROCESSABLE_ENTITY,
            "beta = 1.5 must be in [0.0001, 0.99]",
        ),
        (
            with("epsilon", json!(1.0)),
            StatusCode::UNPROCESSABLE_ENTITY,
            "ε = 1 must be 0 or in [0.000001, 0.999]",
        ),
        (
            with("confidence", json!(0.0)),
            StatusCode::UNPROCESSABLE_ENTITY,
            "confidence = 0 must be in [0.5, 0.999999]",
        ),
        (
            with("max_tests", json!(0)),
            StatusCode::UNPROCESSABLE_ENTITY,
            "max_tests = 0 must be in 1..=2^50",
        ),
        (
            with("max_tests", json!(-5)),
            StatusCode::UNPROCESSABLE_ENTITY,
            "max_tests",
        ),
        (
            with("beta", json!("small")),
            StatusCode::UNPROCESSABLE_ENTITY,
            "beta",
        ),
        (
            with("case", json!("lane-keep")),
            StatusCode::UNPROCESSABLE_ENTITY,
            "unknown case `lane-keep`; known cases: cut-in, highway-exit, car-following",
        ),
        (
            with("vut", json!({"model": "tesla"})),
            StatusCode::UNPROCESSABLE_ENTITY,
            "unknown variant `tesla`",
        ),
        (
            with("vut", json!({"model": "idm", "v0": -3})),
            StatusCode::UNPROCESSABLE_ENTITY,
            "v0",
        ),
        (
            with("vut", json!({"external": "mine", "speed": 3})),
            StatusCode::UNPROCESSABLE_ENTITY,
            "unknown field `speed`",
        ),
        (
            with("library_id", json!(999)),
            StatusCode::UNPROCESSABLE_ENTITY,
            "library_id 999 does not name a library",
        ),
        (
            with("library_id", Value::Null),
            StatusCode::UNPROCESSABLE_ENTITY,
            "method `library` needs a library_id",
        ),
        (
            with("betta", json!(0.1)),
            StatusCode::UNPROCESSABLE_ENTITY,
            "unknown field `betta`",
        ),
        (
            with("method", json!("magic")),
            StatusCode::UNPROCESSABLE_ENTITY,
            "unknown variant `magic`",
        ),
    ];
    for (body, status, detail) in cases {
        let (got, problem) = post(&http, &campaigns, &body).await;
        assert_eq!(got, status, "{body} → {problem}");
        assert_eq!(problem["status"], json!(status.as_u16()));
        let text = problem["detail"].as_str().unwrap_or_default();
        assert!(
            text.contains(detail),
            "{body}: detail `{text}` lacks `{detail}`"
        );
    }
    let ndd_unknown_case =
        json!({"case": "lane-keep", "method": "ndd", "vut": {"model": "idm"}, "max_tests": 100});
    let (status, problem) = post(&http, &campaigns, &ndd_unknown_case).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(
        problem["detail"],
        json!("unknown case `lane-keep`; known cases: cut-in, highway-exit, car-following")
    );

    let libraries = format!("{}/api/v1/libraries", server.url);
    let bad_table = json!({"case": "cut-in", "surrogate": {"model": "idm"},
                           "exposure": {"kind": "table", "name": "t.csv", "text": "range,range_rate\n1,x"}});
    let (status, problem) = post(&http, &libraries, &bad_table).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(
        problem["detail"]
            .as_str()
            .unwrap()
            .starts_with("exposure table `t.csv` rejected"),
        "{problem}"
    );
    let (status, problem) = post(&http, &libraries, &json!({"case": "cut-in", "surrogate": {"model": "idm"}, "search": {"method": "multistart", "starts": 0}})).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(
        problem["detail"].as_str().unwrap().contains("starts = 0"),
        "{problem}"
    );
    // Each case takes only its own kind of search.
    for (body, detail) in [
        (
            json!({"case": "car-following", "surrogate": {"model": "idm"}, "search": {"method": "exhaustive"}}),
            "search.method is dynamic-programming or temporal-difference",
        ),
        (
            json!({"case": "car-following", "surrogate": {"model": "idm"}, "threshold": {"kind": "relative", "m": 2}}),
            "it takes no threshold",
        ),
        (
            json!({"case": "car-following", "surrogate": {"model": "idm"}, "search": {"method": "temporal-difference", "alpha": 0}}),
            "alpha = 0 must be in [0.001, 1]",
        ),
        (
            json!({"case": "car-following", "preset": "dense", "surrogate": {"model": "idm"}}),
            "presets are paper",
        ),
        (
            json!({"case": "cut-in", "surrogate": {"model": "idm"}, "search": {"method": "dynamic-programming"}}),
            "search.method is exhaustive or multistart",
        ),
    ] {
        let (status, problem) = post(&http, &libraries, &body).await;
        assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{body}");
        assert!(
            problem["detail"].as_str().unwrap().contains(detail),
            "{body}: {problem}"
        );
    }

    // Malformed JSON, unknown ids, bad ids, wrong methods, unknown routes.
    let raw = http
        .post(&campaigns)
        .header("content-type", "application/json")
        .body("{")
        .send()
        .await
        .unwrap();
    assert_eq!(raw.status(), StatusCode::BAD_REQUEST);
    assert_eq!(raw.headers()["content-type"], "application/problem+json");
    for (method, path, status) in [
        (
            reqwest::Method::GET,
            "/api/v1/campaigns/999",
            StatusCode::NOT_FOUND,
        ),
        (
            reqwest::Method::GET,
            "/api/v1/campaigns/abc",
            StatusCode::BAD_REQUEST,
        ),
        (
            reqwest::Method::GET,
            "/api/v1/libraries/999/file",
            StatusCode::NOT_FOUND,
        ),
        (
            reqwest::Method::DELETE,
            "/api/v1/campaigns",
            StatusCode::METHOD_NOT_ALLOWED,
        ),
        (
            reqwest::Method::GET,
            "/api/v1/nothing",
            StatusCode::NOT_FOUND,
        ),
    ] {
        let response = http
            .request(method.clone(), format!("{}{path}", server.url))
            .send()
            .await
            .unwrap();
        assert_eq!(response.status(), status, "{method} {path}");
        assert_eq!(
            response.headers()["content-type"],
            "application/problem+json",
            "{method} {path}"
        );
        let problem: Value = response.json().await.unwrap();
        assert!(!problem["detail"].as_str().unwrap().is_empty());
    }
    let (status, problem) = post(
        &http,
        &format!("{}/api/v1/leases", server.url),
        &json!({"worker": "", "threads": 1}),
    )
    .await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{problem}");
    let health = http
        .get(format!("{}/healthz", server.url))
        .send()
        .await
        .unwrap();
    assert_eq!(health.status(), StatusCode::OK);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_openapi_document_describes_the_contract() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let doc: Value = reqwest::get(format!("{}/api/v1/openapi.json", server.url))
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert!(doc["openapi"].as_str().unwrap().starts_with("3."));
    for path in [
        "/healthz",
        "/api/v1/libraries",
        "/api/v1/libraries/{id}",
        "/api/v1/campaigns",
        "/api/v1/campaigns/{id}",
        "/api/v1/campaigns/{id}/history",
        "/api/v1/campaigns/{id}/cancel",
        "/api/v1/leases",
        "/api/v1/leases/{id}/heartbeat",
        "/api/v1/leases/{id}/results",
    ] {
        assert!(doc["paths"][path].is_object(), "{path} missing");
    }
    let view = &doc["components"]["schemas"]["CampaignView"]["properties"];
    for field in [
        "status",
        "tests",
        "events",
        "invalid",
        "estimate",
        "half_width",
        "relative_half_width",
        "ci_low",
        "ci_high",
    ] {
        assert!(view[field].is_object(), "CampaignView.{field} missing");
    }
    // The cases, as their descriptors say: what a client needs to build a
    // request without reading the code.
    assert!(doc["paths"]["/api/v1/cases"].is_object());
    let cases: Value = reqwest::get(format!("{}/api/v1/cases", server.url))
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let names: Vec<&str> = cases
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["cut-in", "highway-exit", "car-following"]);
    let highway = &cases[1];
    assert_eq!(highway["presets"][0]["name"], "paper");
    assert_eq!(highway["default_surrogate"], "mobil");
    assert_eq!(highway["default_search"]["method"], "exhaustive");
    assert_eq!(
        highway["tables"][0]["doc"],
        "docs/bring-your-own.md#highway-exit-pv1-r-v2"
    );
    let following = &cases[2];
    assert_eq!(
        (&following["scenarios"], &following["default_outside"]),
        (&serde_json::json!("sequential"), &serde_json::json!("ndd"))
    );
    assert_eq!(following["adaptive"], false);
    assert_eq!(cases[0]["tables"].as_array().unwrap().len(), 1);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_late_result_counts_until_the_lease_is_taken_over_and_nothing_counts_after_the_stop() {
    let dir = scratch();
    let server = ServerProcess::start(
        &dir.path().join("db.sqlite"),
        &["--lease-ttl-seconds", "1", "--lease-size", "100"],
    );
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let request = campaign(Method::Library, library.id, "idm", 0.2, 3);
    let id = client.create_campaign(&request).await.unwrap().id;
    let file = client.library_file(library.id).await.unwrap();
    let tests = open_case("cut-in", None, &ExposureSource::Builtin)
        .unwrap()
        .campaign(
            Some(&file),
            &json!({"model": "idm"}),
            0.1,
            Default::default(),
            Default::default(),
            3,
        )
        .unwrap();
    let run = |lease: &Lease| -> Vec<EventResult> {
        (lease.start..lease.end)
            .filter_map(|index| {
                let o = tests.run(index);
                o.event.then_some(EventResult {
                    index,
                    weight: o.weight,
                })
            })
            .collect()
    };
    let first = claim(&client, "w1").await.unwrap();
    let second = claim(&client, "w1").await.unwrap();
    assert_eq!((first.start, second.start), (0, 100));

    // Both expire; nobody takes them over. The holder's late report is
    // still the lease's only report: it counts.
    tokio::time::sleep(Duration::from_millis(1300)).await;
    let late = client
        .report(first.id, &report("w1", &first, 0, 100, &run(&first)))
        .await
        .unwrap();
    assert_eq!((late.accepted, late.duplicate), (100, 0));
    // These 100 tests satisfy the rule: the campaign stops exactly where
    // the in-process run does.
    let stopped = client.campaign(id).await.unwrap();
    assert_eq!(stopped.status, CampaignStatus::Converged);
    assert_same(&stopped, &in_process(Some("idm"), &request));
    assert!(!late.proceed);

    // After the stop: a result is acknowledged and ignored, a heartbeat says
    // stop, a repeated or even conflicting report changes nothing.
    let after = client
        .report(second.id, &report("w1", &second, 100, 200, &run(&second)))
        .await
        .unwrap();
    assert_eq!(
        (after.accepted, after.ignored, after.proceed),
        (0, 100, false)
    );
    let fence = LeaseFence {
        worker: "w1".into(),
        attempt: second.attempt,
        key: second.key.clone(),
    };
    let beat = client.heartbeat(second.id, &fence).await.unwrap();
    assert_eq!(
        (beat.proceed, beat.campaign_status),
        (false, CampaignStatus::Converged)
    );
    let conflicting = client
        .report(first.id, &report("w1", &first, 0, 100, &[]))
        .await
        .unwrap();
    assert_eq!((conflicting.accepted, conflicting.ignored), (0, 100));
    let view = client.campaign(id).await.unwrap();
    assert_eq!(
        (view.indices, view.events, view.estimate.map(f64::to_bits)),
        (
            stopped.indices,
            stopped.events,
            stopped.estimate.map(f64::to_bits)
        )
    );
    assert!(claim(&client, "w2").await.is_none(), "no work is left");
}
