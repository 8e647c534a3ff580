//! What a hostile or unlucky client sends cannot hang, stall or fool the
//! coordinator (issue 20): numbers outside the method's ranges are refused
//! with a precise problem, figures draw whatever is stored, over-long URLs
//! get a problem like every other error, reported effort is bounded by the
//! lease's age, and a worker that is refused gives its lease back at once
//! and says why.

use crate::support::*;
use reqwest::StatusCode;
use serde_json::{json, Value};
use sqlx::Connection;
use std::path::Path;
use std::time::{Duration, Instant};
use tslg_api::{Method, ResultReport};
use tslg_client::CallError;

/// Posts `body` and returns the status and the problem's detail.
async fn post(url: &str, body: &Value) -> (StatusCode, String) {
    let response = reqwest::Client::new()
        .post(url)
        .json(body)
        .send()
        .await
        .unwrap();
    let status = response.status();
    let problem: Value = response.json().await.unwrap_or(Value::Null);
    (status, problem["detail"].as_str().unwrap_or("").to_owned())
}

async fn database(path: &Path) -> sqlx::SqliteConnection {
    sqlx::SqliteConnection::connect(&format!("sqlite://{}", path.display()))
        .await
        .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_number_is_held_to_the_methods_range_and_stored_nonsense_cannot_hang_a_figure() {
    let dir = scratch();
    let path = dir.path().join("db.sqlite");
    let server = ServerProcess::start(&path, &[]);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let campaigns = format!("{}/api/v1/campaigns", server.url);
    let good = json!({"case": "cut-in", "method": "library", "library_id": library.id,
                      "vut": {"model": "idm"}, "max_tests": 100000, "beta": 0.2});
    let with = |key: &str, value: Value| {
        let mut body = good.clone();
        body[key] = value;
        body
    };
    for (body, expected) in [
        (
            with("beta", json!(1e-310)),
            "beta = 1e-310 must be in [0.0001, 0.99]",
        ),
        (with("beta", json!(0.995)), "beta = 0.995 must be in"),
        (
            with("epsilon", json!(1e-310)),
            "must be 0 or in [0.000001, 0.999]",
        ),
        (with("epsilon", json!(0.9999)), "must be 0 or in"),
        (
            with("confidence", json!(0.9999999)),
            "confidence = 0.9999999 must be in",
        ),
        (
            with("confidence", json!(0.3)),
            "confidence = 0.3 must be in",
        ),
        (
            with("min_events", json!(0)),
            "min_events = 0 must be in 1..=1000000",
        ),
        (
            with("min_events", json!(10_000_000)),
            "min_events = 10000000 must be in",
        ),
        (
            with("n_min", json!(0)),
            "n_min = 0 must be in 1..=max_tests",
        ),
        (
            with("n_min", json!(200_000)),
            "n_min = 200000 must be in 1..=max_tests",
        ),
        (
            with("max_tests", json!(1u64 << 51)),
            "max_tests = 2251799813685248 must be in",
        ),
        (with("max_tests", json!(0)), "max_tests = 0 must be in"),
        (
            with("vut", json!({"model": "idm", "v0": 1e-310})),
            "`v0` = 1e-310 must be 0 or between",
        ),
        (
            with("vut", json!({"model": "idm", "v0": 1e300})),
            "`v0` = 1e300 must be 0 or between",
        ),
        (
            with("vut", json!({"model": "fvdm", "k": -1.0})),
            "`k` = -1 must be > 0",
        ),
        (
            with("case", json!("cut\u{0}in")),
            "case must be 1 to 64 bytes without control characters",
        ),
        (
            with("case", json!("x".repeat(100))),
            "case must be 1 to 64 bytes",
        ),
    ] {
        let (status, detail) = post(&campaigns, &body).await;
        assert_eq!(
            status,
            StatusCode::UNPROCESSABLE_ENTITY,
            "{body} → {detail}"
        );
        assert!(
            detail.contains(expected),
            "{body}: `{detail}` lacks `{expected}`"
        );
    }
    let libraries = format!("{}/api/v1/libraries", server.url);
    for (body, expected) in [
        (
            json!({"case": "cut-in", "surrogate": {"model": "idm"},
                   "threshold": {"kind": "relative", "m": 1e-310}}),
            "m = 1e-310 must be in [1e-6, 1e6]",
        ),
        (
            json!({"case": "cut-in", "surrogate": {"model": "idm"},
                   "threshold": {"kind": "absolute", "gamma": 2.0}}),
            "γ = 2 must be in [0, 1]",
        ),
        (
            json!({"case": "car-following", "surrogate": {"model": "idm"},
                   "search": {"method": "temporal-difference", "alpha": 1e-300}}),
            "alpha = 1e-300 must be in [0.001, 1]",
        ),
        (
            json!({"case": "cut-in", "surrogate": {"model": "switching-acc", "ts": 1e-320}}),
            "`ts` = 1e-320 must be 0 or between",
        ),
        (
            json!({"case": "cut-in", "preset": "p\u{1b}[31m", "surrogate": {"model": "idm"}}),
            "preset must be 1 to 64 bytes without control characters",
        ),
        (
            json!({"case": "cut-in", "surrogate": {"model": "idm"},
                   "exposure": {"kind": "table", "name": "n".repeat(300), "text": "1"}}),
            "exposure.name must be 1 to 256 bytes",
        ),
    ] {
        let (status, detail) = post(&libraries, &body).await;
        assert_eq!(
            status,
            StatusCode::UNPROCESSABLE_ENTITY,
            "{body} → {detail}"
        );
        assert!(
            detail.contains(expected),
            "{body}: `{detail}` lacks `{expected}`"
        );
    }

    // A campaign with history, then a β no request may give written
    // straight into the database (an older release, a hand edit): its
    // figures still answer, and so does everything else.
    let id = client
        .create_campaign(&campaign(Method::Ndd, library.id, "idm", 0.2, 1))
        .await
        .unwrap()
        .id;
    let _worker = WorkerProcess::start(&server.url, 1, "w1");
    wait_for(&client, id, Duration::from_secs(60), |v| v.indices > 1000).await;
    let mut db = database(&path).await;
    sqlx::query("UPDATE campaigns SET beta = 1e-310, s1 = 1e-320, s2 = 1e308 WHERE id = ?")
        .bind(id)
        .execute(&mut db)
        .await
        .unwrap();
    let http = reqwest::Client::builder()
        .timeout(Duration::from_secs(20))
        .build()
        .unwrap();
    for figure in ["relative-half-width", "estimate"] {
        for _ in 0..2 {
            let response = http
                .get(format!(
                    "{}/api/v1/campaigns/{id}/figures/{figure}.svg",
                    server.url
                ))
                .send()
                .await
                .unwrap_or_else(|e| panic!("the {figure} figure does not answer: {e}"));
            assert_eq!(response.status(), StatusCode::OK, "{figure}");
            let svg = response.text().await.unwrap();
            roxmltree::Document::parse(&svg).expect("the figure is XML");
        }
    }
    let health = http
        .get(format!("{}/healthz", server.url))
        .send()
        .await
        .unwrap();
    assert_eq!(health.status(), StatusCode::OK);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_overlong_url_is_refused_with_a_problem_at_every_length() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let http = reqwest::Client::new();
    // 10 kB: the router's limit; 70 kB: past what hyper parses at all (and
    // what an HTTP client library would send, so over a raw connection).
    for length in [10_000, 70_000] {
        let head = format!(
            "GET /api/v1/campaigns/{} HTTP/1.1\r\nhost: {}\r\nconnection: close\r\n\r\n",
            "9".repeat(length),
            server.address
        );
        let answer = raw(&server.address, head.as_bytes()).await;
        assert!(answer.starts_with("HTTP/1.1 414"), "{length}: {answer}");
        let (head, body) = answer.split_once("\r\n\r\n").unwrap();
        assert!(
            head.to_ascii_lowercase()
                .contains("content-type: application/problem+json"),
            "{length}: {head}"
        );
        let problem: Value = serde_json::from_str(body).unwrap();
        assert_eq!(problem["status"], 414, "{problem}");
        assert!(!problem["detail"].as_str().unwrap().is_empty());
    }
    // A head hyper cannot parse at all: a 400 with a problem too.
    let answer = raw(
        &server.address,
        b"GET /healthz HTTP/1.1\r\nbad header\r\n\r\n",
    )
    .await;
    assert!(answer.starts_with("HTTP/1.1 400"), "{answer}");
    assert!(answer.contains("application/problem+json"), "{answer}");
    // And the coordinator serves on.
    let health = http
        .get(format!("{}/healthz", server.url))
        .send()
        .await
        .unwrap();
    assert_eq!(health.status(), StatusCode::OK);
}

/// Sends `bytes` over a fresh connection and returns all it answers.
async fn raw(address: &str, bytes: &[u8]) -> String {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut stream = tokio::net::TcpStream::connect(address).await.unwrap();
    // The server may answer and close before taking everything.
    let _ = stream.write_all(bytes).await;
    let mut answer = Vec::new();
    let _ = stream.read_to_end(&mut answer).await;
    String::from_utf8_lossy(&answer).into_owned()
}

fn effort(lease: &tslg_api::Lease, worker: &str, seconds: f64, threads: u32) -> ResultReport {
    ResultReport {
        next_lease: None,
        near_misses: Vec::new(),
        worker: worker.into(),
        attempt: lease.attempt,
        key: lease.key.clone(),
        from: lease.resume_at,
        to: lease.resume_at + 10,
        events: Vec::new(),
        packed_events: None,
        invalid: Vec::new(),
        compute_seconds: seconds,
        threads,
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn reported_effort_cannot_exceed_the_leases_age_nor_seize_the_fair_share() {
    let dir = scratch();
    let path = dir.path().join("db.sqlite");
    let server = ServerProcess::start(&path, &["--lease-size", "100"]);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let long = |method| {
        let mut request = campaign(method, library.id, "idm", 0.001, 5);
        request.max_tests = 1 << 50;
        request
    };
    let a = client.create_campaign(&long(Method::Ndd)).await.unwrap().id;
    let lease = claim(&client, "w").await.unwrap();
    for (seconds, threads, expected) in [
        (1e300, 1, "compute_seconds = 1e300 must be in [0, 86400]"),
        (f64::MAX, 1, "must be in [0, 86400]"),
        (-1.0, 1, "must be in [0, 86400]"),
        (3600.0, 1, "exceeds the"),
        (0.1, 2, "threads = 2 exceeds the 1 threads"),
        (0.1, 0, "threads = 0 must be in 1..=4096"),
    ] {
        let refused = client
            .report(lease.id, &effort(&lease, "w", seconds, threads))
            .await;
        match refused {
            Err(CallError::Refused {
                status: 422,
                detail,
            }) => {
                assert!(
                    detail.contains(expected),
                    "{seconds}: `{detail}` lacks `{expected}`"
                )
            }
            other => panic!("{seconds} s on {threads} threads: {other:?}"),
        }
    }
    let ack = client
        .report(lease.id, &effort(&lease, "w", 0.01, 1))
        .await
        .unwrap();
    assert_eq!(ack.accepted, 10);

    // Whatever cost is stored (a database from before the checks), a
    // campaign's turn never wraps around to take every lease.
    let b = client
        .create_campaign(&long(Method::Library))
        .await
        .unwrap()
        .id;
    let mut db = database(&path).await;
    sqlx::query("UPDATE campaigns SET cost_per_test = 1e300 WHERE id = ?")
        .bind(a)
        .execute(&mut db)
        .await
        .unwrap();
    let mut to_a = 0;
    for k in 0..40 {
        let lease = claim(&client, &format!("fair-{k}")).await.unwrap();
        to_a += u32::from(lease.campaign_id == a);
    }
    assert!(
        to_a <= 2,
        "the campaign with an absurd cost took {to_a} of 40 leases"
    );
    for id in [a, b] {
        client.cancel_campaign(id).await.unwrap();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_refused_worker_gives_its_lease_back_at_once_and_says_why() {
    let dir = scratch();
    let path = dir.path().join("db.sqlite");
    // A body limit too small for the reports of a campaign with many events.
    let server = ServerProcess::start(
        &path,
        &["--max-body-bytes", "3000", "--lease-ttl-seconds", "600"],
    );
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let id = client
        .create_campaign(&campaign(Method::Library, library.id, "fvdm", 0.01, 2))
        .await
        .unwrap()
        .id;
    let worker = WorkerProcess::start(&server.url, 1, "refused");
    let started = Instant::now();
    let reason = loop {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "never released"
        );
        let workers = client.workers().await.unwrap();
        let said = workers
            .workers
            .iter()
            .find(|w| w.name == "refused")
            .and_then(|w| w.last_release_reason.clone());
        if let Some(reason) = said {
            break reason;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    assert!(reason.contains("report refused (413)"), "{reason}");
    drop(worker);
    // With a TTL of ten minutes, only a release can have handed a lease out
    // again within these seconds (to the refused worker again, or now to
    // another).
    claim(&client, "other").await.unwrap();
    let mut db = database(&path).await;
    let (attempt,): (i64,) =
        sqlx::query_as("SELECT MAX(attempt) FROM leases WHERE campaign_id = ?")
            .bind(id)
            .fetch_one(&mut db)
            .await
            .unwrap();
    assert!(
        attempt >= 2,
        "the refused lease was handed out {attempt} times"
    );
    assert!(server.log_line(|l| l.contains("lease released")).is_some());
    client.cancel_campaign(id).await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn oversized_reports_are_refused_and_a_high_event_campaign_runs_through() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &["--lease-size", "100000"]);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    // FVDM tested with the IDM library: about 91 % of its tests are events.
    let request = campaign(Method::Library, library.id, "fvdm", 0.02, 4);
    let id = client.create_campaign(&request).await.unwrap().id;
    let lease = client
        .claim(&tslg_api::LeaseRequest {
            worker: "big".into(),
            threads: 1,
            include_tests: false,
            offers: Vec::new(),
            unhealthy: Vec::new(),
            max_tests: Some(70_000),
            wait_seconds: None,
            audits_only: false,
            noisy: Vec::new(),
        })
        .await
        .unwrap()
        .unwrap();
    assert_eq!(
        lease.end - lease.start,
        70_000,
        "the worker's cap is the size"
    );
    let mut report = effort(&lease, "big", 0.0, 1);
    report.to = lease.end;
    report.events = (lease.start..lease.end)
        .map(|index| tslg_api::EventResult { index, weight: 1.0 })
        .collect();
    match client.report(lease.id, &report).await {
        Err(CallError::Refused {
            status: 422,
            detail,
        }) => assert!(
            detail.contains("at most 65536 per report: report the range in parts"),
            "{detail}"
        ),
        other => panic!("{other:?}"),
    }
    client
        .release(
            lease.id,
            &tslg_api::LeaseFence {
                worker: "big".into(),
                attempt: lease.attempt,
                key: lease.key.clone(),
            }
            .release(Some("testing".into())),
        )
        .await
        .unwrap();
    // A real worker splits its chunks and the campaign ends as in process.
    let _worker = WorkerProcess::start(&server.url, 2, "w");
    let view = finished(&client, id, Duration::from_secs(600)).await;
    assert!(
        view.events * 10 > view.tests * 8,
        "a high-event campaign: {view:?}"
    );
    assert_same(&view, &in_process(Some("idm"), &request));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_cause_of_an_internal_error_is_logged_and_never_sent() {
    let dir = scratch();
    let path = dir.path().join("db.sqlite");
    let server = ServerProcess::start(&path, &["--lease-size", "100"]);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let id = client
        .create_campaign(&campaign(Method::Library, library.id, "idm", 0.01, 3))
        .await
        .unwrap()
        .id;
    // Two leases; the second is reported first, so its events wait beyond
    // the frontier, and then its stored row is damaged on disk.
    let first = claim(&client, "w").await.unwrap();
    let second = claim(&client, "w").await.unwrap();
    let mut report = effort(&second, "w", 0.0, 1);
    report.to = second.end;
    report.events = real_events(&client, id, second.start, second.end).await;
    assert!(!report.events.is_empty());
    client.report(second.id, &report).await.unwrap();
    let mut db = database(&path).await;
    sqlx::query("UPDATE reports SET packed = x'07' WHERE campaign_id = ? AND from_index = ?")
        .bind(id)
        .bind(second.start as i64)
        .execute(&mut db)
        .await
        .unwrap();
    // Reporting the first lease folds through the damaged row: a 500 whose
    // body says only where the cause is, and whose cause is in the log.
    let mut report = effort(&first, "w", 0.0, 1);
    report.to = first.end;
    report.events = real_events(&client, id, first.start, first.end).await;
    let response = worker_http(&client, "w")
        .post(format!("{}/api/v1/leases/{}/results", server.url, first.id))
        .json(&report)
        .send()
        .await
        .unwrap();
    assert_eq!(response.status(), StatusCode::INTERNAL_SERVER_ERROR);
    let problem: Value = response.json().await.unwrap();
    assert_eq!(
        problem["detail"],
        "internal error; the cause is in the coordinator's log"
    );
    let line = server
        .log_line(|l| l.contains("internal error") && l.contains("/results"))
        .unwrap_or_else(|| panic!("no cause logged: {}", server.log()));
    assert!(line.contains("method=POST"), "{line}");
    assert!(
        line.contains("is damaged: packed events: unknown tag 7"),
        "{line}"
    );
}
