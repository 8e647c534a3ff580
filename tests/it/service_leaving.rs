//! Workers that leave cleanly (issue 48), as pods and batch jobs do: on
//! SIGTERM a worker lets the test running finish within `--grace-seconds`
//! and reports it, or, when the grace is over, kills its program and gives
//! the test back; either way it gives back what it did not run and exits
//! 0. With `--exit-when-idle-seconds` a batch job's worker leaves by itself
//! when there is no work.

use crate::support::*;
use std::path::Path;
use std::time::{Duration, Instant};
use tslg_api::{CampaignStatus, CreateCampaign, Method};

/// The FVDM as a program whose every test sleeps `sleep` seconds first and
/// appends a byte to `tally` as it starts, so the test knows a test runs.
fn slow_program(sleep: f64, tally: &Path) -> String {
    format!(
        "slow={} --sleep {sleep} --tally {}",
        example_binary("fvdm_vut").display(),
        tally.display()
    )
}

fn on_the_program(plain: &CreateCampaign) -> CreateCampaign {
    CreateCampaign {
        vut: serde_json::json!({"external": "slow", "mode": "episode"}),
        ..plain.clone()
    }
}

/// Waits until `tally` says a test has started.
async fn a_test_started(tally: &Path) {
    let started = Instant::now();
    while std::fs::metadata(tally).map_or(0, |m| m.len()) == 0 {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "no test started"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// The queue's entry of the program: its live workers and those wanted.
async fn program_demand(client: &tslg_client::Client) -> (u32, u32) {
    let queue = client.queue().await.unwrap();
    let d = queue
        .programs
        .iter()
        .find(|d| d.program == "slow:cut-in:episode")
        .unwrap_or_else(|| panic!("{queue:?}"));
    (d.workers, d.workers_wanted)
}

/// Asserts that `worker` gets the campaign's first test at once, as its
/// lease's second attempt: the first was given back, not left to expire.
async fn given_back_from_the_start(client: &tslg_client::Client, worker: &str) {
    let lease = client
        .claim(&ask(worker, &["slow:cut-in:episode"]))
        .await
        .unwrap()
        .expect("the lease given back");
    assert_eq!((lease.resume_at, lease.attempt), (0, 2));
}

/// Tests started, by the tally.
fn started(tally: &Path) -> u64 {
    std::fs::metadata(tally).map_or(0, |m| m.len())
}

/// A worker whose program is in a test that takes `sleep` seconds, with
/// `grace` seconds to finish it once stopped: the coordinator, the
/// campaign, the tally of tests the program started, and the worker.
struct InATest {
    client: tslg_client::Client,
    campaign: i64,
    tally: std::path::PathBuf,
    worker: WorkerProcess,
    _server: ServerProcess,
    _dir: tempfile::TempDir,
}

async fn in_a_test(sleep: f64, grace: &str) -> InATest {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    let library = ready_library(&client, "idm", false).await;
    let tally = dir.path().join("tally");
    let exec = slow_program(sleep, &tally);
    let plain = campaign(Method::Ndd, library.id, "fvdm", 0.2, 5);
    let campaign = client
        .create_campaign(&on_the_program(&plain))
        .await
        .unwrap()
        .id;
    let worker = WorkerProcess::start_with(
        &server.url,
        1,
        "pod-1",
        &["--vut-exec", &exec, "--grace-seconds", grace],
    );
    a_test_started(&tally).await;
    InATest {
        client,
        campaign,
        tally,
        worker,
        _server: server,
        _dir: dir,
    }
}

impl InATest {
    /// Waits for the stopped worker to exit, and checks it exits 0.
    async fn exits_cleanly(&mut self) {
        let status = self.worker.exit_status(Duration::from_secs(90)).await;
        assert!(status.success(), "exit status {status}");
    }
}

/// A pod's worker SIGTERMed while its program is in a test ([`in_a_test`]).
async fn sigterm_during_a_test(sleep: f64, grace: &str) -> InATest {
    let mut pod = in_a_test(sleep, grace).await;
    pod.worker.signal_term();
    pod.exits_cleanly().await;
    pod
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_during_a_test_lets_it_finish_within_the_grace_and_reports_it() {
    let stopped = sigterm_during_a_test(2.0, "120").await;
    let (client, id, ran) = (&stopped.client, stopped.campaign, started(&stopped.tally));
    // The test that was running when the signal came was finished and
    // reported; nothing else started, nothing was reported invalid.
    let view = client.campaign(id).await.unwrap();
    assert_eq!(view.status, CampaignStatus::Running);
    assert_eq!(view.indices, ran, "every test started was reported");
    assert_eq!(view.tests, view.indices, "no invalid test");
    // It said it left: out of the fleet at once, and the campaign it
    // leaves behind wants a worker.
    assert_eq!(program_demand(client).await, (0, 1));
    // Whatever the worker held is free at once (the TTL is 30 s): the
    // next worker's lease starts where the reports end.
    let lease = client
        .claim(&ask("pod-2", &["slow:cut-in:episode"]))
        .await
        .unwrap()
        .expect("the rest of the campaign, at once");
    assert_eq!(lease.resume_at, view.indices);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_past_the_grace_kills_the_program_and_gives_its_test_back() {
    // A test that would take ten minutes; the grace is one second.
    let stopped = sigterm_during_a_test(600.0, "1").await;
    let (client, id, tally) = (&stopped.client, stopped.campaign, &stopped.tally);
    // Not reported at all: not as a result, not as an invalid test.
    let view = client.campaign(id).await.unwrap();
    assert_eq!((view.indices, view.tests), (0, 0), "{view:?}");
    assert_eq!(program_demand(client).await, (0, 1));
    // The program was killed, not left sleeping.
    let left = std::process::Command::new("pgrep")
        .args(["-f", &tally.display().to_string()])
        .output()
        .unwrap();
    assert!(
        left.stdout.is_empty(),
        "the program still runs: {}",
        String::from_utf8_lossy(&left.stdout)
    );
    // Its lease was given back, not left to expire: the next worker gets
    // the same tests at once, as the lease's second attempt.
    given_back_from_the_start(client, "pod-2").await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_batch_jobs_worker_runs_a_campaign_to_its_stop_and_leaves_when_idle() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    let library = ready_library(&client, "idm", false).await;
    let request = campaign(Method::Library, library.id, "fvdm", 0.2, 5);
    let id = client.create_campaign(&request).await.unwrap().id;
    let mut worker =
        WorkerProcess::start_with(&server.url, 2, "job-1", &["--exit-when-idle-seconds", "2"]);
    let status = worker.exit_status(Duration::from_secs(180)).await;
    assert!(status.success(), "exit status {status}");
    // It left only once nothing was left to do.
    let view = client.campaign(id).await.unwrap();
    assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
    assert_same(&view, &in_process(Some("idm"), &request));
    // It said it left: no longer live, at once.
    let workers = client.workers().await.unwrap().workers;
    let job = workers.iter().find(|w| w.name == "job-1").expect("listed");
    assert!(!job.live && job.left && job.tests > 0, "{job:?}");
    assert_eq!(client.queue().await.unwrap().workers_wanted, 0);
    // A job with nothing to do at all leaves too.
    let mut idle =
        WorkerProcess::start_with(&server.url, 1, "job-2", &["--exit-when-idle-seconds", "1"]);
    let status = idle.exit_status(Duration::from_secs(60)).await;
    assert!(status.success(), "exit status {status}");
}

/// Whether a process whose command line holds `marker` still runs (a
/// killed one may take a moment to go).
async fn still_running(marker: &str) -> bool {
    for _ in 0..50 {
        let out = std::process::Command::new("pgrep")
            .args(["-f", marker])
            .output()
            .unwrap();
        if out.stdout.is_empty() {
            return false;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    true
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_batch_system_signalling_every_process_costs_no_invalid_test() {
    // SLURM's scancel and preemption send SIGTERM to every process of the
    // job: the worker and, in the same instant, its program in a test.
    let mut job = in_a_test(600.0, "120").await;
    let _ = std::process::Command::new("pkill")
        .args(["-TERM", "-f", &job.tally.display().to_string()])
        .status();
    job.worker.signal_term();
    job.exits_cleanly().await;
    let (client, id, tally) = (&job.client, job.campaign, &job.tally);
    // The test its program was in is given back, not reported invalid,
    // and no other test started after the signal.
    let view = client.campaign(id).await.unwrap();
    assert_eq!(
        (view.indices, view.tests, view.invalid),
        (0, 0, 0),
        "{view:?}"
    );
    assert_eq!(started(tally), 1);
    given_back_from_the_start(client, "job-10").await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_worker_that_leaves_takes_its_programs_helpers_with_it() {
    // A program that starts a helper of its own (a simulator's server, say)
    // before it serves: the helper is in the program's process group.
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let marker = "sleep 3131.25";
    let exec = format!(
        "helped=sh -c '{marker} & exec {}'",
        example_binary("fvdm_vut").display()
    );
    let mut worker = WorkerProcess::start_with(
        &server.url,
        1,
        "job-11",
        &["--vut-exec", &exec, "--exit-when-idle-seconds", "1"],
    );
    let status = worker.exit_status(Duration::from_secs(60)).await;
    assert!(status.success(), "exit status {status}");
    assert!(
        !still_running(marker).await,
        "the program's helper outlived the worker"
    );
}
