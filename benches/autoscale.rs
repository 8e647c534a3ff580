//! Worker-seconds of an autoscaled fleet against a fixed one (issue 48):
//! what a user pays for the workers, and how long the answer takes, when
//! campaigns come and go. A user runs a campaign of a slow program (the
//! FVDM at gain 0.1 as `examples/fvdm_vut.rs` with `--sleep d`, whose NDD
//! baseline stops after about 2,000 tests at β 0.2), waits `G` seconds,
//! and runs a second one (another seed). The fleet is either
//!
//! - **fixed**: 8 one-thread workers, alive from the first campaign's start
//!   to the second one's stop (the least a fixed fleet costs), or
//! - **autoscaled**: a loop that reads `workers_wanted` from
//!   `GET /api/v1/queue` every second and starts workers (at most 8) to
//!   match; workers leave after 3 s without work
//!   (`--exit-when-idle-seconds`), as a batch job does. Surplus workers
//!   are either stopped at once (SIGTERM's path: "down at once") or left
//!   to finish and leave when idle ("down when idle", what
//!   `scripts/slurm-scale` does, and what KEDA and an HPA do within their
//!   scale-down stabilization window). The coordinator's
//!   `--queue-target-seconds T` is the row's.
//!
//! For each: the wall time of each campaign, the worker-seconds used (the
//! sum of the workers' lifetimes) and the busy part (tests run × d).
//! Prints a Markdown table for docs/benchmarks.md.
//!
//! ```sh
//! cargo build --release --example fvdm_vut
//! cargo bench --bench autoscale
//! ```
//!
//! `TSLG_AUTOSCALE_SLEEP` (d, default 0.05 s), `TSLG_AUTOSCALE_GAP` (G,
//! default 30 s) and `TSLG_AUTOSCALE_TARGETS` (T, default `5,30`) choose
//! the rows; `TSLG_AUTOSCALE_TRACE=1` prints the queue at every step.

mod common;

use std::path::PathBuf;
use std::time::{Duration, Instant};
use tokio::sync::watch;
use tokio::task::JoinHandle;
use tslg_api::Method;
use tslg_client::Client;

/// The most workers either fleet has.
const FLEET: usize = 8;
/// The program's gain: the FVDM at an eighth of its sensitivity fails
/// often enough for a short NDD campaign.
const HOT_GAIN: f64 = 0.1;

fn number(var: &str, default: f64) -> f64 {
    std::env::var(var).map_or(default, |v| {
        v.parse().unwrap_or_else(|_| panic!("{var}: `{v}`"))
    })
}

/// A worker in this process: its shutdown, its task and when it started.
struct Worker {
    stop: watch::Sender<bool>,
    task: JoinHandle<()>,
    started: Instant,
}

/// A coordinator and the workers it has had.
struct Service {
    url: String,
    sleep: f64,
    tally: PathBuf,
    stop: watch::Sender<bool>,
    coordinator: JoinHandle<()>,
    live: Vec<Worker>,
    /// Seconds lived by the workers that are gone.
    lived: f64,
    started: usize,
    _dir: tempfile::TempDir,
}

async fn stopped(mut rx: watch::Receiver<bool>) {
    let _ = rx.wait_for(|s| *s).await;
}

impl Service {
    async fn start(sleep: f64, target: f64) -> anyhow::Result<Self> {
        let dir = tempfile::tempdir()?;
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
        let url = format!("http://{}", listener.local_addr()?);
        let database = format!("sqlite://{}", dir.path().join("db.sqlite").display());
        let mut config = tslg_server::Config::embedded(&database);
        config.queue_target_seconds = target;
        let coordinator = tslg_server::Coordinator::open(config).await?;
        let (stop, rx) = watch::channel(false);
        let served = coordinator.serve(listener, stopped(rx));
        let coordinator = tokio::spawn(async move {
            served.await.expect("the coordinator");
        });
        Ok(Self {
            url,
            sleep,
            tally: dir.path().join("tally"),
            stop,
            coordinator,
            live: Vec::new(),
            lived: 0.0,
            started: 0,
            _dir: dir,
        })
    }

    /// Starts a worker offering the program `hot`.
    fn add_worker(&mut self, exit_when_idle: Option<f64>) {
        self.started += 1;
        let mut config =
            tslg_worker::WorkerConfig::local(&self.url, 1, format!("w{}", self.started));
        config.exit_when_idle_seconds = exit_when_idle;
        config.vut_exec = vec![format!(
            "hot={} --sleep {} --gain {HOT_GAIN} --tally {}",
            common::fvdm_vut_example().display(),
            self.sleep,
            self.tally.display()
        )];
        let (stop, rx) = watch::channel(false);
        let run = tslg_worker::run(config, stopped(rx));
        self.live.push(Worker {
            stop,
            task: tokio::spawn(async move {
                run.await.expect("a worker");
            }),
            started: Instant::now(),
        });
    }

    /// Forgets the workers that left by themselves, counting their time.
    fn reap(&mut self) {
        let (gone, live): (Vec<Worker>, Vec<Worker>) =
            self.live.drain(..).partition(|w| w.task.is_finished());
        self.live = live;
        for w in gone {
            // Finished: its lifetime ends about now (the loop looks every
            // second; a worker reaped late is charged up to a second more,
            // as a pod is until it is gone).
            self.lived += w.started.elapsed().as_secs_f64();
        }
    }

    /// Stops the newest worker (SIGTERM's path) and counts its time.
    async fn remove_worker(&mut self) {
        if let Some(w) = self.live.pop() {
            let _ = w.stop.send(true);
            let _ = w.task.await;
            self.lived += w.started.elapsed().as_secs_f64();
        }
    }

    /// Worker-seconds so far, the live workers' included.
    fn worker_seconds(&self) -> f64 {
        self.lived
            + self
                .live
                .iter()
                .map(|w| w.started.elapsed().as_secs_f64())
                .sum::<f64>()
    }

    /// Tests the program has started.
    fn tests_run(&self) -> u64 {
        std::fs::metadata(&self.tally).map_or(0, |m| m.len())
    }

    async fn shut(mut self) {
        while !self.live.is_empty() {
            self.remove_worker().await;
        }
        let _ = self.stop.send(true);
        let _ = self.coordinator.await;
    }
}

/// How the fleet is sized.
#[derive(Clone, Copy)]
enum Sizing {
    Fixed,
    /// Up to the queue's want; surplus workers stopped at once
    /// (`down_at_once`) or left to leave when idle.
    Autoscaled {
        target: f64,
        down_at_once: bool,
    },
}

struct Row {
    sizing: Sizing,
    walls: Vec<f64>,
    tests: u64,
    worker_seconds: f64,
    busy: f64,
    peak: usize,
    started: usize,
}

/// One autoscaler step: match the fleet to what the queue wants (down
/// only when `down_at_once`; else workers leave when idle).
async fn scale(service: &mut Service, client: &Client, down_at_once: bool) -> anyhow::Result<()> {
    service.reap();
    let queue = client.queue().await?;
    let wanted = (queue.workers_wanted as usize).min(FLEET);
    if std::env::var_os("TSLG_AUTOSCALE_TRACE").is_some() {
        eprintln!(
            "trace: live {} queue {:?}",
            service.live.len(),
            queue.programs
        );
    }
    while service.live.len() < wanted {
        service.add_worker(Some(3.0));
    }
    while down_at_once && service.live.len() > wanted {
        service.remove_worker().await;
    }
    Ok(())
}

async fn measure(sizing: Sizing, sleep: f64, gap: f64) -> anyhow::Result<Row> {
    let (target, autoscaled) = match sizing {
        Sizing::Fixed => (300.0, None),
        Sizing::Autoscaled {
            target,
            down_at_once,
        } => (target, Some(down_at_once)),
    };
    let mut service = Service::start(sleep, target).await?;
    let client = Client::new(&service.url, None)?;
    if let Sizing::Fixed = sizing {
        for _ in 0..FLEET {
            service.add_worker(None);
        }
    }
    let mut walls = Vec::new();
    let mut peak = service.live.len();
    for (k, seed) in [1u64, 2].into_iter().enumerate() {
        if k > 0 {
            // The user's pause between campaigns; the autoscaler keeps
            // looking.
            let pause = Instant::now();
            while pause.elapsed().as_secs_f64() < gap {
                if let Some(down) = autoscaled {
                    scale(&mut service, &client, down).await?;
                }
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
        }
        let started = Instant::now();
        let id = client
            .create_campaign(&common::program_campaign(Method::Ndd, "hot", None, seed))
            .await?
            .id;
        loop {
            if let Some(down) = autoscaled {
                scale(&mut service, &client, down).await?;
            }
            peak = peak.max(service.live.len());
            let view = client.campaign(id).await?;
            if view.status.is_final() {
                anyhow::ensure!(
                    view.status == tslg_api::CampaignStatus::Converged,
                    "{view:?}"
                );
                break;
            }
            tokio::time::sleep(Duration::from_secs(1)).await;
        }
        walls.push(started.elapsed().as_secs_f64());
    }
    // The fixed fleet is charged to the last stop; the autoscaled one
    // until its workers are gone (they leave within seconds of idling).
    if let Some(down) = autoscaled {
        while !service.live.is_empty() {
            scale(&mut service, &client, down).await?;
            tokio::time::sleep(Duration::from_secs(1)).await;
        }
    }
    let worker_seconds = service.worker_seconds();
    let tests = service.tests_run();
    let started = service.started;
    service.shut().await;
    Ok(Row {
        sizing,
        walls,
        tests,
        worker_seconds,
        busy: tests as f64 * sleep,
        peak,
        started,
    })
}

fn main() -> anyhow::Result<()> {
    let sleep = number("TSLG_AUTOSCALE_SLEEP", 0.05);
    let gap = number("TSLG_AUTOSCALE_GAP", 30.0);
    let targets: Vec<f64> = std::env::var("TSLG_AUTOSCALE_TARGETS")
        .unwrap_or_else(|_| "5,30".into())
        .split(',')
        .map(|t| t.trim().parse().expect("TSLG_AUTOSCALE_TARGETS: seconds"))
        .collect();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    let mut rows = Vec::new();
    let sizings = std::iter::once(Sizing::Fixed).chain(targets.iter().flat_map(|&target| {
        [true, false].map(|down_at_once| Sizing::Autoscaled {
            target,
            down_at_once,
        })
    }));
    for sizing in sizings {
        let row = runtime.block_on(measure(sizing, sleep, gap))?;
        eprintln!(
            "{}: walls {:?}, {:.0} worker-seconds",
            label(row.sizing),
            row.walls,
            row.worker_seconds
        );
        rows.push(row);
    }
    println!(
        "d = {sleep} s a test, two NDD campaigns {gap} s apart, at most {FLEET} one-thread workers"
    );
    println!();
    println!("| fleet | campaign 1 wall (s) | campaign 2 wall (s) | tests run | busy worker-s (tests × d) | worker-seconds | busy share | peak workers | workers started |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for r in &rows {
        println!(
            "| {} | {:.1} | {:.1} | {} | {:.0} | {:.0} | {:.0} % | {} | {} |",
            label(r.sizing),
            r.walls[0],
            r.walls[1],
            r.tests,
            r.busy,
            r.worker_seconds,
            100.0 * r.busy / r.worker_seconds,
            r.peak,
            r.started
        );
    }
    Ok(())
}

fn label(sizing: Sizing) -> String {
    match sizing {
        Sizing::Fixed => format!("fixed, {FLEET} workers"),
        Sizing::Autoscaled {
            target,
            down_at_once,
        } => format!(
            "autoscaled, T {target} s, down {}",
            if down_at_once { "at once" } else { "when idle" }
        ),
    }
}
