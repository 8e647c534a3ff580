//! Service overhead: the same cheap NDD baseline (IDM on cut-in, ~60 ns per
//! test) run in this process and through a local coordinator with one
//! worker on the same cores, the same tests as two campaigns side by side,
//! and the lease round-trip time. Prints Markdown tables for
//! docs/benchmarks.md.
//!
//! `cargo bench --bench service` (set TSLG_BENCH_TESTS to change the size
//! of the NDD runs, TSLG_BENCH_HIGH_BETA the high-event campaign's β, and
//! TSLG_BENCH_HIGH_ONLY to run only the high-event table).

mod common;

use std::time::{Duration, Instant};
use tslg::service::LocalService;
use tslg_api::{CreateCampaign, LeaseRequest, Method, ResultReport};
use tslg_client::Client;
use tslg_method::cases::open_case;
use tslg_method::estimator::{default_n_min, StoppingRule, MIN_BETA};
use tslg_method::registry::ExposureSource;

fn request(tests: u64) -> CreateCampaign {
    CreateCampaign {
        // Never reached: the campaign runs to its budget.
        beta: MIN_BETA,
        max_tests: tests,
        seed: 1,
        guard_outside: Some(false),
        ..CreateCampaign::new("cut-in", Method::Ndd, serde_json::json!({"model": "idm"}))
    }
}

fn in_process(tests: u64) -> f64 {
    let campaign = common::cutin_idm_ndd(1);
    let rule = StoppingRule::new(MIN_BETA, tests);
    let started = Instant::now();
    // The in-process runner's own path: spans of tests in batches.
    let result = tslg_method::campaign::run_campaign_tests(campaign.as_ref(), &rule, &|_| false);
    assert_eq!(result.indices, tests);
    started.elapsed().as_secs_f64()
}

/// How long the bench waits before it looks at a campaign run to its
/// budget again: 50 ms until 95 % of the budget is resolved, then 2 ms,
/// so the end is seen at once. Each look is a request the coordinator
/// answers, and the answer parsed, on the cores the worker runs on:
/// looking every 5 ms throughout took about 0.6 of the 9 CPU-seconds of
/// a 10⁸-test run (2026-11-27, three runs each way), work the in-process
/// runner is not charged.
fn poll_after(resolved: u64, budget: u64) -> Duration {
    if resolved < budget / 20 * 19 {
        Duration::from_millis(50)
    } else {
        Duration::from_millis(2)
    }
}

/// The NDD campaigns of `seeds`, `tests` tests each, side by side through
/// a local coordinator with `workers` workers of `threads` threads:
/// seconds from their creation until all stop. With several campaigns,
/// leases take turns between them, so a worker's leases alternate.
async fn through_service(
    seeds: &[u64],
    tests: u64,
    workers: usize,
    threads: usize,
) -> anyhow::Result<f64> {
    let dir = tempfile::tempdir()?;
    let url = format!("sqlite://{}", dir.path().join("bench.sqlite").display());
    let service = LocalService::start(&url, workers, threads).await?;
    let client = Client::new(&service.url, None)?;
    let started = Instant::now();
    let mut ids = Vec::new();
    for &seed in seeds {
        let campaign = CreateCampaign {
            seed,
            ..request(tests)
        };
        ids.push(client.create_campaign(&campaign).await?.id);
    }
    for id in ids {
        loop {
            let view = client.campaign(id).await?;
            if view.status.is_final() {
                assert_eq!(view.indices, tests);
                break;
            }
            tokio::time::sleep(poll_after(view.indices, tests)).await;
        }
    }
    let seconds = started.elapsed().as_secs_f64();
    service.stop().await?;
    Ok(seconds)
}

/// Claim-and-report round trips with no worker running, of an NDD campaign
/// or (`library`) of a library campaign of the IDM's cut-in library, whose
/// reports the coordinator checks against its own runs (every event, a
/// tenth of the rest) and replays for exploring tests. Returns the
/// sorted times (ms) and the mean lease size.
async fn round_trips(count: usize, library: bool) -> anyhow::Result<(Vec<f64>, f64)> {
    let dir = tempfile::tempdir()?;
    let url = format!("sqlite://{}", dir.path().join("rtt.sqlite").display());
    let service = LocalService::start(&url, 0, 1).await?;
    let client = Client::new(&service.url, None)?;
    let mut campaign = request(u64::MAX >> 20);
    if library {
        campaign.method = Method::Library;
        campaign.library_id = Some(common::idm_library(&client).await?);
    }
    let id = client.create_campaign(&campaign).await?.id;
    // The coordinator checks reports against its own runs: report the real
    // outcomes, computed outside the timed requests.
    let prepared = tslg_worker::prepared::Cache::default()
        .get(&client, id)
        .await?
        .tests()
        .ok_or_else(|| anyhow::anyhow!("campaign {id} is a library build"))?;
    let mut times = Vec::with_capacity(count);
    let mut leased = 0u64;
    for _ in 0..count {
        let started = Instant::now();
        let lease = client
            .claim(&LeaseRequest {
                worker: "bench".into(),
                threads: 1,
                include_tests: false,
                offers: Vec::new(),
                unhealthy: Vec::new(),
                // Leases of 256 tests, as this table always measured
                // (the reports' cost below would allow far more).
                max_tests: Some(256),
                wait_seconds: None,
                audits_only: false,
                noisy: Vec::new(),
            })
            .await?
            .expect("work");
        let claimed = started.elapsed();
        leased += lease.end - lease.start;
        let events: Vec<(u64, f64)> = (lease.start..lease.end)
            .filter_map(|i| {
                let outcome = prepared.tests.run(i);
                outcome.event.then_some((i, outcome.weight))
            })
            .collect();
        let mut report = ResultReport {
            next_lease: None,
            near_misses: Vec::new(),
            worker: "bench".into(),
            attempt: lease.attempt,
            key: lease.key.clone(),
            from: lease.start,
            to: lease.end,
            events: vec![],
            packed_events: None,
            invalid: vec![],
            // A millisecond a report: the coordinator learns a cost, so its
            // leases leave the one test a thread of an unknown vehicle.
            compute_seconds: 1e-3,
            threads: 1,
        };
        report.pack_events(&events);
        let sent = Instant::now();
        client.report(lease.id, &report).await?;
        times.push((claimed + sent.elapsed()).as_secs_f64() * 1e3);
    }
    service.stop().await?;
    times.sort_by(f64::total_cmp);
    Ok((times, leased as f64 / count as f64))
}

/// The high-event campaign of issue 20: the FVDM tested with the IDM's
/// exhaustive cut-in library, about 91 % of whose tests are events, to
/// relative half-width `beta`. In process: seconds to the stop and the stop
/// index. Through the service (one worker on every core, the embedded
/// coordinator): seconds from the campaign's creation to its stop, the stop
/// index, and what the events cost on disk.
fn high_event_in_process(beta: f64) -> (f64, u64) {
    let case = open_case("cut-in", None, &ExposureSource::Builtin).unwrap();
    let library = case
        .build_library(
            &serde_json::json!({"model": "idm"}),
            &tslg_method::registry::BuildRequest {
                threshold: None,
                search: Some(tslg_method::registry::LibrarySearch::Cells(
                    tslg_method::library::SearchMethod::Exhaustive,
                )),
            },
        )
        .unwrap();
    let campaign = case
        .campaign(
            Some(&library.file),
            &serde_json::json!({"model": "fvdm"}),
            0.1,
            Default::default(),
            Default::default(),
            1,
        )
        .unwrap();
    let rule = StoppingRule {
        n_min: default_n_min(Some(0.1), 1 << 40),
        ..StoppingRule::new(beta, 1 << 40)
    };
    let started = Instant::now();
    let result = tslg_method::campaign::run_campaign_tests(campaign.as_ref(), &rule, &|_| false);
    (started.elapsed().as_secs_f64(), result.indices)
}

struct ServiceRun {
    seconds: f64,
    indices: u64,
    events: u64,
    report_rows: i64,
    packed_bytes: i64,
    /// Events read back from the database (those past the stop included)
    /// and how long that took.
    read_events: usize,
    read_seconds: f64,
    file_bytes: u64,
}

async fn high_event_service(beta: f64, threads: usize) -> anyhow::Result<ServiceRun> {
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("high.sqlite");
    let url = format!("sqlite://{}", path.display());
    let service = LocalService::start(&url, 1, threads).await?;
    let client = Client::new(&service.url, None)?;
    let request = CreateCampaign {
        method: Method::Library,
        library_id: Some(common::idm_library(&client).await?),
        vut: serde_json::json!({"model": "fvdm"}),
        beta,
        max_tests: 1 << 40,
        ..request(0)
    };
    let started = Instant::now();
    let id = client.create_campaign(&request).await?.id;
    let view = loop {
        let view = client.campaign(id).await?;
        if view.status.is_final() {
            break view;
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
    };
    let seconds = started.elapsed().as_secs_f64();
    service.stop().await?;
    use sqlx::Connection;
    let mut db = sqlx::SqliteConnection::connect(&url).await?;
    let (report_rows, packed_bytes): (i64, i64) =
        sqlx::query_as("SELECT COUNT(*), COALESCE(SUM(LENGTH(packed)), 0) FROM reports")
            .fetch_one(&mut db)
            .await?;
    // Every event read back as the fold reads them: rows in index order,
    // each unpacked.
    let read = Instant::now();
    let rows: Vec<(i64, Vec<u8>)> = sqlx::query_as(
        "SELECT from_index, packed FROM reports WHERE campaign_id = ? ORDER BY from_index",
    )
    .bind(id)
    .fetch_all(&mut db)
    .await?;
    let mut read_events = 0usize;
    for (from, bytes) in &rows {
        read_events += tslg_api::packed::unpack(*from as u64, bytes)?.len();
    }
    let read_seconds = read.elapsed().as_secs_f64();
    sqlx::query("VACUUM").execute(&mut db).await?;
    db.close().await?;
    Ok(ServiceRun {
        seconds,
        indices: view.indices,
        events: view.events,
        report_rows,
        packed_bytes,
        read_events,
        read_seconds,
        file_bytes: std::fs::metadata(&path)?.len(),
    })
}

fn high_event_table(runtime: &tokio::runtime::Runtime, cores: usize) -> anyhow::Result<()> {
    let beta: f64 = std::env::var("TSLG_BENCH_HIGH_BETA")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0.01);
    let mut local = Vec::new();
    let mut served = Vec::new();
    for _ in 0..3 {
        local.push(high_event_in_process(beta));
        served.push(runtime.block_on(high_event_service(beta, cores))?);
    }
    let (l, stop) = local
        .iter()
        .copied()
        .fold((f64::INFINITY, 0), |a, b| if b.0 < a.0 { b } else { a });
    let s = served
        .iter()
        .min_by(|a, b| a.seconds.total_cmp(&b.seconds))
        .expect("three runs");
    assert_eq!(s.indices, stop, "the service stops where the process does");
    println!(
        "High-event campaign: FVDM with the IDM library, β = {beta}, {cores} cores (best of 3)\n"
    );
    println!("| runner | seconds | stop index | events | tests/s |");
    println!("|---|---:|---:|---:|---:|");
    println!(
        "| in-process (rayon, {cores} threads) | {l:.2} | {stop} | | {:.3e} |",
        stop as f64 / l
    );
    println!(
        "| service (1 worker × {cores} threads, embedded coordinator) | {:.2} | {} | {} | {:.3e} |",
        s.seconds,
        s.indices,
        s.events,
        s.indices as f64 / s.seconds
    );
    println!("\nservice / in-process time: {:.2}", s.seconds / l);
    println!(
        "storage: {} report rows, {} bytes of packed events ({:.2} bytes per event), \
         database file {} bytes after VACUUM ({:.2} bytes per event)\n",
        s.report_rows,
        s.packed_bytes,
        s.packed_bytes as f64 / s.events as f64,
        s.file_bytes,
        s.file_bytes as f64 / s.events as f64
    );
    println!(
        "reading every stored event back ({} with those past the stop): {:.0} ms\n",
        s.read_events,
        s.read_seconds * 1e3
    );
    Ok(())
}

fn main() -> anyhow::Result<()> {
    let tests: u64 = std::env::var("TSLG_BENCH_TESTS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(20_000_000);
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    high_event_table(&runtime, cores)?;
    if std::env::var_os("TSLG_BENCH_HIGH_ONLY").is_some() {
        return Ok(());
    }
    let mut local = Vec::new();
    let mut service = Vec::new();
    for _ in 0..3 {
        local.push(in_process(tests));
        service.push(runtime.block_on(through_service(&[1], tests, 1, cores))?);
    }
    let best = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
    let (l, s) = (best(&local), best(&service));
    println!("NDD baseline, cut-in IDM, {tests} tests, {cores} cores (best of 3)\n");
    println!("| runner | seconds | tests/s |");
    println!("|---|---:|---:|");
    println!(
        "| in-process (rayon, {cores} threads) | {l:.2} | {:.3e} |",
        tests as f64 / l
    );
    println!(
        "| service (1 worker × {cores} threads, embedded coordinator) | {s:.2} | {:.3e} |",
        tests as f64 / s
    );
    println!("\nthroughput ratio service / in-process: {:.3}\n", l / s);
    let mut two = Vec::new();
    for _ in 0..3 {
        two.push(runtime.block_on(through_service(&[1, 2], tests / 2, 1, cores))?);
    }
    let t = best(&two);
    println!(
        "two campaigns of {} tests side by side through the service: {t:.2} s, {:.3e} tests/s \
         (one campaign of {tests}: {s:.2} s)\n",
        tests / 2,
        tests as f64 / t
    );
    // How throughput grows with the number of workers (one thread each) on
    // this machine's cores: a quarter of the tests, best of 3.
    let scaled = tests / 4;
    println!("| workers × threads ({scaled} tests) | seconds | tests/s | per worker thread |");
    println!("|---|---:|---:|---:|");
    for workers in [1, 2, 4, 8] {
        let mut times = Vec::new();
        for _ in 0..3 {
            times.push(runtime.block_on(through_service(&[1], scaled, workers, 1))?);
        }
        let t = best(&times);
        println!(
            "| {workers} × 1 | {t:.2} | {:.3e} | {:.3e} |",
            scaled as f64 / t,
            scaled as f64 / t / workers as f64
        );
    }
    println!();
    println!("| lease round trip (claim + report, 1000 trips) | mean lease (tests) | p50 ms | p90 ms | p99 ms |");
    println!("|---|---:|---:|---:|---:|");
    for (label, library) in [
        ("NDD campaign", false),
        ("library campaign (exploring tests replayed)", true),
    ] {
        let (rtt, lease) = runtime.block_on(round_trips(1000, library))?;
        let q = |p: f64| rtt[((rtt.len() - 1) as f64 * p) as usize];
        println!(
            "| {label}, loopback, SQLite WAL | {lease:.0} | {:.2} | {:.2} | {:.2} |",
            q(0.5),
            q(0.9),
            q(0.99)
        );
    }
    Ok(())
}
