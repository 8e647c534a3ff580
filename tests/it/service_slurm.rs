//! Workers as SLURM jobs (issue 48), on a real single-node SLURM that
//! `scripts/slurm-local` starts on this machine: the coordinator runs as a
//! long job (`deploy/slurm/tslg-coordinator.sbatch`, which writes its URL
//! to a file), `deploy/slurm/tslg-worker.sbatch` submitted as a job array
//! runs an NDD campaign of a program (named in
//! `TSLG_VUT_EXEC`) and a library campaign to their stop, bit-identical to
//! the in-process runs; `scancel` mid-campaign stops the workers cleanly
//! (their leases come back at once, the answer does not change), and
//! `scripts/slurm-scale` submits the workers the queue asks for, which
//! leave by themselves once idle. Where SLURM cannot run (not root, not
//! installed), the test says SKIPPED with the reason.

use crate::support::*;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use tslg_api::{CampaignStatus, CreateCampaign, Method};

/// A single-node SLURM in a folder, stopped when dropped.
struct LocalSlurm {
    dir: PathBuf,
    conf: PathBuf,
}

impl LocalSlurm {
    /// Starts one in `dir`, or says why SLURM cannot run here (the
    /// script's exit 3: no SLURM installed, not root). Any other failure
    /// to start is the test's failure.
    fn start(dir: &Path) -> Result<Self, String> {
        let out = Command::new(repo_path("scripts/slurm-local"))
            .arg("start")
            .arg(dir)
            .output()
            .expect("scripts/slurm-local runs");
        let said = String::from_utf8_lossy(&out.stderr).trim().to_owned();
        match out.status.code() {
            Some(0) => {}
            Some(3) => return Err(said),
            _ => panic!("scripts/slurm-local start failed ({}): {said}", out.status),
        }
        Ok(Self {
            dir: dir.to_owned(),
            conf: dir.join("slurm.conf"),
        })
    }

    /// A SLURM command of this cluster.
    fn command(&self, tool: &str) -> Command {
        let mut command = Command::new(tool);
        command.env("SLURM_CONF", &self.conf);
        command
    }

    /// The jobs and array tasks queued or running (`JOB` or `JOB_TASK`).
    fn tasks(&self) -> Vec<String> {
        let out = self
            .command("squeue")
            .args(["-h", "-r", "-o", "%i"])
            .output()
            .expect("squeue");
        assert!(out.status.success(), "squeue: {out:?}");
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .map(str::to_owned)
            .collect()
    }

    /// Waits until no task that `counts` picks is queued or running.
    async fn drained(&self, limit: Duration, counts: impl Fn(&str) -> bool) {
        let started = Instant::now();
        loop {
            let tasks: Vec<String> = self.tasks().into_iter().filter(|t| counts(t)).collect();
            if tasks.is_empty() {
                return;
            }
            assert!(
                started.elapsed() < limit,
                "SLURM tasks still there after {limit:?}: {tasks:?}"
            );
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
    }
}

impl Drop for LocalSlurm {
    fn drop(&mut self) {
        let _ = Command::new(repo_path("scripts/slurm-local"))
            .arg("stop")
            .arg(&self.dir)
            .status();
    }
}

/// The coordinator job's tokens (its node is shared).
const ADMIN: &str = "adm-slurm-5c1e";
const WORKER: &str = "wrk-slurm-7a3d";

/// The folder of the service binaries (`TSLG_BIN`).
fn binaries() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_tslg-worker"))
        .parent()
        .expect("the binaries' folder")
}

/// What the worker jobs read from the environment sbatch passes them.
fn worker_environment(command: &mut Command, server: &str, program: &str) {
    command
        .env("TSLG_SERVER", server)
        .env("TSLG_WORKER_TOKEN", WORKER)
        .env("TSLG_BIN", binaries())
        .env("TSLG_VUT_EXEC", format!("{program}\n"))
        .env("TSLG_EXIT_WHEN_IDLE", "3")
        .env("TSLG_MAX_BACKOFF", "0.3");
}

/// The workers' logs, for a failure's message.
fn logs(dir: &Path) -> String {
    let mut text = String::new();
    for entry in std::fs::read_dir(dir).unwrap().flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with("tslg-") {
            text += &format!(
                "== {name}\n{}\n",
                std::fs::read_to_string(entry.path()).unwrap()
            );
        }
    }
    text
}

/// The scaling loop, killed when dropped.
struct Scaler(Option<Child>);

impl Scaler {
    /// Stops the loop; what it printed.
    fn stop(mut self) -> String {
        let mut child = self.0.take().expect("running");
        let _ = child.kill();
        let output = child.wait_with_output().expect("the loop's output");
        String::from_utf8_lossy(&output.stdout).into_owned()
    }
}

impl Drop for Scaler {
    fn drop(&mut self) {
        if let Some(child) = &mut self.0 {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_slurm_job_array_runs_campaigns_to_the_in_process_answer_and_survives_scancel() {
    let dir = scratch();
    let slurm = match LocalSlurm::start(&dir.path().join("slurm")) {
        Ok(slurm) => slurm,
        Err(why) => {
            tslg_testkit::skip("slurm", &why);
            return;
        }
    };
    let jobs = dir.path().join("jobs");
    std::fs::create_dir(&jobs).unwrap();
    // The coordinator as a long job; its URL comes from the file it writes.
    let data = dir.path().join("data");
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let out = slurm
        .command("sbatch")
        .current_dir(&jobs)
        .args(["--parsable", "--cpus-per-task=1"])
        .arg(repo_path("deploy/slurm/tslg-coordinator.sbatch"))
        .env("TSLG_DATA_DIR", &data)
        .env("TSLG_ADMIN_TOKEN", ADMIN)
        .env("TSLG_WORKER_TOKEN", WORKER)
        .env("TSLG_BIN", binaries())
        .env("TSLG_PORT", port.to_string())
        .env("TSLG_HOST", "127.0.0.1")
        .env("TSLG_QUEUE_TARGET", "2")
        .output()
        .unwrap();
    assert!(out.status.success(), "sbatch: {out:?}");
    let coordinator = String::from_utf8_lossy(&out.stdout).trim().to_owned();
    let started = Instant::now();
    let url = loop {
        if let Ok(url) = std::fs::read_to_string(data.join("coordinator-url")) {
            break url.trim().to_owned();
        }
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "no coordinator URL: {:?}\n{}",
            slurm.tasks(),
            logs(&jobs)
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    assert_eq!(url, format!("http://127.0.0.1:{port}"));
    let client = tslg_client::Client::new(&url, Some(ADMIN.into())).unwrap();
    while client.health().await.is_err() {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "the coordinator job does not answer\n{}",
            logs(&jobs)
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let library = ready_library(&client, "idm", false).await;
    // The FVDM as a program whose tests take 2 ms each (the built-in
    // FVDM's outcomes, test for test).
    let program = format!(
        "slow={} --sleep 0.002",
        example_binary("fvdm_vut").display()
    );
    let ndd = campaign(Method::Ndd, library.id, "fvdm", 0.3, 3);
    let on_program = CreateCampaign {
        vut: serde_json::json!({"external": "slow", "mode": "episode"}),
        ..ndd.clone()
    };
    let ndd_id = client.create_campaign(&on_program).await.unwrap().id;

    // Two workers as a job array, the way deploy/slurm/README.md submits them.
    let mut sbatch = slurm.command("sbatch");
    sbatch
        .current_dir(&jobs)
        .args(["--parsable", "--array=1-2", "--cpus-per-task=1"])
        .arg(repo_path("deploy/slurm/tslg-worker.sbatch"));
    worker_environment(&mut sbatch, &url, &program);
    let out = sbatch.output().unwrap();
    assert!(out.status.success(), "sbatch: {out:?}");
    let job = String::from_utf8_lossy(&out.stdout).trim().to_owned();

    let workers_job = |task: &str| task.starts_with(&format!("{job}_"));
    // scancel once both workers have reported work, mid-campaign.
    let started = Instant::now();
    loop {
        let workers = client.workers().await.unwrap().workers;
        let working = workers
            .iter()
            .filter(|w| w.name.starts_with(&format!("tslg-worker-{job}_")) && w.tests > 0)
            .count();
        if working == 2 {
            break;
        }
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "the array's workers did not both work: {:?}\n{}",
            slurm.tasks(),
            logs(&jobs)
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let status = slurm.command("scancel").arg(&job).status().unwrap();
    assert!(status.success());
    slurm
        .drained(Duration::from_secs(90), |task| workers_job(task))
        .await;
    let view = client.campaign(ndd_id).await.unwrap();
    assert_eq!(view.status, CampaignStatus::Running, "cancelled too late");
    // Each worker left by its SIGTERM path and said so; what it held was
    // given back, not left to expire: the first lease anyone takes now
    // resumes where the reported tests end.
    let text = logs(&jobs);
    assert_eq!(
        text.matches("worker stopped").count(),
        2,
        "both workers stopped cleanly:\n{text}"
    );
    // Every lease the workers held is free at once (not left to its 30 s
    // TTL): leases taken now cover the tests from where the reports end.
    let mut taken = Vec::new();
    while !taken
        .iter()
        .any(|l: &tslg_api::Lease| l.resume_at == view.indices)
    {
        let lease = client
            .claim(&ask("probe", &["slow:cut-in:episode"]))
            .await
            .unwrap()
            .unwrap_or_else(|| panic!("a held lease was not given back: {taken:?} {view:?}"));
        assert!(
            taken.len() < 64,
            "no lease resumes at {}: {taken:?}",
            view.indices
        );
        taken.push(lease);
    }
    for lease in &taken {
        client
            .release(
                lease.id,
                &tslg_api::LeaseRelease {
                    worker: "probe".into(),
                    attempt: lease.attempt,
                    key: lease.key.clone(),
                    reason: Some("probing".into()),
                },
            )
            .await
            .unwrap();
    }
    let record = slurm
        .command("scontrol")
        .args(["show", "job", &job])
        .output()
        .unwrap();
    // Exit 0, not a signal's death (ExitCode=STATUS:SIGNAL).
    let record = String::from_utf8_lossy(&record.stdout);
    assert_eq!(record.matches("ExitCode=0:0").count(), 2, "{record}");

    // Now scaled from the queue: scripts/slurm-scale submits what
    // workers_wanted asks for, at most two.
    let library_campaign = campaign(Method::Library, library.id, "fvdm", 0.2, 5);
    let library_id = client.create_campaign(&library_campaign).await.unwrap().id;
    let mut scale = Command::new(repo_path("scripts/slurm-scale"));
    scale
        .current_dir(&jobs)
        .env("SLURM_CONF", &slurm.conf)
        .args(["--interval", "1", "--max", "2", "--", "--cpus-per-task=1"])
        .stdout(Stdio::piped());
    worker_environment(&mut scale, &url, &program);
    let scaler = Scaler(Some(scale.spawn().unwrap()));
    let ndd_view = finished(&client, ndd_id, Duration::from_secs(400)).await;
    let library_view = finished(&client, library_id, Duration::from_secs(200)).await;
    assert_eq!(ndd_view.status, CampaignStatus::Converged, "{ndd_view:?}");
    assert_eq!(library_view.status, CampaignStatus::Converged);
    // The answers are the campaigns', whoever ran them and however often
    // they were stopped.
    assert_same(&ndd_view, &in_process(None, &ndd));
    assert_same(&library_view, &in_process(Some("idm"), &library_campaign));
    // Nothing is wanted any more, and the workers leave by themselves.
    assert_eq!(client.queue().await.unwrap().workers_wanted, 0);
    slurm
        .drained(Duration::from_secs(90), |task| task != coordinator)
        .await;
    let said = scaler.stop();
    assert!(said.contains("submitted job array"), "{said}");
    eprintln!("scripts/slurm-scale said:\n{said}\n{}", logs(&jobs));
    // The coordinator's job ends on scancel as on its time limit: it stops
    // by itself, its database kept for the next job.
    let status = slurm.command("scancel").arg(&coordinator).status().unwrap();
    assert!(status.success());
    slurm.drained(Duration::from_secs(90), |_| true).await;
    let log =
        std::fs::read_to_string(jobs.join(format!("tslg-coordinator-{coordinator}.out"))).unwrap();
    assert!(log.contains("shutdown requested"), "{log}");
    assert!(data.join("tslg.sqlite").exists());
}
