//! The router driven in process (`tower::ServiceExt::oneshot`) on a scratch
//! database: the store logic behind the routes, where no real process or
//! socket is needed (the end-to-end tests in `tests/it/` start those).

use crate::config::Config;
use crate::db::Database;
use crate::state::AppState;
use axum::body::Body;
use axum::http::{Request, StatusCode};
use axum::Router;
use serde_json::{json, Value};
use tower::ServiceExt;

struct App {
    router: Router,
    state: AppState,
    /// The secrets of the workers registered, by name.
    secrets: std::sync::Mutex<std::collections::HashMap<String, String>>,
    _dir: tempfile::TempDir,
}

async fn app(configure: impl FnOnce(&mut Config)) -> App {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}", dir.path().join("db.sqlite").display());
    let mut config = Config::embedded(&url);
    configure(&mut config);
    let db = Database::open(&url, config.durability).await.unwrap();
    let state = AppState::new(db, config);
    App {
        router: super::router(state.clone()),
        state,
        secrets: Default::default(),
        _dir: dir,
    }
}

impl App {
    /// Calls the router; a lease request, heartbeat, release or report
    /// naming a worker carries its secret (registered at first use, as
    /// `tslg_client::Client` does).
    async fn call(&self, method: &str, uri: &str, body: Option<Value>) -> (StatusCode, Value) {
        let mut request = Request::builder().method(method).uri(uri);
        let worker = body
            .as_ref()
            .and_then(|b| b["worker"].as_str())
            .filter(|_| uri.starts_with("/api/v1/leases"));
        if let Some(worker) = worker {
            request = request.header(tslg_api::WORKER_SECRET_HEADER, self.secret(worker).await);
        }
        self.send(request, body).await
    }

    /// Sends `request` with `body` (JSON) and reads the answer.
    async fn send(
        &self,
        request: axum::http::request::Builder,
        body: Option<Value>,
    ) -> (StatusCode, Value) {
        let request = match body {
            Some(body) => request
                .header("content-type", "application/json")
                .body(Body::from(body.to_string())),
            None => request.body(Body::empty()),
        }
        .unwrap();
        let response = self.router.clone().oneshot(request).await.unwrap();
        let status = response.status();
        let bytes = axum::body::to_bytes(response.into_body(), usize::MAX)
            .await
            .unwrap();
        (
            status,
            serde_json::from_slice(&bytes).unwrap_or(Value::Null),
        )
    }

    /// `worker`'s secret, registering it at first use.
    async fn secret(&self, worker: &str) -> String {
        if let Some(secret) = self.secrets.lock().unwrap().get(worker) {
            return secret.clone();
        }
        let issued = Box::pin(self.call("POST", "/api/v1/workers", Some(json!({"name": worker}))));
        let (status, issued) = issued.await;
        assert_eq!(status, StatusCode::CREATED, "{issued}");
        assert_eq!(issued["name"], worker, "{issued}");
        let secret = issued["secret"].as_str().unwrap().to_owned();
        self.secrets
            .lock()
            .unwrap()
            .insert(worker.into(), secret.clone());
        secret
    }

    /// An NDD campaign of the external program `x` on cut-in, which only
    /// workers offering `x:cut-in:step` run.
    async fn external_campaign(&self) -> i64 {
        let (status, view) = self
            .call(
                "POST",
                "/api/v1/campaigns",
                Some(
                    json!({"case": "cut-in", "method": "ndd", "vut": {"external": "x"},
                            "beta": 0.01, "max_tests": 1_000_000}),
                ),
            )
            .await;
        assert_eq!(status, StatusCode::CREATED, "{view}");
        view["id"].as_i64().unwrap()
    }

    /// An NDD campaign of the built-in IDM on cut-in (seed 3), which the
    /// coordinator checks by running reported tests again.
    async fn idm_ndd_campaign(&self) -> i64 {
        let (status, view) = self
            .call(
                "POST",
                "/api/v1/campaigns",
                Some(
                    json!({"case": "cut-in", "method": "ndd", "vut": {"model": "idm"},
                            "beta": 0.01, "max_tests": 1_000_000, "seed": 3}),
                ),
            )
            .await;
        assert_eq!(status, StatusCode::CREATED, "{view}");
        view["id"].as_i64().unwrap()
    }

    /// A lease of at most 40 tests for `worker`, offering no program.
    async fn claim_builtin(&self, worker: &str) -> (StatusCode, Value) {
        let ask = json!({"worker": worker, "threads": 1, "max_tests": 40});
        self.call("POST", "/api/v1/leases", Some(ask)).await
    }

    async fn claim(&self, worker: &str, max_tests: u64) -> (StatusCode, Value) {
        let ask = json!({"worker": worker, "threads": 1, "offers": ["x:cut-in:step"],
                         "max_tests": max_tests});
        self.call("POST", "/api/v1/leases", Some(ask)).await
    }
}

/// A report of `lease` whole, with no events.
fn quiet_report(worker: &str, lease: &Value) -> Value {
    json!({"worker": worker, "attempt": lease["attempt"], "key": lease["key"],
           "from": lease["resume_at"], "to": lease["end"], "compute_seconds": 0.0,
           "threads": 1})
}

/// Posts `report` on `lease` and returns the acknowledgement, which must
/// be a 200.
async fn accepted(app: &App, lease: &Value, report: Value) -> Value {
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

#[tokio::test]
async fn reports_beyond_the_limits_or_damaged_are_refused_precisely() {
    // Leases of a fixed size: a first lease is otherwise one test.
    let app = app(|c| c.lease_size = Some(100_000)).await;
    app.external_campaign().await;
    let (_, lease) = app.claim("w", 100_000).await;
    let id = lease["id"].as_i64().unwrap();
    let results = format!("/api/v1/leases/{id}/results");
    let mut report = quiet_report("w", &lease);
    let events: Vec<Value> = (0..=tslg_api::MAX_REPORT_EVENTS as u64)
        .map(|i| json!({"index": i, "weight": 1.0}))
        .collect();
    report["events"] = json!(events);
    let (status, problem) = app.call("POST", &results, Some(report)).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(problem["detail"]
        .as_str()
        .unwrap()
        .contains("at most 65536 per report"));

    let mut both = quiet_report("w", &lease);
    both["events"] = json!([{"index": 1, "weight": 1.0}]);
    both["packed_events"] = json!("AAA=");
    let (status, problem) = app.call("POST", &results, Some(both)).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(
        problem["detail"].as_str().unwrap().contains("not both"),
        "{problem}"
    );

    let mut damaged = quiet_report("w", &lease);
    damaged["packed_events"] = json!("AQU=");
    let (status, problem) = app.call("POST", &results, Some(damaged)).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(
        problem["detail"]
            .as_str()
            .unwrap()
            .contains("packed events"),
        "{problem}"
    );

    let mut early = quiet_report("w", &lease);
    early["compute_seconds"] = json!(30.0);
    let (status, problem) = app.call("POST", &results, Some(early)).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(
        problem["detail"].as_str().unwrap().contains("since lease"),
        "{problem}"
    );

    // Packed like a worker sends it: accepted, and stored packed.
    let mut packed: tslg_api::ResultReport =
        serde_json::from_value(quiet_report("w", &lease)).unwrap();
    packed.pack_events(&[(packed.from + 3, 1.0), (packed.from + 9, 1.0)]);
    let (status, ack) = app
        .call(
            "POST",
            &results,
            Some(serde_json::to_value(&packed).unwrap()),
        )
        .await;
    assert_eq!(status, StatusCode::OK, "{ack}");
    let (rows, events): (i64, i64) = app
        .state
        .db
        .read(|conn| crate::db::sql::one(conn, "SELECT COUNT(*), SUM(events) FROM reports", []))
        .await
        .unwrap();
    assert_eq!((rows, events), (1, 2));
}

#[tokio::test]
async fn a_flagged_worker_gets_nothing_until_an_operator_clears_it() {
    let app = app(|_| {}).await;
    app.external_campaign().await;
    app.state
        .db
        .write(|conn| {
            crate::db::sql::execute(
                conn,
                "INSERT INTO flagged_workers (name, reason) VALUES ('bad', 'lied about test 7')",
                [],
            )
        })
        .await
        .unwrap();
    let (status, problem) = app.claim("bad", 10).await;
    assert_eq!(status, StatusCode::FORBIDDEN);
    assert!(problem["detail"]
        .as_str()
        .unwrap()
        .contains("lied about test 7"));
    let (status, workers) = app.call("GET", "/api/v1/workers", None).await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(workers["workers"][0]["flagged"], "lied about test 7");
    let (status, _) = app.call("DELETE", "/api/v1/workers/bad/flag", None).await;
    assert_eq!(status, StatusCode::NO_CONTENT);
    let (status, problem) = app.call("DELETE", "/api/v1/workers/bad/flag", None).await;
    assert_eq!(status, StatusCode::NOT_FOUND, "{problem}");
    // A name no worker can have is a malformed path, as the contract says.
    let (status, problem) = app.call("DELETE", "/api/v1/workers/a%01b/flag", None).await;
    assert_eq!(status, StatusCode::BAD_REQUEST, "{problem}");
    let (status, lease) = app.claim("bad", 10).await;
    assert_eq!(status, StatusCode::OK, "{lease}");
}

#[tokio::test]
async fn an_audit_is_run_by_another_worker_and_holds_the_prefix_until_it_agrees() {
    let app = app(|c| {
        c.audit_share = 1.0;
        c.lease_size = Some(5);
    })
    .await;
    let id = app.external_campaign().await;
    // Both workers are seen before the first report, so its audits are
    // not waived; with a share of 1 every test is audited.
    let (_, first) = app.claim("a", 5).await;
    let (_, second) = app.claim("b", 5).await;
    let (status, ack) = app
        .call(
            "POST",
            &format!("/api/v1/leases/{}/results", first["id"]),
            Some(quiet_report("a", &first)),
        )
        .await;
    assert_eq!(status, StatusCode::OK, "{ack}");
    let (_, view) = app
        .call("GET", &format!("/api/v1/campaigns/{id}"), None)
        .await;
    assert_eq!(view["indices"], 0, "held at the first audit");
    assert_eq!(view["audits"]["open"], 5);
    // "a" is not given its own tests to audit; "b" is, one test at a time,
    // before any new range.
    let (_, own) = app.claim("a", 5).await;
    assert_eq!(
        own["end"].as_u64().unwrap() - own["start"].as_u64().unwrap(),
        5
    );
    assert!(own["start"].as_u64().unwrap() >= 10);
    for _ in 0..5 {
        let (status, audit) = app.claim("b", 5).await;
        assert_eq!(status, StatusCode::OK);
        let start = audit["start"].as_u64().unwrap();
        assert_eq!(
            (audit["end"].as_u64().unwrap(), start < 5),
            (start + 1, true)
        );
        let (status, ack) = app
            .call(
                "POST",
                &format!("/api/v1/leases/{}/results", audit["id"]),
                Some(quiet_report("b", &audit)),
            )
            .await;
        assert_eq!(status, StatusCode::OK, "{ack}");
    }
    let (_, view) = app
        .call("GET", &format!("/api/v1/campaigns/{id}"), None)
        .await;
    assert_eq!(view["audits"]["agreed"], 5, "{view}");
    assert_eq!(view["audits"]["open"], 0);
    assert_eq!(
        view["indices"], 5,
        "the first range resolved; the second is b's"
    );
    let _ = second;
}

#[tokio::test]
async fn an_overlong_target_is_a_414_problem() {
    let app = app(|_| {}).await;
    let uri = format!("/api/v1/campaigns/{}", "1".repeat(super::MAX_URI_BYTES));
    let (status, problem) = app.call("GET", &uri, None).await;
    assert_eq!(status, StatusCode::URI_TOO_LONG);
    assert!(problem["detail"].as_str().unwrap().contains("at most 8192"));
}

/// A small report of a built-in vehicle, which the writer checks and
/// records in one trip (`receive::at_once`): an honest one is recorded;
/// a forged one (an event where the coordinator's run gives none) is
/// refused, its worker flagged and its earlier report taken back, and the
/// flag holds (it commits although the report is refused).
#[tokio::test]
async fn a_small_forged_report_is_refused_and_its_worker_flagged() {
    let app = app(|c| c.lease_size = Some(40)).await;
    let id = app.idm_ndd_campaign().await;
    let tests = app.state.samplers.cached(id).expect("built at creation");
    let events = |lease: &Value| -> Vec<u64> {
        let (from, to) = (
            lease["start"].as_u64().unwrap(),
            lease["end"].as_u64().unwrap(),
        );
        (from..to).filter(|&i| tests.run(i).event).collect()
    };
    let claim = |worker: &'static str| app.claim_builtin(worker);
    let (_, first) = claim("forger").await;
    let mut honest = quiet_report("forger", &first);
    honest["events"] = json!(events(&first)
        .iter()
        .map(|i| json!({"index": i, "weight": 1.0}))
        .collect::<Vec<_>>());
    let results = |lease: &Value| format!("/api/v1/leases/{}/results", lease["id"]);
    let (status, ack) = app.call("POST", &results(&first), Some(honest)).await;
    assert_eq!(
        (status, ack["accepted"].as_u64()),
        (StatusCode::OK, Some(40)),
        "{ack}"
    );
    let (_, view) = app
        .call("GET", &format!("/api/v1/campaigns/{id}"), None)
        .await;
    assert_eq!(view["indices"], 40);

    let (_, second) = claim("forger").await;
    let real = events(&second);
    let start = second["start"].as_u64().unwrap();
    let fake = (start..start + 40).find(|i| !real.contains(i)).unwrap();
    let caught = real.first().map_or(fake, |&r| r.min(fake));
    let mut forged = quiet_report("forger", &second);
    forged["events"] = json!([{"index": fake, "weight": 1.0}]);
    let (status, problem) = app.call("POST", &results(&second), Some(forged)).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{problem}");
    let detail = problem["detail"].as_str().unwrap();
    assert!(
        detail.contains(&format!("test {caught} was reported as")),
        "{detail}"
    );
    assert!(detail.contains("worker `forger` is flagged"), "{detail}");
    let (status, _) = claim("forger").await;
    assert_eq!(status, StatusCode::FORBIDDEN);
    let (_, view) = app
        .call("GET", &format!("/api/v1/campaigns/{id}"), None)
        .await;
    assert_eq!(
        view["indices"], 0,
        "the forger's honest report is taken back"
    );
}

/// A campaign may name a built-in vehicle by its name alone and leave out
/// its budget (the command line's default); a list filters by state and
/// refuses an unknown one; a running campaign no live worker can serve
/// says so.
#[tokio::test]
async fn campaigns_take_a_vehicle_name_and_the_default_budget_and_list_by_state() {
    let app = app(|_| {}).await;
    let (status, view) = app
        .call(
            "POST",
            "/api/v1/campaigns",
            Some(json!({"case": "cut-in", "method": "ndd", "vut": "fvdm"})),
        )
        .await;
    assert_eq!(status, StatusCode::CREATED, "{view}");
    assert_eq!(view["vut"]["model"], "fvdm");
    assert_eq!(view["max_tests"], tslg_api::DEFAULT_MAX_TESTS);
    let waiting = |view: &Value| {
        view["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .filter_map(|w| w.as_str())
            .filter(|w| w.starts_with("no worker"))
            .map(str::to_owned)
            .collect::<Vec<_>>()
    };
    let (_, view) = app.call("GET", "/api/v1/campaigns/1", None).await;
    assert!(
        waiting(&view)[0].contains("no worker has asked for work"),
        "{view}"
    );
    // A worker asks: the built-in vehicle's campaign has one; the external
    // program's, which it does not offer, has none.
    let ask = json!({"worker": "w", "threads": 1, "max_tests": 10});
    app.call("POST", "/api/v1/leases", Some(ask)).await;
    let (_, view) = app.call("GET", "/api/v1/campaigns/1", None).await;
    assert!(waiting(&view).is_empty(), "{view}");
    let id = app.external_campaign().await;
    let (_, view) = app
        .call("GET", &format!("/api/v1/campaigns/{id}"), None)
        .await;
    assert!(waiting(&view)[0].contains("`x:cut-in:step`"), "{view}");
    app.call("POST", &format!("/api/v1/campaigns/{id}/cancel"), None)
        .await;
    let (_, view) = app
        .call("GET", &format!("/api/v1/campaigns/{id}"), None)
        .await;
    assert!(
        waiting(&view).is_empty(),
        "a stopped campaign waits for nothing: {view}"
    );

    let ids = |list: &Value| -> Vec<i64> {
        list["campaigns"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c["id"].as_i64().unwrap())
            .collect()
    };
    let (status, list) = app.call("GET", "/api/v1/campaigns", None).await;
    assert_eq!((status, ids(&list)), (StatusCode::OK, vec![id, 1]));
    let (_, list) = app
        .call("GET", "/api/v1/campaigns?status=running", None)
        .await;
    assert_eq!(ids(&list), vec![1]);
    let (_, list) = app
        .call("GET", "/api/v1/campaigns?status=cancelled", None)
        .await;
    assert_eq!(ids(&list), vec![id]);
    for bad in ["status=runing", "state=running"] {
        let (status, problem) = app
            .call("GET", &format!("/api/v1/campaigns?{bad}"), None)
            .await;
        assert_eq!(status, StatusCode::BAD_REQUEST, "{bad}");
        let field = bad.split(['=', 'n']).next().unwrap();
        assert!(
            problem["detail"].as_str().unwrap().contains(field),
            "{problem}"
        );
    }

    // A library's surrogate may be named alone too, and it builds (it was
    // accepted, then failed: "invalid type: string").
    let (status, library) = app
        .call(
            "POST",
            "/api/v1/libraries",
            Some(json!({"case": "cut-in", "surrogate": "idm"})),
        )
        .await;
    assert_eq!(status, StatusCode::ACCEPTED, "{library}");
    let path = format!("/api/v1/libraries/{}", library["id"]);
    let mut library = library;
    for _ in 0..600 {
        if library["status"] != "building" {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
        library = app.call("GET", &path, None).await.1;
    }
    assert_eq!(library["status"], "ready", "{library}");
    assert_eq!(library["surrogate"]["model"], "idm", "{library}");
}

/// The requests that make work claimable wake the lease requests waiting
/// for it (`server/src/work_signal.rs`): a campaign created running, a
/// library turned ready, a worker flagged (its results taken back) wake
/// all; a lease given back wakes one. Other requests wake none.
#[tokio::test]
async fn requests_that_make_work_wake_the_waiting_lease_requests() {
    let app = app(|_| {}).await;
    let announced = || app.state.work.announced();
    assert_eq!(announced(), [0, 0]);
    let id = app.idm_ndd_campaign().await;
    assert_eq!(announced(), [1, 0], "a campaign created running");
    let claim = |worker: &'static str| app.claim_builtin(worker);
    let (_, lease) = claim("w1").await;
    app.call("GET", &format!("/api/v1/campaigns/{id}"), None)
        .await;
    assert_eq!(announced(), [1, 0], "a claim and a read wake none");
    let release = json!({"worker": "w1", "attempt": lease["attempt"], "key": lease["key"],
                         "reason": "shutting down"});
    let (status, _) = app
        .call(
            "POST",
            &format!("/api/v1/leases/{}/release", lease["id"]),
            Some(release),
        )
        .await;
    assert_eq!(status, StatusCode::NO_CONTENT);
    assert_eq!(announced(), [1, 1], "a lease given back");

    // A forged event: the worker is flagged and its results taken back.
    let tests = app.state.samplers.cached(id).expect("built at creation");
    let (_, lease) = claim("forger").await;
    let start = lease["start"].as_u64().unwrap();
    let fake = (start..start + 40).find(|&i| !tests.run(i).event).unwrap();
    let mut forged = quiet_report("forger", &lease);
    forged["events"] = json!([{"index": fake, "weight": 1.0}]);
    let (status, problem) = app
        .call(
            "POST",
            &format!("/api/v1/leases/{}/results", lease["id"]),
            Some(forged),
        )
        .await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{problem}");
    assert_eq!(announced(), [2, 1], "a worker flagged");

    // A library built in the coordinator: ready, and its campaigns run.
    let (status, library) = app
        .call(
            "POST",
            "/api/v1/libraries",
            Some(json!({"case": "cut-in", "surrogate": {"model": "idm"},
                        "search": {"method": "exhaustive"}})),
        )
        .await;
    assert_eq!(status, StatusCode::ACCEPTED, "{library}");
    let path = format!("/api/v1/libraries/{}", library["id"]);
    for _ in 0..600 {
        let (_, library) = app.call("GET", &path, None).await;
        if library["status"] == "ready" {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    let (_, library) = app.call("GET", &path, None).await;
    assert_eq!(library["status"], "ready", "{library}");
    // The builder announces when the write's answer reaches it, which may
    // be just after the status can be read.
    for _ in 0..100 {
        if announced() == [3, 1] {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    assert_eq!(announced(), [3, 1], "a library turned ready");
}

/// A worker whose lease request waited and found nothing is idle (its next
/// wait rechecks at the long ceiling from the start), until a request of
/// it gets a lease; a request that did not wait does not make it idle.
#[tokio::test]
async fn a_wait_that_finds_nothing_marks_its_worker_idle() {
    let app = app(|_| {}).await;
    let ask = |wait: f64| {
        let ask = json!({"worker": "w1", "threads": 1, "max_tests": 40, "wait_seconds": wait});
        app.call("POST", "/api/v1/leases", Some(ask))
    };
    let (status, _) = ask(0.0).await;
    assert_eq!(status, StatusCode::NO_CONTENT);
    assert!(!app.state.workers.idle("w1"), "no wait, not idle");
    let (status, _) = ask(0.2).await;
    assert_eq!(status, StatusCode::NO_CONTENT);
    assert!(app.state.workers.idle("w1"), "a wait that found nothing");
    app.idm_ndd_campaign().await;
    let (status, lease) = ask(0.2).await;
    assert_eq!(status, StatusCode::OK, "{lease}");
    assert!(!app.state.workers.idle("w1"), "a lease");
}

mod identity;

/// A report past its lease's range is refused before any of it is
/// replayed: replaying 2²² tests nobody leased cost the coordinator their
/// CPU, and a mismatch among them flagged the worker for tests that were
/// not its own.
#[tokio::test]
async fn a_report_past_its_lease_is_refused_before_its_replay() {
    let app = app(|c| {
        c.lease_size = Some(40);
        c.replay_share = 1.0;
    })
    .await;
    let id = app.idm_ndd_campaign().await;
    let (_, lease) = app.claim_builtin("w").await;
    let results = format!("/api/v1/leases/{}/results", lease["id"]);
    let mut report = quiet_report("w", &lease);
    let from = lease["resume_at"].as_u64().unwrap();
    report["to"] = json!(from + (1 << 22));
    let (status, problem) = app.call("POST", &results, Some(report)).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{problem}");
    let detail = problem["detail"].as_str().unwrap();
    assert!(
        detail.contains(&format!(
            "range {from}..{} is not inside lease",
            from + (1 << 22)
        )),
        "{detail}"
    );
    // Nothing was replayed, nobody is flagged, and the lease goes on.
    let (_, workers) = app.call("GET", "/api/v1/workers", None).await;
    assert!(workers["workers"][0].get("flagged").is_none(), "{workers}");
    let (_, view) = app
        .call("GET", &format!("/api/v1/campaigns/{id}"), None)
        .await;
    assert_eq!(view["indices"], 0);
    let (status, heartbeat) = app
        .call(
            "POST",
            &format!("/api/v1/leases/{}/heartbeat", lease["id"]),
            Some(json!({"worker": "w", "attempt": lease["attempt"], "key": lease["key"]})),
        )
        .await;
    assert_eq!(status, StatusCode::OK, "{heartbeat}");
}

/// Pages of events across many report rows (more than a batch of the
/// store's read), with small limits, give every event once in order.
#[tokio::test]
async fn event_pages_cross_report_rows_in_order() {
    let app = app(|c| c.lease_size = Some(1000)).await;
    let id = app.idm_ndd_campaign().await;
    let tests = app.state.samplers.cached(id).expect("built at creation");
    let mut all: Vec<u64> = Vec::new();
    for _ in 0..60 {
        let (_, lease) = app.claim("w", 1000).await;
        let (from, to) = (
            lease["start"].as_u64().unwrap(),
            lease["end"].as_u64().unwrap(),
        );
        let events: Vec<u64> = (from..to).filter(|&i| tests.run(i).event).collect();
        all.extend(&events);
        let mut report = quiet_report("w", &lease);
        report["events"] = json!(events
            .iter()
            .map(|i| json!({"index": i, "weight": 1.0}))
            .collect::<Vec<_>>());
        let results = format!("/api/v1/leases/{}/results", lease["id"]);
        let (status, ack) = app.call("POST", &results, Some(report)).await;
        assert_eq!(status, StatusCode::OK, "{ack}");
    }
    let (_, view) = app
        .call("GET", &format!("/api/v1/campaigns/{id}"), None)
        .await;
    let resolved = view["indices"].as_u64().unwrap();
    all.retain(|&i| i < resolved);
    assert!(
        all.len() > 40,
        "{} events: too few to cross rows",
        all.len()
    );
    for limit in [1, 3, 17] {
        let mut paged = Vec::new();
        let mut after: Option<u64> = None;
        loop {
            let query = after.map_or(String::new(), |a| format!("&after={a}"));
            let (status, page) = app
                .call(
                    "GET",
                    &format!("/api/v1/campaigns/{id}/events?limit={limit}{query}"),
                    None,
                )
                .await;
            assert_eq!(status, StatusCode::OK, "{page}");
            let events = page["events"].as_array().unwrap();
            assert!(events.len() <= limit);
            paged.extend(events.iter().map(|e| e["test_index"].as_u64().unwrap()));
            match page["next_after"].as_u64() {
                Some(next) => {
                    assert!(after.is_none_or(|a| next > a), "the cursor moves on");
                    after = Some(next);
                }
                None => break,
            }
        }
        assert_eq!(paged, all, "limit {limit}");
    }
}
mod dodging;
mod queue;

/// A noisy vehicle is a vehicle under test, never a library's surrogate,
/// wherever the library would be built; and `vehicle_noise` marks
/// programs, not built-in vehicles (whose noise the coordinator replays).
#[tokio::test]
async fn noisy_surrogates_and_noise_marks_on_builtin_vehicles_are_refused() {
    for builds in [
        crate::config::BuildPlace::Coordinator,
        crate::config::BuildPlace::Workers,
    ] {
        let app = app(|c| c.library_builds = builds).await;
        let (status, problem) = app
            .call(
                "POST",
                "/api/v1/libraries",
                Some(
                    json!({"case": "cut-in", "surrogate": {"model": "idm", "noise": 1.5},
                            "search": {"method": "exhaustive"}}),
                ),
            )
            .await;
        assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{problem}");
        let detail = problem["detail"].as_str().unwrap();
        assert!(
            detail.contains("surrogate must be deterministic"),
            "{detail}"
        );
    }
    let app = app(|_| {}).await;
    let (status, problem) = app
        .call(
            "POST",
            "/api/v1/campaigns",
            Some(
                json!({"case": "cut-in", "method": "ndd", "vut": {"model": "idm", "noise": 1.5},
                        "vehicle_noise": true}),
            ),
        )
        .await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{problem}");
    assert!(
        problem["detail"]
            .as_str()
            .unwrap()
            .contains("built-in vehicle is deterministic"),
        "{problem}"
    );
    // A noisy built-in vehicle itself is welcome, with its Monte Carlo
    // reference.
    let (status, view) = app
        .call(
            "POST",
            "/api/v1/campaigns",
            Some(json!({"case": "cut-in", "method": "ndd", "vut": {"model": "idm", "noise": 1.5}})),
        )
        .await;
    assert_eq!(status, StatusCode::CREATED, "{view}");
    assert_eq!(
        (&view["vut"]["model"], &view["vut"]["noise"]),
        (&json!("idm"), &json!(1.5))
    );
    assert!(
        view["exact_probability"].as_f64().unwrap() > 1.1e-3,
        "{view}"
    );
}
