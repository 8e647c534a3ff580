//! Worker identities (issue 47): a request naming a worker must carry that
//! worker's secret. The attack they stop: anyone with the shared worker
//! token claimed a lease in a live worker's name and sent one report the
//! replay contradicted; the named worker was flagged and all its results
//! taken back (two requests per victim wiped 104 M tests).

use super::*;

/// Calls the router with `secret` (or none) as the worker secret.
async fn call_as(app: &App, uri: &str, body: Value, secret: Option<&str>) -> (StatusCode, Value) {
    let mut request = Request::builder().method("POST").uri(uri);
    if let Some(secret) = secret {
        request = request.header(tslg_api::WORKER_SECRET_HEADER, secret);
    }
    app.send(request, Some(body)).await
}

async fn indices(app: &App, id: i64) -> Value {
    app.call("GET", &format!("/api/v1/campaigns/{id}"), None)
        .await
        .1["indices"]
        .clone()
}

#[tokio::test]
async fn a_request_in_another_workers_name_is_refused_and_changes_nothing() {
    let app = app(|c| c.lease_size = Some(40)).await;
    let id = app.idm_ndd_campaign().await;
    let tests = app.state.samplers.cached(id).expect("built at creation");
    // The victim works honestly: 40 tests recorded.
    let (_, lease) = app.claim_builtin("victim").await;
    let events_of = |lease: &Value| {
        let (from, to) = (
            lease["start"].as_u64().unwrap(),
            lease["end"].as_u64().unwrap(),
        );
        json!((from..to)
            .filter(|&i| tests.run(i).event)
            .map(|i| json!({"index": i, "weight": 1.0}))
            .collect::<Vec<_>>())
    };
    let mut honest = quiet_report("victim", &lease);
    honest["events"] = events_of(&lease);
    let results = format!("/api/v1/leases/{}/results", lease["id"]);
    let (status, ack) = app.call("POST", &results, Some(honest)).await;
    assert_eq!(status, StatusCode::OK, "{ack}");
    assert_eq!(indices(&app, id).await, 40);
    let (_, second) = app.claim_builtin("victim").await;

    // The attacker has the fleet token (none is set here) but not the
    // victim's secret: without one, or with its own, every request in the
    // victim's name is a 403.
    let (status, own) = app
        .call("POST", "/api/v1/workers", Some(json!({"name": "attacker"})))
        .await;
    assert_eq!(status, StatusCode::CREATED, "{own}");
    let own = own["secret"].as_str().unwrap();
    let ask = json!({"worker": "victim", "threads": 1, "max_tests": 40});
    let mut forged = quiet_report("victim", &second);
    forged["events"] = json!([{"index": second["start"], "weight": 1.0}]);
    let fence = json!({"worker": "victim", "attempt": second["attempt"], "key": second["key"]});
    let lease_path = |what: &str| format!("/api/v1/leases/{}/{what}", second["id"]);
    for secret in [None, Some(own), Some("0".repeat(64).as_str())] {
        for (uri, body) in [
            ("/api/v1/leases".to_owned(), ask.clone()),
            (lease_path("results"), forged.clone()),
            (lease_path("heartbeat"), fence.clone()),
            (lease_path("release"), fence.clone()),
        ] {
            let (status, problem) = call_as(&app, &uri, body, secret).await;
            assert_eq!(
                status,
                StatusCode::FORBIDDEN,
                "{uri} with {secret:?}: {problem}"
            );
            let detail = problem["detail"].as_str().unwrap();
            assert!(detail.contains("worker `victim`"), "{detail}");
        }
    }
    // Nothing changed: the victim is not flagged, its results stand, its
    // lease is its own and its report is taken.
    let (_, workers) = app.call("GET", "/api/v1/workers", None).await;
    let victim = &workers["workers"]
        .as_array()
        .unwrap()
        .iter()
        .find(|w| w["name"] == "victim")
        .unwrap();
    assert!(victim.get("flagged").is_none(), "{victim}");
    assert!(victim["registered_at"]
        .as_str()
        .is_some_and(|t| t.ends_with('Z')));
    assert_eq!(indices(&app, id).await, 40);
    let mut own_report = quiet_report("victim", &second);
    own_report["events"] = events_of(&second);
    let (status, ack) = app
        .call("POST", &lease_path("results"), Some(own_report))
        .await;
    assert_eq!(
        (status, ack["accepted"].as_u64()),
        (StatusCode::OK, Some(40)),
        "{ack}"
    );
    assert_eq!(indices(&app, id).await, 80);
}

#[tokio::test]
async fn a_name_is_issued_once_and_a_revoked_worker_gets_nothing() {
    let app = app(|c| c.lease_size = Some(40)).await;
    app.idm_ndd_campaign().await;
    let register =
        |name: &'static str| app.call("POST", "/api/v1/workers", Some(json!({"name": name})));
    let (status, first) = register("node-1").await;
    assert_eq!(
        (status, first["name"].as_str()),
        (StatusCode::CREATED, Some("node-1"))
    );
    // The same name again (another worker, or this one restarted without
    // its secret) is the next free variant: the first keeps its own.
    let (_, second) = register("node-1").await;
    let (_, third) = register("node-1").await;
    assert_eq!(second["name"], "node-1.2");
    assert_eq!(third["name"], "node-1.3");
    assert_ne!(first["secret"], second["secret"]);
    assert_eq!(first["secret"].as_str().unwrap().len(), 64);
    for bad in [
        json!({"name": ""}),
        json!({"name": "a\u{7}b"}),
        json!({"name": "x".repeat(121)}),
    ] {
        let (status, problem) = app.call("POST", "/api/v1/workers", Some(bad)).await;
        assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{problem}");
    }

    // node-1 takes a lease; the operator revokes it: the lease is handed
    // out again at once and node-1 is refused from then on.
    let secret = first["secret"].as_str().unwrap();
    app.secrets
        .lock()
        .unwrap()
        .insert("node-1".into(), secret.into());
    let (status, lease) = app.claim_builtin("node-1").await;
    assert_eq!(status, StatusCode::OK, "{lease}");
    let (status, _) = app.call("DELETE", "/api/v1/workers/node-1", None).await;
    assert_eq!(status, StatusCode::NO_CONTENT);
    let (status, problem) = app.call("DELETE", "/api/v1/workers/node-1", None).await;
    assert_eq!(status, StatusCode::NOT_FOUND, "{problem}");
    let (status, problem) = app.claim_builtin("node-1").await;
    assert_eq!(status, StatusCode::FORBIDDEN, "{problem}");
    assert!(
        problem["detail"].as_str().unwrap().contains("revoked at"),
        "{problem}"
    );
    let (status, again) = app.claim_builtin("other").await;
    assert_eq!(status, StatusCode::OK, "{again}");
    assert_eq!(
        again["start"], lease["start"],
        "the revoked worker's range is handed out again"
    );
    let (_, workers) = app.call("GET", "/api/v1/workers", None).await;
    let node = workers["workers"]
        .as_array()
        .unwrap()
        .iter()
        .find(|w| w["name"] == "node-1")
        .cloned()
        .unwrap();
    assert!(node["revoked_at"].as_str().is_some(), "{node}");
    // The revoked name is not issued again.
    let (_, fourth) = register("node-1").await;
    assert_eq!(fourth["name"], "node-1.4");
}
