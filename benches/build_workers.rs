//! Library builds with a program as surrogate, leased to workers (issue 22
//! part 4): the example user-defined case (`examples/cases/cut-in.toml`,
//! 3,420 cells) built by exhaustive search through an embedded coordinator
//! with 1, 2 and 4 workers of one thread each, beside the command line
//! running the program itself. Two programs: the example (a Python cut-in
//! simulation, tens of microseconds per scenario, so the protocol and the
//! leases dominate) and the same with 5 ms per scenario (a heavier
//! simulator, where workers add throughput until the machine's cores, and
//! beyond them while the program waits rather than computes). Prints a
//! Markdown table for docs/benchmarks.md.
//!
//! `cargo bench --bench build_workers`

use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tslg::service::LocalService;
use tslg_api::{CreateCase, CreateLibrary, LibraryStatus};
use tslg_client::Client;
use tslg_method::cases::user::descriptor;
use tslg_method::cases::user::file::CaseFile;
use tslg_method::registry::{BuildRequest, ExposureSource};
use tslg_worker::external::{ProgramSettings, ProgramSpec, Programs};

fn repo(path: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(path)
        .display()
        .to_string()
}

/// `cutin-idm=COMMAND` of the example program, or of the slow fixture.
fn program(slow: bool) -> String {
    if slow {
        format!(
            "cutin-idm=python3 {} slow cut-in-py",
            repo("tests/fixtures/faulty_case.py")
        )
    } else {
        format!(
            "cutin-idm=python3 {} cut-in-py",
            repo("examples/cases/cutin_idm.py")
        )
    }
}

fn settings() -> ProgramSettings {
    ProgramSettings {
        worker: "bench".into(),
        timeout: Duration::from_secs(60),
        max_failures: 5,
        cooldown: Duration::from_secs(1),
    }
}

/// The command line's build: the program run in this process.
fn offline(slow: bool) -> f64 {
    let text = std::fs::read_to_string(repo("examples/cases/cut-in.toml")).unwrap();
    let table = std::fs::read_to_string(repo("examples/cases/cut-in-exposure.csv")).unwrap();
    let file = CaseFile::parse(&text).unwrap();
    let spec: ProgramSpec = program(slow).parse().unwrap();
    let host = Programs::start_specs(vec![spec], &settings()).unwrap();
    let case = descriptor::open(
        file,
        "cut-in-exposure.csv",
        &table,
        None,
        &ExposureSource::Builtin,
        Some(Arc::new(host)),
    )
    .unwrap();
    let started = Instant::now();
    let built = case
        .build_library(
            &serde_json::json!({"external": "cutin-idm"}),
            &BuildRequest::default(),
        )
        .unwrap();
    assert_eq!(built.size, 286);
    started.elapsed().as_secs_f64()
}

/// Seconds from the request to the ready library through `workers` workers.
async fn through_workers(workers: usize, slow: bool) -> anyhow::Result<f64> {
    let dir = tempfile::tempdir()?;
    let url = format!("sqlite://{}", dir.path().join("bench.sqlite").display());
    let service = LocalService::start(&url, 0, 1).await?;
    let client = Client::new(&service.url, None)?;
    client
        .create_case(&CreateCase {
            file: std::fs::read_to_string(repo("examples/cases/cut-in.toml"))?,
            table: std::fs::read_to_string(repo("examples/cases/cut-in-exposure.csv"))?,
            table_name: None,
        })
        .await?;
    let (stop, rx) = tokio::sync::watch::channel(false);
    let handles: Vec<_> = (1..=workers)
        .map(|k| {
            let mut config =
                tslg_worker::WorkerConfig::local(&service.url, 1, format!("bench-{k}"));
            config.vut_exec = vec![program(slow)];
            let mut rx = rx.clone();
            tokio::spawn(tslg_worker::run(config, async move {
                let _ = rx.wait_for(|s| *s).await;
            }))
        })
        .collect();
    // The workers' programs are started (their handshakes) before the clock.
    tokio::time::sleep(Duration::from_millis(500)).await;
    let started = Instant::now();
    let library = client
        .create_library(&CreateLibrary {
            case: "cut-in-py".into(),
            preset: None,
            surrogate: serde_json::json!({"external": "cutin-idm"}),
            exposure: Default::default(),
            search: None,
            threshold: None,
        })
        .await?;
    loop {
        let view = client.library(library.id).await?;
        if view.status != LibraryStatus::Building {
            anyhow::ensure!(view.status == LibraryStatus::Ready, "{view:?}");
            anyhow::ensure!(view.size == Some(286), "{view:?}");
            break;
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let seconds = started.elapsed().as_secs_f64();
    let _ = stop.send(true);
    for h in handles {
        h.await??;
    }
    service.stop().await?;
    Ok(seconds)
}

fn main() -> anyhow::Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    println!("| program | build | seconds | cells/s | vs. the command line |");
    println!("|---|---|---|---|---|");
    for slow in [false, true] {
        let name = if slow {
            "example + 5 ms/scenario"
        } else {
            "example (Python)"
        };
        let base = offline(slow);
        println!(
            "| {name} | command line, one process on both cores | {base:.2} | {:.0} | 1.00 |",
            3420.0 / base
        );
        for workers in [1, 2, 4] {
            let seconds = runtime.block_on(through_workers(workers, slow))?;
            println!(
                "| {name} | {workers} worker(s) × 1 thread | {seconds:.2} | {:.0} | {:.2} |",
                3420.0 / seconds,
                base / seconds
            );
        }
    }
    Ok(())
}
