//! Service overhead: the same cheap NDD baseline (IDM on cut-in, ~1 µs per
//! test) run in this process and through a local coordinator with one
//! worker on the same cores, and the lease round-trip time. Prints a
//! Markdown table for docs/benchmarks.md.
//!
//! `cargo bench --bench service` (set TSLG_BENCH_TESTS to change the size).

use std::time::{Duration, Instant};
use tslg::service::LocalService;
use tslg_api::{
    CreateCampaign, CreateLibrary, ExposureRequest, LeaseRequest, LibraryStatus, Method,
    ResultReport, SearchRequest,
};
use tslg_client::Client;
use tslg_method::campaign::run_indexed_campaign;
use tslg_method::estimator::StoppingRule;
use tslg_method::registry::{open_case, ExposureSource};

fn request(tests: u64) -> CreateCampaign {
    CreateCampaign {
        case: "cut-in".into(),
        method: Method::Ndd,
        library_id: None,
        vut: serde_json::json!({"model": "idm"}),
        epsilon: 0.1,
        // Never reached: the campaign runs to its budget.
        beta: 1e-6,
        confidence: 0.9,
        max_tests: tests,
        seed: 1,
        n_min: None,
        min_events: None,
        guard_outside: false,
        outside: None,
    }
}

fn in_process(tests: u64) -> f64 {
    let case = open_case("cut-in", None, &ExposureSource::Builtin).unwrap();
    let campaign = case
        .campaign(
            None,
            &serde_json::json!({"model": "idm"}),
            0.1,
            Default::default(),
            1,
        )
        .unwrap();
    let rule = StoppingRule::new(1e-6, tests);
    let started = Instant::now();
    let result = run_indexed_campaign(
        &|i| {
            let outcome = campaign.run(i);
            outcome.event.then_some(outcome.weight)
        },
        &rule,
    );
    assert_eq!(result.indices, tests);
    started.elapsed().as_secs_f64()
}

async fn through_service(tests: u64, workers: usize, threads: usize) -> anyhow::Result<f64> {
    let dir = tempfile::tempdir()?;
    let url = format!("sqlite://{}", dir.path().join("bench.sqlite").display());
    let service = LocalService::start(&url, workers, threads).await?;
    let client = Client::new(&service.url, None)?;
    let started = Instant::now();
    let id = client.create_campaign(&request(tests)).await?.id;
    loop {
        let view = client.campaign(id).await?;
        if view.status.is_final() {
            assert_eq!(view.indices, tests);
            break;
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
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
        let mut view = client
            .create_library(&CreateLibrary {
                case: "cut-in".into(),
                preset: None,
                surrogate: serde_json::json!({"model": "idm"}),
                exposure: ExposureRequest::Builtin,
                search: Some(SearchRequest::Exhaustive),
                threshold: None,
            })
            .await?;
        while view.status == LibraryStatus::Building {
            tokio::time::sleep(Duration::from_millis(20)).await;
            view = client.library(view.id).await?;
        }
        campaign.method = Method::Library;
        campaign.library_id = Some(view.id);
    }
    let id = client.create_campaign(&campaign).await?.id;
    // The coordinator checks reports against its own runs: report the real
    // outcomes, computed outside the timed requests.
    let prepared = tslg_worker::prepared::Cache::default()
        .get(&client, id)
        .await?;
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
                max_tests: None,
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
            worker: "bench".into(),
            attempt: lease.attempt,
            key: lease.key.clone(),
            from: lease.start,
            to: lease.end,
            events: vec![],
            packed_events: None,
            invalid: vec![],
            compute_seconds: 0.0,
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
    let mut local = Vec::new();
    let mut service = Vec::new();
    for _ in 0..3 {
        local.push(in_process(tests));
        service.push(runtime.block_on(through_service(tests, 1, cores))?);
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
    // How throughput grows with the number of workers (one thread each) on
    // this machine's cores: a quarter of the tests, best of 3.
    let scaled = tests / 4;
    println!("| workers × threads ({scaled} tests) | seconds | tests/s | per worker thread |");
    println!("|---|---:|---:|---:|");
    for workers in [1, 2, 4, 8] {
        let mut times = Vec::new();
        for _ in 0..3 {
            times.push(runtime.block_on(through_service(scaled, workers, 1))?);
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
