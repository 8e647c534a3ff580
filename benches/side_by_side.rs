//! The same estimate four ways (issue 23): the cut-in NDD estimate of the
//! IDM's accident rate (`paper-code`, built-in exposure) to a relative
//! half-width of β = 0.05 at 90 % confidence, computed by
//!
//! 1. OpenTURNS (`ProbabilitySimulationAlgorithm`, Monte Carlo, stopping at
//!    a coefficient of variation of β/z) calling the model written in
//!    Python (`benches/openturns_cutin.py`), what a user would pick instead;
//! 2. a plain scalar Rust loop: the model and the sampling written here
//!    from scratch, one thread, checking the same rule every 1,000 tests;
//! 3. tslg in this process (`run_campaign_tests`, both cores);
//! 4. tslg through an embedded coordinator with one worker of two threads.
//!
//! Prints a Markdown table: tests to the stop, estimate, wall time,
//! tests/s and time against tslg in process. Each run is the median of
//! three seeds' wall times (OpenTURNS: one run, it takes minutes).
//! `cargo bench --bench side_by_side`; the Python interpreter with
//! OpenTURNS is `TSLG_BENCH_PYTHON` (default `target/bench-venv/bin/python`,
//! which `scripts/bench` installs); without it that row says why.

mod common;

use rand::distr::weighted::WeightedIndex;
use rand::distr::Distribution;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::time::{Duration, Instant};
use tslg::service::LocalService;
use tslg_api::{CreateCampaign, Method};
use tslg_client::Client;
use tslg_method::case::Case;
use tslg_method::cases::cutin::{CutIn, CutInPreset};
use tslg_method::estimator::StoppingRule;

const BETA: f64 = 0.05;
const CONFIDENCE: f64 = 0.9;
const SEEDS: u64 = 3;

/// One way's result.
struct Run {
    tests: u64,
    estimate: f64,
    seconds: f64,
}

/// The IDM after a cut-in, `paper-code` preset, written out plainly.
fn plain_idm_accident(range: f64, range_rate: f64) -> bool {
    let lead = 20.0 + range_rate;
    let (mut v, mut gap) = (20.0f64, range);
    if gap <= 0.0 {
        return true;
    }
    let two_sqrt_ab = 2.0 * (2.0f64 * 3.0).sqrt();
    for _ in 0..10 {
        let desired = 2.0 + v + v * (v - lead) / two_sqrt_ab;
        let interaction = desired / (gap - 4.0);
        let r = v / 18.0;
        let a = 2.0 * (1.0 - r * r * (r * r) - interaction * interaction);
        let a = if a.is_nan() { -3.0 } else { a.clamp(-3.0, 3.0) };
        let a = if (v >= 40.0 && a > 0.0) || (v <= 0.0 && a < 0.0) {
            0.0
        } else {
            a
        };
        gap += (lead - v) - a / 2.0;
        v = (v + a).clamp(0.0, 40.0);
        if gap <= 0.0 {
            return true;
        }
    }
    false
}

/// The plain loop: draws cells by weight, runs them, stops when the
/// relative half-width `z √((1 − p̂)/(n p̂))` is at most β (checked every
/// 1,000 tests, at least 30 tests and 10 events as tslg's rule).
fn plain_loop(case: &CutIn, z: f64, seed: u64) -> Run {
    let grid = case.grid();
    let cells: Vec<(f64, f64)> = (0..grid.len())
        .map(|c| (grid.value(c, 0), grid.value(c, 1)))
        .collect();
    let weights: Vec<f64> = (0..grid.len()).map(|c| case.exposure().p(c)).collect();
    let draw = WeightedIndex::new(&weights).expect("a positive exposure");
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let started = Instant::now();
    let (mut n, mut events) = (0u64, 0u64);
    loop {
        for _ in 0..1000 {
            let (r, rr) = cells[draw.sample(&mut rng)];
            events += u64::from(plain_idm_accident(r, rr));
        }
        n += 1000;
        let p = events as f64 / n as f64;
        if events >= 10 && z * ((1.0 - p) / (n as f64 * p)).sqrt() <= BETA {
            return Run {
                tests: n,
                estimate: p,
                seconds: started.elapsed().as_secs_f64(),
            };
        }
    }
}

fn rule() -> StoppingRule {
    StoppingRule {
        confidence: CONFIDENCE,
        ..StoppingRule::new(BETA, 1 << 40)
    }
}

fn in_process(seed: u64) -> Run {
    let tests = common::cutin_idm_ndd(seed);
    let started = Instant::now();
    let result = tslg_method::campaign::run_campaign_tests(tests.as_ref(), &rule(), &|_| false);
    Run {
        tests: result.indices,
        estimate: result.estimate,
        seconds: started.elapsed().as_secs_f64(),
    }
}

async fn through_service(seed: u64, threads: usize) -> anyhow::Result<Run> {
    let dir = tempfile::tempdir()?;
    let url = format!("sqlite://{}", dir.path().join("bench.sqlite").display());
    let service = LocalService::start(&url, 1, threads).await?;
    let client = Client::new(&service.url, None)?;
    let started = Instant::now();
    let id = client
        .create_campaign(&CreateCampaign {
            beta: BETA,
            confidence: CONFIDENCE,
            max_tests: 1 << 40,
            seed,
            guard_outside: Some(false),
            ..CreateCampaign::new("cut-in", Method::Ndd, serde_json::json!({"model": "idm"}))
        })
        .await?
        .id;
    let view = loop {
        let view = client.campaign(id).await?;
        if view.status.is_final() {
            break view;
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
    };
    let seconds = started.elapsed().as_secs_f64();
    service.stop().await?;
    Ok(Run {
        tests: view.indices,
        estimate: view.estimate.unwrap_or(f64::NAN),
        seconds,
    })
}

/// OpenTURNS on the Python model, or why it could not run.
fn openturns(case: &CutIn, z: f64, exact: f64) -> Result<Run, String> {
    let python = std::env::var("TSLG_BENCH_PYTHON")
        .unwrap_or_else(|_| "target/bench-venv/bin/python".to_owned());
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    let table = dir.path().join("exposure.csv");
    let grid = case.grid();
    let mut csv = String::from("range,range_rate,p\n");
    for c in 0..grid.len() {
        csv += &format!(
            "{},{},{}\n",
            grid.value(c, 0),
            grid.value(c, 1),
            case.exposure().p(c)
        );
    }
    std::fs::write(&table, csv).map_err(|e| e.to_string())?;
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/benches/openturns_cutin.py");
    let out = std::process::Command::new(&python)
        .args([
            script,
            table.to_str().unwrap(),
            &BETA.to_string(),
            &z.to_string(),
            "1",
        ])
        .output()
        .map_err(|e| format!("{python}: {e} (scripts/bench installs OpenTURNS)"))?;
    if !out.status.success() {
        return Err(String::from_utf8_lossy(&out.stderr).trim().to_owned());
    }
    let answer: serde_json::Value =
        serde_json::from_slice(&out.stdout).map_err(|e| e.to_string())?;
    let theirs = answer["exact"].as_f64().unwrap_or(f64::NAN);
    // The same model: its exact P(A) on the grid is tslg's.
    assert!(
        (theirs - exact).abs() <= 1e-12 * exact,
        "the Python model's exact P(A) {theirs} differs from tslg's {exact}"
    );
    Ok(Run {
        tests: answer["tests"].as_u64().unwrap_or(0),
        estimate: answer["estimate"].as_f64().unwrap_or(f64::NAN),
        seconds: answer["seconds"].as_f64().unwrap_or(f64::NAN),
    })
}

/// The run with the median wall time of `runs`.
fn median(mut runs: Vec<Run>) -> Run {
    runs.sort_by(|a, b| a.seconds.total_cmp(&b.seconds));
    runs.swap_remove(runs.len() / 2)
}

fn main() -> anyhow::Result<()> {
    let case = CutIn::builtin(CutInPreset::PaperCode);
    let idm = tslg_method::vehicle::VehicleModel::builtin("idm").unwrap();
    let exact =
        tslg_method::exact::event_probability(&case, &tslg_method::exact::event_cells(&case, &idm));
    // The plain model is the same model.
    let grid = case.grid();
    for c in 0..grid.len() {
        assert_eq!(
            plain_idm_accident(grid.value(c, 0), grid.value(c, 1)),
            case.is_event(&idm, c),
            "cell {c}"
        );
    }
    let z = rule().z();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let plain = median((1..=SEEDS).map(|s| plain_loop(&case, z, s)).collect());
    let local = median((1..=SEEDS).map(in_process).collect());
    let service = median(
        (1..=SEEDS)
            .map(|s| runtime.block_on(through_service(s, cores)))
            .collect::<anyhow::Result<_>>()?,
    );
    let ot = openturns(&case, z, exact);
    println!(
        "Cut-in NDD estimate of the IDM's accident rate (exact {exact:.4e}), β = {BETA}, \
         confidence {CONFIDENCE}; median of {SEEDS} seeds\n"
    );
    println!(
        "| runner | tests to the stop | estimate | seconds | tests/s | time / tslg in process |"
    );
    println!("|---|---:|---:|---:|---:|---:|");
    let row = |name: &str, r: &Run| {
        println!(
            "| {name} | {} | {:.4e} | {:.3} | {:.3e} | {:.2} |",
            r.tests,
            r.estimate,
            r.seconds,
            r.tests as f64 / r.seconds,
            r.seconds / local.seconds
        )
    };
    match &ot {
        Ok(run) => row("OpenTURNS 1.27, model in Python (1 thread)", run),
        Err(why) => println!("| OpenTURNS, model in Python | not run: {why} | | | | |"),
    }
    row("plain scalar Rust loop (1 thread)", &plain);
    row(&format!("tslg in process ({cores} threads)"), &local);
    row(
        &format!("tslg through the service (1 worker × {cores} threads)"),
        &service,
    );
    Ok(())
}
