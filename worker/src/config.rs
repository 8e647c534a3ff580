//! The worker's settings: one clap struct, every flag also readable from
//! the environment.

use clap::Parser;

/// The longest per-test timeout and cooldown of a program, in seconds (a
/// day): a `Duration` of 10²⁰ s panics, and an `Instant` that far ahead
/// overflows.
pub const MAX_VUT_SECONDS: f64 = 86_400.0;

#[derive(Debug, Clone, Parser)]
#[command(
    name = "tslg-worker",
    version,
    about = "A tslg worker: runs the tests a coordinator hands out",
    long_about = None,
    // A leading minus is a value the range checks answer for.
    allow_negative_numbers = true
)]
/// The worker's settings: every flag also readable from the environment.
pub struct WorkerConfig {
    /// The coordinator's base URL.
    #[arg(long, env = "TSLG_SERVER", default_value = "http://127.0.0.1:8080")]
    pub server: String,

    /// Threads to simulate on (default: every core).
    #[arg(long, env = "TSLG_THREADS")]
    pub threads: Option<usize>,

    /// The worker token, sent as `Authorization: Bearer …`.
    #[arg(long, env = "TSLG_WORKER_TOKEN", hide_env_values = true)]
    pub token: Option<String>,

    /// This worker's name, unique among live workers (default: host and
    /// process id).
    #[arg(long, env = "TSLG_WORKER_NAME")]
    pub name: Option<String>,

    /// A file that keeps this worker's credential (the name the coordinator
    /// issued and its secret, mode 0600): read at start when it exists, so
    /// a restarted worker keeps its name, its results and its standing in
    /// audits; written after registering when it does not.
    #[arg(long, env = "TSLG_CREDENTIAL_FILE")]
    pub credential_file: Option<std::path::PathBuf>,

    /// The enrolment secret an administrator issued this worker's principal
    /// (`tslg worker enrol PRINCIPAL`), sent when it registers: required by
    /// a coordinator run with `--enrolment required`. Prefer the
    /// environment or `--enrolment-file` to the command line, which other
    /// users of the machine can read.
    #[arg(long, env = "TSLG_ENROLMENT_SECRET", hide_env_values = true)]
    pub enrolment: Option<String>,

    /// A file holding the enrolment secret (its first line), instead of
    /// `--enrolment`.
    #[arg(long, env = "TSLG_ENROLMENT_FILE", conflicts_with = "enrolment")]
    pub enrolment_file: Option<std::path::PathBuf>,

    /// Longest pause between polls when there is no work (seconds), for a
    /// coordinator that answers a lease request at once (`--claim-wait-seconds
    /// 0`, or its `--max-claim-wait-seconds 0`).
    #[arg(long, env = "TSLG_MAX_BACKOFF", default_value_t = 5.0)]
    pub max_backoff_seconds: f64,

    /// With no work, how long a lease request waits at the coordinator for
    /// some (long polling; 0.5 to 30 s, and at most the coordinator's
    /// `--max-claim-wait-seconds`): a campaign is leased as soon as it
    /// starts. 0 polls with backoff instead.
    #[arg(long, env = "TSLG_CLAIM_WAIT", default_value_t = 10.0)]
    pub claim_wait_seconds: f64,

    /// Exit when there has been no work for this many seconds (default:
    /// never).
    #[arg(long, env = "TSLG_EXIT_WHEN_IDLE")]
    pub exit_when_idle_seconds: Option<f64>,

    /// On SIGTERM or Ctrl-C, how long the tests already running may take
    /// to finish (seconds). They are reported; when the grace is over the
    /// programs still running a test are killed and their tests given back
    /// to the coordinator, which hands them to another worker. Either way
    /// the worker gives back every test it did not run and exits 0, at
    /// most 8 s after the grace (its last reports). Keep grace + 8 s below
    /// the platform's own limit (Kubernetes'
    /// `terminationGracePeriodSeconds`, SLURM's `KillWait`, both 30 s by
    /// default).
    #[arg(long, env = "TSLG_GRACE_SECONDS", default_value_t = 20.0)]
    pub grace_seconds: f64,

    /// An external vehicle under test, `NAME=COMMAND` (repeatable):
    /// campaigns with `"vut": {"external": "NAME"}` run COMMAND, split into
    /// words like a shell does, over the protocol of docs/vut-protocol.md.
    /// From the environment (a batch job's, a pod's): `TSLG_VUT_EXEC`, one
    /// `NAME=COMMAND` per line.
    #[arg(
        long = "vut-exec",
        value_name = "NAME=COMMAND",
        env = "TSLG_VUT_EXEC",
        value_delimiter = '\n'
    )]
    pub vut_exec: Vec<String>,

    /// Time limit of one test (and of the handshake) of an external
    /// program, in seconds.
    #[arg(long = "vut-timeout", env = "TSLG_VUT_TIMEOUT", default_value_t = 60.0)]
    pub vut_timeout_seconds: f64,

    /// Failed tests in a row after which an external program is unhealthy
    /// and no longer offered.
    #[arg(long, env = "TSLG_VUT_MAX_FAILURES", default_value_t = 5)]
    pub vut_max_failures: u32,

    /// Seconds an unhealthy program rests before it is tried again.
    #[arg(
        long = "vut-cooldown",
        env = "TSLG_VUT_COOLDOWN",
        default_value_t = 60.0
    )]
    pub vut_cooldown_seconds: f64,
}

/// The shortest wait a worker asks for: a request the coordinator held at
/// least half of it counts as held (and is asked again at once), one
/// answered sooner as not (and polled with backoff), so no setting makes an
/// idle worker ask more than about four times a second.
pub const MIN_CLAIM_WAIT: f64 = 0.5;

impl WorkerConfig {
    /// Settings for a worker in this process (the demo, tests).
    pub fn local(server: impl Into<String>, threads: usize, name: impl Into<String>) -> Self {
        Self {
            server: server.into(),
            threads: Some(threads),
            token: None,
            name: Some(name.into()),
            credential_file: None,
            enrolment: None,
            enrolment_file: None,
            max_backoff_seconds: 0.5,
            claim_wait_seconds: 10.0,
            exit_when_idle_seconds: None,
            grace_seconds: 20.0,
            vut_exec: Vec::new(),
            vut_timeout_seconds: 60.0,
            vut_max_failures: 5,
            vut_cooldown_seconds: 60.0,
        }
    }

    /// Simulation threads: `--threads`, else the machine's parallelism (at least 1).
    pub fn threads(&self) -> usize {
        self.threads
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
            .max(1)
    }

    /// The worker's name: `--name`, else `HOSTNAME-PID`.
    pub fn name(&self) -> String {
        self.name.clone().unwrap_or_else(|| {
            let host = std::env::var("HOSTNAME")
                .ok()
                .or_else(|| std::fs::read_to_string("/etc/hostname").ok())
                .map(|h| h.trim().to_owned())
                .filter(|h| !h.is_empty())
                .unwrap_or_else(|| "worker".into());
            format!("{host}-{}", std::process::id())
        })
    }

    /// Checks the settings before the worker starts.
    pub fn validate(&self) -> anyhow::Result<()> {
        anyhow::ensure!(
            self.server.starts_with("http://") || self.server.starts_with("https://"),
            "--server {} must be an http:// or https:// URL",
            self.server
        );
        anyhow::ensure!(self.threads != Some(0), "--threads must be at least 1");
        anyhow::ensure!(
            self.max_backoff_seconds.is_finite() && self.max_backoff_seconds > 0.0,
            "--max-backoff-seconds must be > 0"
        );
        anyhow::ensure!(
            self.claim_wait_seconds == 0.0
                || (MIN_CLAIM_WAIT..=tslg_api::MAX_CLAIM_WAIT_SECONDS)
                    .contains(&self.claim_wait_seconds),
            "--claim-wait-seconds must be 0 (poll) or in [{MIN_CLAIM_WAIT}, {}]",
            tslg_api::MAX_CLAIM_WAIT_SECONDS
        );
        anyhow::ensure!(
            self.vut_timeout_seconds.is_finite()
                && self.vut_timeout_seconds > 0.0
                && self.vut_timeout_seconds <= MAX_VUT_SECONDS,
            "--vut-timeout must be in (0, {MAX_VUT_SECONDS}] seconds"
        );
        anyhow::ensure!(
            self.vut_max_failures >= 1,
            "--vut-max-failures must be at least 1"
        );
        anyhow::ensure!(
            self.vut_cooldown_seconds.is_finite()
                && (0.0..=MAX_VUT_SECONDS).contains(&self.vut_cooldown_seconds),
            "--vut-cooldown must be in [0, {MAX_VUT_SECONDS}] seconds"
        );
        anyhow::ensure!(
            self.grace_seconds.is_finite() && (0.0..=MAX_VUT_SECONDS).contains(&self.grace_seconds),
            "--grace-seconds must be in [0, {MAX_VUT_SECONDS}] seconds"
        );
        anyhow::ensure!(
            self.exit_when_idle_seconds
                .is_none_or(|s| s.is_finite() && (0.0..=MAX_VUT_SECONDS).contains(&s)),
            "--exit-when-idle-seconds must be in [0, {MAX_VUT_SECONDS}] seconds"
        );
        Ok(())
    }
}
