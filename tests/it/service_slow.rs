//! Slow vehicles (docs/operations.md, "Slow vehicles"): leases sized from
//! what a test costs, from one test per thread while nobody knows; never
//! much more out on lease than a campaign can use; a stopped campaign's
//! worker dropping its lease at the next exchange; and an audit run before
//! a worker's next range. Counted in tests, never timed.

use crate::support::*;
use std::path::Path;
use std::time::{Duration, Instant};
use tslg_api::{CampaignStatus, CreateCampaign, Lease, LeaseRequest, Method, ResultReport};

/// An NDD campaign of the external program `name` on cut-in (step mode),
/// which never stops on its own (β at its least, a large `n_min`).
fn program_campaign(name: &str, seed: u64) -> CreateCampaign {
    CreateCampaign {
        library_id: None,
        vut: serde_json::json!({ "external": name }),
        n_min: Some(1_000),
        max_tests: 1_000_000,
        ..campaign(
            Method::Ndd,
            0,
            "idm",
            tslg_method::estimator::MIN_BETA,
            seed,
        )
    }
}

/// `worker`'s request for a lease of program `slow`, on `threads` threads.
fn slow_ask(worker: &str, threads: u32) -> LeaseRequest {
    LeaseRequest {
        threads,
        ..ask(worker, &["slow:cut-in:step"])
    }
}

/// A report of `lease` whole that says its tests took `seconds` on
/// `threads` threads.
fn timed(lease: &Lease, worker: &str, threads: u32, seconds: f64) -> ResultReport {
    ResultReport {
        threads,
        compute_seconds: seconds,
        ..whole(lease, worker, Vec::new())
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_slow_program_starts_at_one_test_a_thread_and_its_cost_is_kept_for_its_next_campaign() {
    let dir = scratch();
    let server = ServerProcess::start(
        &dir.path().join("db.sqlite"),
        &["--lease-target-seconds", "2"],
    );
    let client = server.client();
    let first = client
        .create_campaign(&program_campaign("slow", 1))
        .await
        .unwrap()
        .id;

    // Nobody knows what a test of `slow` costs: one test per thread.
    let lease = client.claim(&slow_ask("w", 4)).await.unwrap().unwrap();
    assert_eq!((lease.end - lease.start, lease.seconds_per_test), (4, None));
    // The 4 tests took 0.2 s on 4 threads: 0.2 s a test on one thread.
    tokio::time::sleep(Duration::from_millis(250)).await;
    client
        .report(lease.id, &timed(&lease, "w", 4, 0.2))
        .await
        .unwrap();

    // Now 2 s of work on 4 threads: 40 tests.
    let lease = client.claim(&slow_ask("w", 4)).await.unwrap().unwrap();
    assert_eq!(lease.end - lease.start, 40, "{lease:?}");
    let cost = lease.seconds_per_test.expect("the measured cost");
    assert!((cost - 0.2).abs() < 1e-9, "{cost}");
    let workers = client.workers().await.unwrap();
    assert_eq!(workers.costs.len(), 1, "{workers:?}");
    assert_eq!(workers.costs[0].program, "slow:cut-in:step");
    assert!((workers.costs[0].seconds_per_test - 0.2).abs() < 1e-9);

    // The next campaign of the program starts from that cost: 2 s of
    // work on 2 threads is 20 tests, from its first lease on.
    client.cancel_campaign(first).await.unwrap();
    let second = client
        .create_campaign(&program_campaign("slow", 2))
        .await
        .unwrap()
        .id;
    let lease = client.claim(&slow_ask("v", 2)).await.unwrap().unwrap();
    assert_eq!(
        (lease.campaign_id, lease.end - lease.start),
        (second, 20),
        "{lease:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_campaign_that_needs_100_tests_never_has_much_more_out_on_lease_among_8_workers() {
    // The IDM library campaign on its own library stops at its n_min of
    // 100 tests (ε 0.1: ten exploring tests), well before β binds. Eight
    // one-thread workers claim in turn and report whole, each as soon as
    // its lease ends, in the order they claimed; each report says its
    // tests took a millisecond, so the time target alone would lease
    // thousands of tests.
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let id = client
        .create_campaign(&campaign(Method::Library, library.id, "idm", 0.2, 2))
        .await
        .unwrap()
        .id;
    let names: Vec<String> = (1..=8).map(|w| format!("w{w}")).collect();
    let mut held: std::collections::VecDeque<(String, Lease)> = Default::default();
    for name in &names {
        if let Some(lease) = client.claim(&ask(name, &[])).await.unwrap() {
            held.push_back((name.clone(), lease));
        }
    }
    let (mut leased_most, mut ran) = (0, 0);
    while let Some((name, lease)) = held.pop_front() {
        let view = client.campaign(id).await.unwrap();
        leased_most = leased_most.max(view.leased);
        if view.status != CampaignStatus::Running {
            continue;
        }
        let tests = lease.end - lease.resume_at;
        ran += tests;
        let events = real_events(&client, id, lease.resume_at, lease.end).await;
        let report = ResultReport {
            compute_seconds: 1e-3,
            ..whole(&lease, &name, events)
        };
        client.report(lease.id, &report).await.unwrap();
        if let Some(next) = client.claim(&ask(&name, &[])).await.unwrap() {
            held.push_back((name, next));
        }
    }
    let view = client.campaign(id).await.unwrap();
    assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
    assert_eq!(view.indices, 100, "stopped at its n_min");
    assert!(
        leased_most <= 2 * view.indices,
        "{leased_most} leased for a stop at {}",
        view.indices
    );
    assert!(
        ran * 5 <= view.indices * 6,
        "the workers ran {ran} tests for {} used",
        view.indices
    );
}

/// The debug build's `examples/fvdm_vut` with `args`, as `--vut-exec`'s
/// `slow=COMMAND`.
fn slow_program(args: &str) -> String {
    format!("slow={} {args}", example_binary("fvdm_vut").display())
}

/// Waits until `n` workers have registered (a minute at most).
async fn until_registered(client: &tslg_client::Client, n: usize) {
    let started = Instant::now();
    while client.workers().await.unwrap().workers.len() < n {
        assert!(started.elapsed() < Duration::from_secs(60), "workers seen");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Tests the program has started, counted in its tally file.
fn tally(file: &Path) -> u64 {
    std::fs::metadata(file).map_or(0, |m| m.len())
}

/// Waits until the tally stops growing for `quiet`, up to `limit`.
async fn settled_tally(file: &Path, quiet: Duration, limit: Duration) -> u64 {
    let started = Instant::now();
    let (mut last, mut since) = (tally(file), Instant::now());
    while since.elapsed() < quiet && started.elapsed() < limit {
        tokio::time::sleep(Duration::from_millis(20)).await;
        let now = tally(file);
        if now != last {
            (last, since) = (now, Instant::now());
        }
    }
    last
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_cancelled_campaign_s_worker_drops_the_rest_of_its_lease_at_the_next_report() {
    // Leases of 40 tests of 0.1 s: a worker that ran its lease out would
    // run about 40 tests after the cancel; one that hears it at its next
    // report runs the test under way and at most the next chunk's.
    let dir = scratch();
    let counted = dir.path().join("tally");
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &["--lease-size", "40"]);
    let program = slow_program(&format!("--sleep 0.1 --tally {}", counted.display()));
    let _worker = WorkerProcess::start_with(&server.url, 1, "slow-1", &["--vut-exec", &program]);
    let client = server.client();
    let id = client
        .create_campaign(&program_campaign("slow", 3))
        .await
        .unwrap()
        .id;
    wait_for(&client, id, Duration::from_secs(60), |v| v.indices >= 3).await;
    let view = client.cancel_campaign(id).await.unwrap();
    assert_eq!(view.status, CampaignStatus::Cancelled);
    let at_cancel = tally(&counted);
    let after = settled_tally(&counted, Duration::from_secs(2), Duration::from_secs(60)).await;
    assert!(
        after <= at_cancel + 3,
        "{} tests started after the cancel (at {at_cancel}) of a 40-test lease",
        after - at_cancel
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_audit_is_run_before_the_auditing_worker_s_next_range() {
    // Every test is audited. Two workers of a 0.05 s program hold leases
    // of 40 tests; the first audit holds the prefix at test 0. Were audits
    // handed out only with new leases, test 0's could not run before the
    // other worker had run its 40 tests out (80 in all, side by side);
    // taken with a report, it runs after a chunk or two of each worker,
    // and the prefix moves.
    let dir = scratch();
    let counted = dir.path().join("tally");
    let server = ServerProcess::start(
        &dir.path().join("db.sqlite"),
        &["--lease-size", "40", "--audit-share", "1"],
    );
    let program = slow_program(&format!("--sleep 0.05 --tally {}", counted.display()));
    let _a = WorkerProcess::start_with(&server.url, 1, "slow-a", &["--vut-exec", &program]);
    let _b = WorkerProcess::start_with(&server.url, 1, "slow-b", &["--vut-exec", &program]);
    let client = server.client();
    until_registered(&client, 2).await;
    let id = client
        .create_campaign(&program_campaign("slow", 4))
        .await
        .unwrap()
        .id;
    let view = wait_for(&client, id, Duration::from_secs(60), |v| v.indices >= 1).await;
    let ran = tally(&counted);
    client.cancel_campaign(id).await.unwrap();
    assert!(
        ran < 40,
        "{ran} tests ran before test 0's audit agreed: {view:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_timeline_shows_where_a_slow_program_s_campaign_spent_its_time() {
    // Three one-thread workers of a 0.05 s program run an NDD campaign
    // to its budget of 60 tests. Every test's wait is worker time, so the
    // timeline's busy worker-seconds are at least 60 × 0.05 s; they cannot
    // exceed the three workers' time; its buckets hold the 60 tests once.
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let program = slow_program("--sleep 0.05");
    let _workers: Vec<WorkerProcess> = (1..=3)
        .map(|k| {
            WorkerProcess::start_with(&server.url, 1, &format!("w{k}"), &["--vut-exec", &program])
        })
        .collect();
    let client = server.client();
    until_registered(&client, 3).await;
    let id = client
        .create_campaign(&CreateCampaign {
            max_tests: 60,
            n_min: Some(60),
            ..program_campaign("slow", 5)
        })
        .await
        .unwrap()
        .id;
    let view = finished(&client, id, Duration::from_secs(120)).await;
    assert_eq!(view.indices, 60, "{view:?}");
    let t = client.timeline(id, 10).await.unwrap();
    assert_eq!((t.campaign_id, t.workers, t.buckets.len()), (id, 3, 10));
    assert!(t.busy_worker_seconds >= 60.0 * 0.05, "{t:?}");
    assert!(t.seconds >= 60.0 * 0.05 / 3.0, "{t:?}");
    assert!(t.busy_share > 0.0 && t.busy_share <= 1.0 + 1e-9, "{t:?}");
    let reported: u64 = t.buckets.iter().map(|b| b.reported_tests).sum();
    assert_eq!(reported, 60, "{t:?}");
    assert_eq!(t.buckets.last().unwrap().folded, 60, "{t:?}");
    let busiest = t.buckets.iter().map(|b| b.busy_workers).fold(0.0, f64::max);
    assert!(busiest <= 3.0 + 1e-9, "{t:?}");

    // The CLI's table, and a bad bucket count refused with the reason.
    let id = id.to_string();
    let timeline = |buckets| {
        tslg(&[
            "campaign",
            "timeline",
            &id,
            "--server",
            &server.url,
            "--buckets",
            buckets,
        ])
    };
    let out = timeline("5");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("3 workers ran its work"), "{text}");
    assert_eq!(
        text.lines().filter(|l| l.contains(" |")).count(),
        5,
        "{text}"
    );
    let refused = timeline("0");
    assert!(clean_refusal(&refused), "{refused:?}");
    assert!(
        String::from_utf8_lossy(&refused.stderr).contains("buckets = 0 must be in 1..=1000"),
        "{}",
        String::from_utf8_lossy(&refused.stderr)
    );
}
