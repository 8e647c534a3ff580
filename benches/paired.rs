//! Paired regression campaigns against two independent campaigns, both
//! through a local coordinator with workers: how many simulations each
//! needs for the same half-width of the difference of two vehicles' rates.
//! Prints a Markdown table for docs/benchmarks.md.
//!
//! For each seed, the paired campaign runs first (β 0.2, 90 %) and stops
//! with the difference's half-width `h`; then each vehicle runs alone, on
//! its own seed (independent draws), until its own half-width is at most
//! `h/√2` (β = `h / (√2 · exact P(A))`), so that the two independent
//! estimates' difference has half-width about `h`. The paired campaign
//! simulates both vehicles on each of its `n` tests: `2n` simulations,
//! against `n_a + n_b`.
//!
//! `cargo bench --bench paired` (TSLG_BENCH_SEEDS, default 5).

mod common;

use serde_json::{json, Value};
use std::time::{Duration, Instant};
use tslg::service::LocalService;
use tslg_api::{CampaignView, CreateCampaign, Method, PairView};
use tslg_client::Client;

fn request(method: Method, library_id: Option<i64>, vut: &Value, seed: u64) -> CreateCampaign {
    CreateCampaign {
        library_id,
        max_tests: 100_000_000,
        seed,
        guard_outside: Some(false),
        ..CreateCampaign::new("cut-in", method, vut.clone())
    }
}

async fn finished(client: &Client, id: i64) -> anyhow::Result<CampaignView> {
    loop {
        let view = client.campaign(id).await?;
        if view.status.is_final() {
            return Ok(view);
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

/// One comparison: the paired campaign, then the two independent ones.
struct Row {
    pair: PairView,
    independent: [CampaignView; 2],
    seconds: [f64; 2],
}

async fn compare(
    client: &Client,
    method: Method,
    library_id: Option<i64>,
    (a, b): (&Value, &Value),
    seed: u64,
) -> anyhow::Result<Row> {
    let started = Instant::now();
    let paired = CreateCampaign {
        paired_with: Some(b.clone()),
        ..request(method, library_id, a, seed)
    };
    let id = client.create_campaign(&paired).await?.id;
    let view = finished(client, id).await?;
    let paired_seconds = started.elapsed().as_secs_f64();
    let pair = view.pair.clone().expect("a pair");
    let difference = pair.difference.expect("a difference");
    let h = (difference.ci_high - difference.ci_low) / 2.0;
    let partner = client.campaign(pair.campaign_b).await?;
    let started = Instant::now();
    let mut independent = Vec::new();
    for (k, (vut, exact)) in [(a, view.exact_probability), (b, partner.exact_probability)]
        .into_iter()
        .enumerate()
    {
        let exact = exact.expect("cut-in enumerates");
        let alone = CreateCampaign {
            // At most the largest β a campaign takes: its half-width is
            // then below h/√2 (shown in the table).
            beta: (h / (std::f64::consts::SQRT_2 * exact)).min(0.99),
            // Seeds of their own: independent draws.
            ..request(method, library_id, vut, 1_000_000 + 2 * seed + k as u64)
        };
        let id = client.create_campaign(&alone).await?.id;
        independent.push(finished(client, id).await?);
    }
    Ok(Row {
        pair,
        independent: independent.try_into().expect("two"),
        seconds: [paired_seconds, started.elapsed().as_secs_f64()],
    })
}

fn print(title: &str, rows: &[Row]) {
    println!("\n{title}\n");
    println!(
        "| seed | paired tests n | 2n simulations | half-width h | exact Δ inside | independent n_a + n_b | their half-width | exact Δ inside theirs | (n_a + n_b) / 2n | seconds paired / independent |"
    );
    println!("|---:|---:|---:|---:|:-:|---:|---:|:-:|---:|---:|");
    let mut ratios = Vec::new();
    for (seed, row) in rows.iter().enumerate() {
        let d = row.pair.difference.unwrap();
        let h = (d.ci_high - d.ci_low) / 2.0;
        let covers = |low: f64, high: f64| {
            row.pair
                .exact_difference
                .map_or("-", |x| if low <= x && x <= high { "yes" } else { "no" })
        };
        let inside = covers(d.ci_low, d.ci_high);
        let [a, b] = &row.independent;
        let half = |v: &CampaignView| v.half_width.unwrap_or(f64::NAN);
        let independent_h = (half(a).powi(2) + half(b).powi(2)).sqrt();
        let independent_d = a.estimate.unwrap_or(0.0) - b.estimate.unwrap_or(0.0);
        let theirs = covers(independent_d - independent_h, independent_d + independent_h);
        let total = a.tests + b.tests;
        let ratio = total as f64 / (2 * row.pair.tests) as f64;
        ratios.push(ratio);
        println!(
            "| {} | {} | {} | {h:.3e} | {inside} | {total} | {independent_h:.3e} | {theirs} | {ratio:.1} | {:.1} / {:.1} |",
            seed + 1,
            row.pair.tests,
            2 * row.pair.tests,
            row.seconds[0],
            row.seconds[1]
        );
    }
    ratios.sort_by(f64::total_cmp);
    println!(
        "\nmedian (n_a + n_b) / 2n over {} seeds: {:.1}",
        ratios.len(),
        ratios[ratios.len() / 2]
    );
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let seeds: u64 = std::env::var("TSLG_BENCH_SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(5);
    let dir = tempfile::tempdir()?;
    let url = format!("sqlite://{}", dir.path().join("paired.sqlite").display());
    let service = LocalService::start(&url, 1, 2).await?;
    let client = Client::new(&service.url, None)?;
    let (regression, idm, fvdm) = (
        json!({"model": "idm", "s0": 0.5}),
        json!({"model": "idm"}),
        json!({"model": "fvdm"}),
    );
    let mut rows = Vec::new();
    for seed in 1..=seeds {
        rows.push(compare(&client, Method::Ndd, None, (&regression, &idm), seed).await?);
    }
    print(
        "Cut-in NDD, IDM with jam distance 0.5 m (a) against the IDM (b): a 5-cell regression",
        &rows,
    );
    let library = common::idm_library(&client).await?;
    let mut rows = Vec::new();
    for seed in 1..=seeds {
        rows.push(compare(&client, Method::Library, Some(library), (&fvdm, &idm), seed).await?);
    }
    print(
        "Cut-in, the IDM's exhaustive library (ε 0.1), FVDM (a) against the IDM (b)",
        &rows,
    );
    service.stop().await?;
    Ok(())
}
