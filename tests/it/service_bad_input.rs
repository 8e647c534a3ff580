//! Bad input on every endpoint the OpenAPI document lists: malformed JSON,
//! wrong types, unknown fields, out-of-range numbers, bodies over the limit,
//! unknown and malformed ids, and methods the path does not take. Each gets
//! a 4xx `application/problem+json` with a detail, and the coordinator keeps
//! serving. (scripts/fuzz-api fuzzes the same document with schemathesis.)

use crate::support::*;
use reqwest::{Method as Http, StatusCode};
use serde_json::{json, Value};
use tslg_api::Method;

/// Sends `body` (raw text, as JSON) and returns status and problem.
async fn send(
    http: &reqwest::Client,
    method: Http,
    url: &str,
    body: Option<&str>,
) -> (StatusCode, Value) {
    let mut request = http.request(method.clone(), url);
    if let Some(body) = body {
        request = request
            .header("content-type", "application/json")
            .body(body.to_owned());
    }
    let response = request.send().await.unwrap();
    let status = response.status();
    let content_type = response
        .headers()
        .get("content-type")
        .map(|v| v.to_str().unwrap().to_owned());
    let problem: Value = response.json().await.unwrap_or(Value::Null);
    assert_eq!(
        content_type.as_deref(),
        Some("application/problem+json"),
        "{method} {url} {body:?} → {status} {problem}"
    );
    assert_eq!(problem["status"], json!(status.as_u16()), "{method} {url}");
    assert!(
        !problem["detail"].as_str().unwrap_or_default().is_empty(),
        "{method} {url}: {problem}"
    );
    (status, problem)
}

/// Posts `size` bytes of JSON with `Transfer-Encoding: chunked` over a raw
/// connection (no `Content-Length`), returning the response's head.
async fn chunked_post(address: &str, path: &str, size: usize) -> String {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut stream = tokio::net::TcpStream::connect(address).await.unwrap();
    let body = format!("{{\"pad\": \"{}\"}}", "x".repeat(size));
    let head = format!(
        "POST {path} HTTP/1.1\r\nHost: {address}\r\ncontent-type: application/json\r\n\
         transfer-encoding: chunked\r\nconnection: close\r\n\r\n"
    );
    stream.write_all(head.as_bytes()).await.unwrap();
    for piece in body.as_bytes().chunks(1000) {
        let chunk = format!("{:x}\r\n", piece.len());
        // The server may answer and close before the whole body is sent.
        if stream.write_all(chunk.as_bytes()).await.is_err()
            || stream.write_all(piece).await.is_err()
            || stream.write_all(b"\r\n").await.is_err()
        {
            break;
        }
    }
    let _ = stream.write_all(b"0\r\n\r\n").await;
    let mut answer = Vec::new();
    let _ = stream.read_to_end(&mut answer).await;
    String::from_utf8_lossy(&answer).into_owned()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_endpoint_answers_bad_input_with_a_problem_and_keeps_serving() {
    let dir = scratch();
    let limit = 4096;
    let server = ServerProcess::start(
        &dir.path().join("db.sqlite"),
        &["--max-body-bytes", &limit.to_string()],
    );
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let id = client
        .create_campaign(&campaign(Method::Library, library.id, "idm", 0.01, 1))
        .await
        .unwrap()
        .id;
    let http = reqwest::Client::new();
    let get = |path: &str| {
        let request = http.get(format!("{}{path}", server.url));
        async move { request.send().await.unwrap().json::<Value>().await.unwrap() }
    };
    let doc = get("/api/v1/openapi.json").await;
    let paths = doc["paths"].as_object().unwrap();
    assert!(paths.len() >= 17, "{} paths", paths.len());
    let huge = format!("{{\"pad\": \"{}\"}}", "x".repeat(limit));
    let mut checked = 0;
    for (template, item) in paths {
        // Other path parameters take a valid value (a test index).
        let url = |id: &str| {
            let path = template.replace("{id}", id).replace("{index}", "0");
            format!("{}{path}", server.url)
        };
        let methods: Vec<Http> = item
            .as_object()
            .unwrap()
            .keys()
            .map(|m| m.to_uppercase().parse().unwrap())
            .collect();
        let existing = if template.starts_with("/api/v1/libraries") {
            library.id
        } else {
            id
        };
        let good = url(&existing.to_string());
        for method in [Http::GET, Http::POST, Http::PUT, Http::DELETE, Http::PATCH] {
            if !methods.contains(&method) {
                let (status, _) = send(&http, method.clone(), &good, None).await;
                assert_eq!(
                    status,
                    StatusCode::METHOD_NOT_ALLOWED,
                    "{method} {template}"
                );
                checked += 1;
            }
        }
        for method in methods {
            // A body over the limit, on every operation.
            let (status, _) = send(&http, method.clone(), &good, Some(&huge)).await;
            assert_eq!(status, StatusCode::PAYLOAD_TOO_LARGE, "{method} {template}");
            if template.contains("{id}") {
                for bad in ["abc", "1.5", "-", "99999999999999999999"] {
                    let (status, _) = send(&http, method.clone(), &url(bad), None).await;
                    assert_eq!(status, StatusCode::BAD_REQUEST, "{method} {template} {bad}");
                }
                if method == Http::GET {
                    let (status, _) = send(&http, method.clone(), &url("999999"), None).await;
                    assert_eq!(status, StatusCode::NOT_FOUND, "{template}");
                }
            }
            checked += 1;
            if method != Http::POST || !item["post"]["requestBody"].is_object() {
                continue;
            }
            // Bodies: malformed, the wrong type, an empty object.
            for (body, expected) in [
                ("{", StatusCode::BAD_REQUEST),
                ("", StatusCode::BAD_REQUEST),
                ("[]", StatusCode::UNPROCESSABLE_ENTITY),
                ("\"text\"", StatusCode::UNPROCESSABLE_ENTITY),
                ("{}", StatusCode::UNPROCESSABLE_ENTITY),
            ] {
                let (status, _) = send(&http, Http::POST, &good, Some(body)).await;
                assert_eq!(status, expected, "POST {template} {body:?}");
            }
        }
    }
    assert!(checked > 60, "{checked} checks");

    // Out-of-range numbers and wrong types in otherwise good bodies.
    let lease = |body: Value| (Http::POST, "/api/v1/leases".to_owned(), body);
    let fence = json!({"worker": "w", "attempt": 1, "key": "k"});
    let report = json!({"worker": "w", "attempt": 1, "key": "k", "from": 0, "to": 10});
    let with = |mut v: Value, key: &str, value: Value| {
        v[key] = value;
        v
    };
    for (method, path, body) in [
        lease(json!({"worker": "w", "threads": 0})),
        lease(json!({"worker": "w", "threads": 5000})),
        lease(json!({"worker": "w", "threads": -1})),
        lease(json!({"worker": "w", "threads": "two"})),
        lease(json!({"worker": "x".repeat(200), "threads": 1})),
        lease(json!({"worker": "w", "threads": 1, "offers": ["no-colons"]})),
        (
            Http::POST,
            "/api/v1/campaigns".to_owned(),
            json!({"case": "cut-in", "method": "ndd", "vut": {"model": "idm"},
                   "max_tests": 10, "beta": 1e308}),
        ),
        (
            Http::POST,
            "/api/v1/campaigns".to_owned(),
            json!({"case": "cut-in", "method": "ndd", "vut": {"model": "idm"},
                   "max_tests": 1u64 << 60}),
        ),
        (
            Http::POST,
            "/api/v1/leases/1/heartbeat".to_owned(),
            with(fence.clone(), "attempt", json!("one")),
        ),
        (
            Http::POST,
            "/api/v1/leases/1/results".to_owned(),
            with(report.clone(), "to", json!(0)),
        ),
        (
            Http::POST,
            "/api/v1/leases/1/results".to_owned(),
            with(
                report.clone(),
                "events",
                json!([{"index": 3, "weight": -1.0}]),
            ),
        ),
        (
            Http::POST,
            "/api/v1/leases/1/results".to_owned(),
            with(
                report.clone(),
                "events",
                json!([{"index": 99, "weight": 1.0}]),
            ),
        ),
    ] {
        let (status, problem) = send(
            &http,
            method,
            &format!("{}{path}", server.url),
            Some(&body.to_string()),
        )
        .await;
        assert_eq!(
            status,
            StatusCode::UNPROCESSABLE_ENTITY,
            "{path} {body} → {problem}"
        );
    }
    // Unknown fields in otherwise good bodies of every operation that takes
    // a body (cancel takes none): refused by name, not ignored.
    let extra = |mut v: Value| {
        v["colour"] = json!("blue");
        v
    };
    for (path, body) in [
        (
            "/api/v1/libraries".to_owned(),
            json!({"case": "cut-in", "surrogate": {"model": "idm"}}),
        ),
        (
            "/api/v1/campaigns".to_owned(),
            json!({"case": "cut-in", "method": "ndd",
                                                "vut": {"model": "idm"}, "max_tests": 10}),
        ),
        (
            "/api/v1/leases".to_owned(),
            json!({"worker": "w", "threads": 1}),
        ),
        ("/api/v1/leases/1/heartbeat".to_owned(), fence.clone()),
        ("/api/v1/leases/1/release".to_owned(), fence.clone()),
        ("/api/v1/leases/1/results".to_owned(), report.clone()),
    ] {
        let url = format!("{}{path}", server.url);
        let (status, problem) = send(&http, Http::POST, &url, Some(&extra(body).to_string())).await;
        assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{path}");
        assert!(
            problem["detail"]
                .as_str()
                .unwrap()
                .contains("unknown field `colour`"),
            "{path}: {problem}"
        );
    }
    // A body over the limit without a declared length (chunked) is cut at
    // the limit by the JSON reader.
    let chunked = chunked_post(&server.address, "/api/v1/campaigns", limit + 100).await;
    assert!(chunked.starts_with("HTTP/1.1 413"), "{chunked}");
    assert!(chunked.contains("application/problem+json"), "{chunked}");

    // Unknown ids in good requests of a registered worker.
    client.register("w").await.unwrap();
    let http = worker_http(&client, "w");
    for (path, body) in [
        ("/api/v1/campaigns/999999/cancel", json!({})),
        ("/api/v1/leases/999999/heartbeat", fence.clone()),
        ("/api/v1/leases/999999/release", fence),
        ("/api/v1/leases/999999/results", report),
    ] {
        let (status, _) = send(
            &http,
            Http::POST,
            &format!("{}{path}", server.url),
            Some(&body.to_string()),
        )
        .await;
        assert_eq!(status, StatusCode::NOT_FOUND, "{path}");
    }
    for query in [
        "points=0",
        "points=100000",
        "points=-1",
        "points=many",
        "zzz=1",
    ] {
        let url = format!("{}/api/v1/campaigns/{id}/history?{query}", server.url);
        let (status, _) = send(&http, Http::GET, &url, None).await;
        assert_eq!(status, StatusCode::BAD_REQUEST, "{query}");
    }

    // Still serving, and nothing was created or changed by the bad input.
    let health = http
        .get(format!("{}/healthz", server.url))
        .send()
        .await
        .unwrap();
    assert_eq!(health.status(), StatusCode::OK);
    let view = client.campaign(id).await.unwrap();
    assert_eq!((view.indices, view.status.is_final()), (0, false));
    let list = get("/api/v1/campaigns").await;
    assert_eq!(list["campaigns"].as_array().unwrap().len(), 1, "{list}");
    assert!(!server.log().contains("panicked"));
}

/// A coordinator whose database cannot be written answers `/healthz` with
/// 503 and says why (it answered 200 while every write failed), and 200
/// again once it can. Another process holding the write lock is the
/// failure here: reads still work (write-ahead log), every write waits out
/// the busy timeout and fails.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn healthz_reports_a_database_that_cannot_be_written() {
    use sqlx::{ConnectOptions, Connection};
    let dir = scratch();
    let database = dir.path().join("db.sqlite");
    let server = ServerProcess::start(&database, &[]);
    let http = reqwest::Client::new();
    let health = || async {
        let response = http
            .get(format!("{}/healthz", server.url))
            .send()
            .await
            .unwrap();
        (response.status(), response.text().await.unwrap())
    };
    assert_eq!(health().await.0, StatusCode::OK);
    let mut locker = sqlx::sqlite::SqliteConnectOptions::new()
        .filename(&database)
        .connect()
        .await
        .unwrap();
    sqlx::query("BEGIN IMMEDIATE")
        .execute(&mut locker)
        .await
        .unwrap();
    let (status, body) = health().await;
    assert_eq!(status, StatusCode::SERVICE_UNAVAILABLE, "{body}");
    assert!(body.contains("the database cannot be written"), "{body}");
    sqlx::query("ROLLBACK").execute(&mut locker).await.unwrap();
    locker.close().await.unwrap();
    assert_eq!(health().await.0, StatusCode::OK);
    assert!(!server.log().contains("panicked"));
}
