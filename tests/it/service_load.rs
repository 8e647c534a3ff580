//! Load: 64 concurrent simulated workers (`tslg load-test`) against one
//! coordinator, for a fixed number of requests within a time limit. No
//! request fails, the SQLite file is never "locked", and the books balance:
//! the resolved prefix is exactly the tests acknowledged, and its estimate
//! is bit for bit the in-process estimate of that many tests. Leases and
//! reports share commits (group commit).

use crate::support::*;
use serde_json::Value;
use std::process::Command;
use tslg_api::{CampaignStatus, Method};

/// Runs `tslg load-test --json` against `url` with `extra` arguments.
fn load_test(url: &str, extra: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_tslg"))
        .args(["load-test", "--server", url, "--json"])
        .args(extra)
        .output()
        .unwrap()
}

/// The report of a load test that must succeed.
fn successful(output: &std::process::Output) -> Value {
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_str(&stdout).unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sixty_four_concurrent_workers_lose_and_double_nothing() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &["--lease-size", "100"]);
    let (workers, rounds) = (64, 10);
    let requests = (workers * rounds) as u64;
    // Reports that take the next lease (the default), then a request per
    // lease and per report.
    for (extra, claims) in [
        (None, workers as u64),
        (Some("--separate-claims"), requests),
    ] {
        let (groups_before, grouped_before) = (
            scraped(&server.url, "tslg_write_groups_total").await,
            scraped(&server.url, "tslg_grouped_writes_total").await,
        );
        let (workers_arg, rounds_arg) = (workers.to_string(), rounds.to_string());
        let mut args = vec!["--workers", &workers_arg, "--requests", &rounds_arg];
        args.extend(["--time-limit", "120"]);
        args.extend(extra);
        let report = successful(&load_test(&server.url, &args));
        assert_eq!(report["separate_claims"], extra.is_some());
        assert_eq!(report["lease_ms"]["count"], claims);
        assert_eq!(report["result_ms"]["count"], requests);
        assert_eq!(report["errors"].as_array().unwrap().len(), 0);
        assert_eq!(report["accepted_tests"], requests * 100);
        assert_eq!(report["campaign_tests"], requests * 100);
        assert_eq!(report["reported_events"], report["campaign_events"]);
        assert!(report["lease_ms"]["p99"].as_f64().unwrap() > 0.0);
        assert!(report["round_trips_per_second"].as_f64().unwrap() > 0.0);

        let client = server.client();
        let id = report["campaign_id"].as_i64().unwrap();
        let view = client.campaign(id).await.unwrap();
        assert_eq!(view.status, CampaignStatus::Cancelled);
        let mut request = campaign(Method::Ndd, 0, "idm", tslg_method::estimator::MIN_BETA, 1);
        request.library_id = None;
        request.max_tests = requests * 100;
        assert_same(&view, &in_process(None, &request));
        // Every lease and report was committed in a group, and with 64
        // workers at once groups held several requests (group commit).
        let (groups, grouped) = (
            scraped(&server.url, "tslg_write_groups_total").await - groups_before,
            scraped(&server.url, "tslg_grouped_writes_total").await - grouped_before,
        );
        assert!(
            grouped >= (claims + requests) as f64,
            "{grouped} grouped writes"
        );
        assert!(
            groups < grouped,
            "{groups} commits for {grouped} requests: none shared a commit"
        );
        // The load test reports the same counters over its run.
        let commits = &report["commits"];
        assert!(
            commits["requests"].as_u64().unwrap() >= claims + requests,
            "{commits}"
        );
        assert!(
            commits["transactions"].as_u64().unwrap() < commits["requests"].as_u64().unwrap(),
            "{commits}"
        );
    }
    let log = server.log();
    assert!(!log.contains("database is locked"), "{log}");
    assert!(!log.contains("panicked"), "{log}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_load_test_works_against_a_default_coordinator_and_always_cleans_up() {
    let dir = scratch();
    // Adaptive lease sizes, as an operator runs the coordinator.
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let run = |extra: &[&str]| load_test(&server.url, extra);
    let report = successful(&run(&["--workers", "16", "--requests", "10"]));
    assert_eq!(report["errors"].as_array().unwrap().len(), 0);
    // Leases of the default 100 tests, but a worker's first, taken while
    // nobody knows what a test costs, holds one test (one per thread).
    let accepted = report["accepted_tests"].as_u64().unwrap();
    assert!(
        (16 * (1 + 9 * 100)..=16 * 10 * 100).contains(&accepted),
        "{accepted} tests in 160 leases of at most 100"
    );
    assert_eq!(report["accepted_tests"], report["campaign_tests"]);
    // Cut off by its time limit, it still cancels its campaign.
    let output = run(&[
        "--workers",
        "64",
        "--requests",
        "100000",
        "--time-limit",
        "1",
    ]);
    assert!(clean_refusal(&output));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("did not finish within") && stderr.contains("was cancelled"),
        "{stderr}"
    );
    let client = server.client();
    let campaigns = client.campaigns().await.unwrap().campaigns;
    assert_eq!(campaigns.len(), 2);
    for view in campaigns {
        assert_eq!(view.status, CampaignStatus::Cancelled, "{view:?}");
    }
    // A live real worker would take the load campaign's leases and
    // unbalance the books: refused, and no campaign is started.
    let _worker = WorkerProcess::start(&server.url, 1, "real");
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    while !client
        .workers()
        .await
        .unwrap()
        .workers
        .iter()
        .any(|w| w.name == "real")
    {
        assert!(std::time::Instant::now() < deadline, "the worker is listed");
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    let output = run(&["--workers", "2", "--requests", "2"]);
    assert!(clean_refusal(&output));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("1 live worker(s) (real) serve this coordinator"),
        "{stderr}"
    );
    assert_eq!(client.campaigns().await.unwrap().campaigns.len(), 2);
}
