//! Access control: admin, worker and read tokens each open only their
//! part of the API; a worker can report only on leases handed to it (the
//! lease key), although all workers share one token; and no token ever
//! reaches the coordinator's or the worker's log, even at debug level.

use crate::support::*;
use reqwest::{Method as Http, StatusCode};
use serde_json::{json, Value};
use sqlx::sqlite::SqliteConnectOptions;
use sqlx::ConnectOptions;
use std::process::{Command, Stdio};
use std::time::Duration;
use tslg_api::{CampaignStatus, LeaseFence, LeaseKey, LeaseRequest, Method, ResultReport};
use tslg_client::{CallError, Client};

const ADMIN: &str = "adm-3e9f1c7a5b2d";
const WORKER: &str = "wrk-8c2a6e4f0b9d";
const READ: &str = "red-1d7b5f3a9c6e";

/// How a request presents a token.
#[derive(Clone, Copy)]
enum Auth {
    None,
    Bearer(&'static str),
    /// HTTP Basic with the token as the password, as a browser sends it.
    Basic(&'static str),
}

async fn send(http: &reqwest::Client, url: &str, method: Http, auth: Auth) -> reqwest::Response {
    let mut request = http.request(method.clone(), url);
    if method == Http::POST {
        request = request.json(&json!({}));
    }
    request = match auth {
        Auth::None => request,
        Auth::Bearer(t) => request.bearer_auth(t),
        Auth::Basic(t) => request.basic_auth("viewer", Some(t)),
    };
    request.send().await.unwrap()
}

/// Asserts a 401 problem that names the role and not the token.
async fn refused(response: reqwest::Response, what: &str) {
    assert_eq!(response.status(), StatusCode::UNAUTHORIZED, "{what}");
    assert_eq!(
        response.headers()["content-type"],
        "application/problem+json"
    );
    let text = response.text().await.unwrap();
    for token in [ADMIN, WORKER, READ] {
        assert!(!text.contains(token), "{what}: {text}");
    }
}

fn start_server(database: &std::path::Path) -> ServerProcess {
    let mut command = Command::new(env!("CARGO_BIN_EXE_tslg-server"));
    command
        .args(["--bind", "127.0.0.1:0", "--lease-size", "200"])
        .arg("--database-url")
        .arg(format!("sqlite://{}", database.display()))
        .env("TSLG_ADMIN_TOKEN", ADMIN)
        .env("TSLG_WORKER_TOKEN", WORKER)
        .env("TSLG_READ_TOKEN", READ)
        .env("RUST_LOG", "debug");
    ServerProcess::spawn(command, database)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tokens_open_only_their_part_of_the_api_and_never_reach_the_logs() {
    let dir = scratch();
    let server = start_server(&dir.path().join("db.sqlite"));
    let http = reqwest::Client::new();
    let url = |path: &str| format!("{}{path}", server.url);
    let admin = Client::new(&server.url, Some(ADMIN.into())).unwrap();
    let library = ready_library(&admin, "idm", true).await;
    let request = campaign(Method::Library, library.id, "idm", 0.2, 5);
    let id = admin.create_campaign(&request).await.unwrap().id;

    // Creating and cancelling: the admin token only.
    for (method, path) in [
        (Http::POST, "/api/v1/libraries".to_owned()),
        (Http::POST, "/api/v1/campaigns".to_owned()),
        (Http::POST, format!("/api/v1/campaigns/{id}/cancel")),
    ] {
        // Not even the admin token as a Basic password: a browser would
        // resend it with a form posted from another site.
        for auth in [
            Auth::None,
            Auth::Bearer(WORKER),
            Auth::Bearer(READ),
            Auth::Basic(READ),
            Auth::Basic(ADMIN),
        ] {
            let what = format!("{method} {path}");
            refused(send(&http, &url(&path), method.clone(), auth).await, &what).await;
        }
    }
    for token in [WORKER, READ] {
        let client = Client::new(&server.url, Some(token.into())).unwrap();
        let refused = client.cancel_campaign(id).await;
        assert!(
            matches!(refused, Err(CallError::Refused { status: 401, .. })),
            "{refused:?}"
        );
    }

    // Reading: the read or admin token, as a bearer token or a browser's
    // Basic password; without it a browser is asked for one.
    let reads = [
        "/api/v1/libraries".to_owned(),
        format!("/api/v1/libraries/{}", library.id),
        "/api/v1/campaigns".to_owned(),
        format!("/api/v1/campaigns/{id}"),
        format!("/api/v1/campaigns/{id}/history"),
        format!("/api/v1/campaigns/{id}/figures/estimate.svg"),
        "/api/v1/workers".to_owned(),
        "/metrics".to_owned(),
        "/".to_owned(),
        format!("/campaigns/{id}"),
        "/assets/dashboard.js".to_owned(),
    ];
    for path in &reads {
        for auth in [Auth::None, Auth::Bearer(WORKER), Auth::Basic(WORKER)] {
            let response = send(&http, &url(path), Http::GET, auth).await;
            assert!(
                response.headers()["www-authenticate"]
                    .to_str()
                    .unwrap()
                    .starts_with("Basic realm="),
                "{path}"
            );
            refused(response, path).await;
        }
        for auth in [
            Auth::Bearer(READ),
            Auth::Basic(READ),
            Auth::Bearer(ADMIN),
            Auth::Basic(ADMIN),
        ] {
            let response = send(&http, &url(path), Http::GET, auth).await;
            assert_eq!(response.status(), StatusCode::OK, "{path}");
        }
    }
    for path in ["/healthz", "/api/v1/openapi.json"] {
        let response = send(&http, &url(path), Http::GET, Auth::None).await;
        assert_eq!(response.status(), StatusCode::OK, "{path} stays open");
    }

    // Working: the worker (or admin) token.
    for (method, path) in [
        (Http::POST, "/api/v1/leases".to_owned()),
        (Http::POST, "/api/v1/workers/w1/leave".to_owned()),
        (Http::GET, format!("/api/v1/campaigns/{id}/plan")),
        (Http::GET, format!("/api/v1/libraries/{}/file", library.id)),
    ] {
        for auth in [
            Auth::None,
            Auth::Bearer(READ),
            Auth::Basic(READ),
            Auth::Basic(WORKER),
        ] {
            let what = format!("{method} {path}");
            refused(send(&http, &url(&path), method.clone(), auth).await, &what).await;
        }
    }

    // A worker reports only on its own lease: "thief" knows the holder's
    // name and attempt and has the same token, but not the lease's key.
    let workers = Client::new(&server.url, Some(WORKER.into())).unwrap();
    let ask = |name: &str| LeaseRequest {
        worker: name.into(),
        threads: 1,
        include_tests: false,
        offers: Vec::new(),
        unhealthy: Vec::new(),
        max_tests: None,
        wait_seconds: None,
        audits_only: false,
        noisy: Vec::new(),
    };
    let lease = workers.claim(&ask("honest")).await.unwrap().unwrap();
    assert_eq!(lease.key.as_str().len(), 32);
    assert_eq!(
        format!("{:?}", lease.key),
        "LeaseKey(…)",
        "Debug hides the key"
    );
    let report = ResultReport {
        next_lease: None,
        near_misses: Vec::new(),
        worker: "honest".into(),
        attempt: lease.attempt,
        key: lease.key.clone(),
        from: lease.start,
        to: lease.start + 50,
        events: real_events(&workers, id, lease.start, lease.start + 50).await,
        packed_events: None,
        invalid: Vec::new(),
        compute_seconds: 0.1,
        threads: 1,
    };
    let forged_key = LeaseKey("0".repeat(32));
    let forged = ResultReport {
        near_misses: Vec::new(),
        key: forged_key.clone(),
        ..report.clone()
    };
    let fence = LeaseFence {
        worker: "honest".into(),
        attempt: lease.attempt,
        key: forged_key,
    };
    let stolen = workers.report(lease.id, &forged).await;
    assert!(forbidden(&stolen), "{stolen:?}");
    let beat = workers.heartbeat(lease.id, &fence).await;
    assert!(forbidden(&beat), "{beat:?}");
    let released = workers.release(lease.id, &fence.release(None)).await;
    assert!(forbidden(&released), "{released:?}");
    assert_eq!(
        admin.campaign(id).await.unwrap().indices,
        0,
        "nothing recorded"
    );
    let ack = workers.report(lease.id, &report).await.unwrap();
    assert_eq!(ack.accepted, 50, "the holder's own report counts");
    // The attempt's key dies with the attempt: released and handed out
    // again, the old key no longer works.
    workers
        .release(
            lease.id,
            &LeaseFence {
                worker: "honest".into(),
                attempt: lease.attempt,
                key: lease.key.clone(),
            }
            .release(Some("done with it".into())),
        )
        .await
        .unwrap();
    let again = workers.claim(&ask("honest")).await.unwrap().unwrap();
    assert_eq!((again.id, again.attempt), (lease.id, lease.attempt + 1));
    assert_ne!(again.key, lease.key);
    admin.cancel_campaign(id).await.unwrap();

    // A real worker with the token runs a campaign to the end, logging at
    // debug level; neither log holds any token.
    let worker_log = dir.path().join("worker.log");
    let mut worker = Command::new(env!("CARGO_BIN_EXE_tslg-worker"))
        .args(["--server", &server.url, "--threads", "1", "--name", "w1"])
        .env("TSLG_WORKER_TOKEN", WORKER)
        .env("RUST_LOG", "debug")
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&worker_log).unwrap())
        .spawn()
        .unwrap();
    let id = admin.create_campaign(&request).await.unwrap().id;
    let view = finished(&admin, id, Duration::from_secs(120)).await;
    let _ = worker.kill();
    let _ = worker.wait();
    assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
    assert_same(&view, &in_process(Some("idm"), &request));
    let worker_log = std::fs::read_to_string(worker_log).unwrap();
    let server_log = server.log();
    assert!(
        server_log.contains("lease"),
        "the coordinator logged requests"
    );
    assert!(
        worker_log.contains("DEBUG"),
        "the worker logged at debug level"
    );
    // Every lease key ever handed out, the worker's included.
    let mut db = SqliteConnectOptions::new()
        .filename(dir.path().join("db.sqlite"))
        .read_only(true)
        .connect()
        .await
        .unwrap();
    let keys: Vec<String> = sqlx::query_scalar("SELECT key FROM leases")
        .fetch_all(&mut db)
        .await
        .unwrap();
    assert!(keys.len() >= 2, "{keys:?}");
    let secrets: Vec<&str> = [ADMIN, WORKER, READ, lease.key.as_str()]
        .into_iter()
        .chain(keys.iter().map(String::as_str))
        .collect();
    for (name, log) in [("coordinator", &server_log), ("worker", &worker_log)] {
        for secret in &secrets {
            assert!(!log.contains(secret), "the {name}'s log holds `{secret}`");
        }
    }
}

/// A 403 for somebody else's lease.
fn forbidden<T>(result: &Result<T, CallError>) -> bool {
    matches!(result, Err(CallError::Refused { status: 403, detail })
        if detail.contains("only the worker it was handed to"))
}

/// The problem a wrong token gets is the same for every role's endpoint
/// family: it says which token is needed, as JSON problem details.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_refusal_names_the_token_it_needs() {
    let dir = scratch();
    let server = start_server(&dir.path().join("db.sqlite"));
    let http = reqwest::Client::new();
    for (method, path, needs) in [
        (Http::POST, "/api/v1/campaigns", "the admin token"),
        (Http::POST, "/api/v1/leases", "the worker token"),
        (Http::GET, "/api/v1/campaigns", "the read token"),
    ] {
        let response = send(
            &http,
            &format!("{}{path}", server.url),
            method,
            Auth::Bearer("wrong"),
        )
        .await;
        assert_eq!(response.status(), StatusCode::UNAUTHORIZED);
        let problem: Value = response.json().await.unwrap();
        assert!(
            problem["detail"].as_str().unwrap().contains(needs),
            "{path}: {problem}"
        );
    }
    // The CLI says which flag gives a token, and where it looked for a
    // coordinator that does not answer.
    let url = server.url.clone();
    let refused = tokio::task::spawn_blocking(move || {
        tslg(&["campaign", "list", "--server", &url, "--token", "wrong"])
    })
    .await
    .unwrap();
    assert!(!refused.status.success());
    let text = String::from_utf8_lossy(&refused.stderr);
    assert!(
        text.contains("the read token") && text.contains("--token or TSLG_ADMIN_TOKEN"),
        "{text}"
    );
    let closed = free_port_url();
    let unreachable =
        tokio::task::spawn_blocking(move || tslg(&["campaign", "list", "--server", &closed]))
            .await
            .unwrap();
    assert!(!unreachable.status.success());
    let text = String::from_utf8_lossy(&unreachable.stderr);
    assert!(
        text.contains("cannot connect to the coordinator at http://127.0.0.1:")
            && text.contains("is it running there?"),
        "{text}"
    );
}

/// The URL of a port nothing listens on (bound, then let go).
fn free_port_url() -> String {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    format!("http://127.0.0.1:{}", listener.local_addr().unwrap().port())
}

#[test]
fn a_worker_or_read_token_without_an_admin_token_is_refused_at_start() {
    for variable in ["TSLG_WORKER_TOKEN", "TSLG_READ_TOKEN"] {
        let output = Command::new(env!("CARGO_BIN_EXE_tslg-server"))
            .args(["--bind", "127.0.0.1:0", "--database-url", "sqlite::memory:"])
            .env(variable, "some-token")
            .env_remove("TSLG_ADMIN_TOKEN")
            .output()
            .unwrap();
        assert!(clean_refusal(&output), "{variable}");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(stderr.contains("set TSLG_ADMIN_TOKEN too"), "{stderr}");
        assert!(!stderr.contains("some-token"), "{stderr}");
    }
}
