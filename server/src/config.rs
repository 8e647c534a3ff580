//! The coordinator's settings: one clap struct, every flag also readable
//! from the environment.

use clap::Parser;
use std::net::SocketAddr;

/// The coordinator's settings: every flag also readable from the environment.
#[derive(Debug, Clone, Parser)]
#[command(
    name = "tslg-server",
    version,
    about = "The tslg campaign coordinator",
    long_about = None,
    // A leading minus is a value the range checks answer for.
    allow_negative_numbers = true
)]
pub struct Config {
    /// Address to listen on.
    #[arg(long, env = "TSLG_BIND", default_value = "127.0.0.1:8080")]
    pub bind: SocketAddr,

    /// SQLite database URL; the file is created when missing.
    #[arg(
        long,
        env = "TSLG_DATABASE_URL",
        default_value = "sqlite://tslg.sqlite"
    )]
    pub database_url: String,

    /// `full`: every acknowledged result is on stable storage (fsync at
    /// each commit) and survives a power failure; `normal`: it survives a
    /// crash of the coordinator but not of the machine, for more results
    /// per second on slow disks.
    #[arg(long, env = "TSLG_DURABILITY", value_enum, default_value = "full")]
    pub durability: crate::db::Durability,

    /// Where library builds with a built-in surrogate run: `coordinator`
    /// (in its own threads: libraries build with no worker up) or
    /// `workers` (the coordinator does no heavy simulation): an exhaustive
    /// search's run on every cell is leased to the workers as tests, as
    /// builds with a program surrogate always are; a multistart search or
    /// a car-following policy goes whole to one worker, which uploads the
    /// file.
    #[arg(
        long,
        env = "TSLG_LIBRARY_BUILDS",
        value_enum,
        default_value = "coordinator"
    )]
    pub library_builds: BuildPlace,

    /// Token workers present as `Authorization: Bearer …` on the lease
    /// endpoints. When unset, workers need no token.
    #[arg(long, env = "TSLG_WORKER_TOKEN", hide_env_values = true)]
    pub worker_token: Option<String>,

    /// Whether a worker must register with an enrolment credential an
    /// administrator issued (`POST /api/v1/enrolments`): `required` makes
    /// audits, quorums and evidence count principals, so one holder of the
    /// worker token cannot mint voters; `open` (the default) also admits
    /// workers with the worker token alone, each its own principal (one
    /// trusted cluster).
    #[arg(long, env = "TSLG_ENROLMENT", value_enum, default_value = "open")]
    pub enrolment: Enrolment,

    /// Token needed to create libraries and to start or cancel campaigns.
    /// When unset, anyone who can reach the server may.
    #[arg(long, env = "TSLG_ADMIN_TOKEN", hide_env_values = true)]
    pub admin_token: Option<String>,

    /// Token needed to read: the dashboard, `/metrics` and every `GET` of
    /// the API (the admin token also reads). Sent as `Authorization: Bearer
    /// …` or as the password of HTTP Basic authentication, which browsers
    /// ask for. When unset, reads are public. `/healthz` and the OpenAPI
    /// document are always public.
    #[arg(long, env = "TSLG_READ_TOKEN", hide_env_values = true)]
    pub read_token: Option<String>,

    /// Seconds a lease lives without a heartbeat or result before it is
    /// handed out again.
    #[arg(long, env = "TSLG_LEASE_TTL", default_value_t = 30.0)]
    pub lease_ttl_seconds: f64,

    /// Seconds of work a lease aims at, on the worker's threads.
    #[arg(long, env = "TSLG_LEASE_TARGET", default_value_t = 2.0)]
    pub lease_target_seconds: f64,

    /// Hand out leases of exactly this many tests (no adaptation); for
    /// experiments and tests.
    #[arg(long, env = "TSLG_LEASE_SIZE")]
    pub lease_size: Option<u64>,

    /// Longest a lease request waits for work when it asks to
    /// (`wait_seconds`, at most 30): below the idle timeout of any proxy
    /// in front of the coordinator.
    #[arg(long, env = "TSLG_MAX_CLAIM_WAIT", default_value_t = 10.0)]
    pub max_claim_wait_seconds: f64,

    /// The longest a waiting lease request goes without asking the store
    /// again, for work that appears without a request that wakes it (an
    /// expired lease, an adaptive campaign's next stage): its rechecks
    /// start at 50 ms and double up to this, jittered, as the workers' idle
    /// polling did. Work a request starts (a campaign, a ready library, a
    /// lease given back) wakes it at once.
    #[arg(long, env = "TSLG_CLAIM_RECHECK", default_value_t = 5.0)]
    pub claim_recheck_seconds: f64,

    /// The time in which the workers `GET /api/v1/queue` wants (and the
    /// gauge `tslg_workers_wanted`) would finish the running campaigns'
    /// predicted work, in seconds: what an autoscaler scales by.
    #[arg(long, env = "TSLG_QUEUE_TARGET", default_value_t = 300.0)]
    pub queue_target_seconds: f64,

    /// Largest request body accepted, in bytes (uploaded tables included).
    #[arg(long, env = "TSLG_MAX_BODY", default_value_t = 16 * 1024 * 1024)]
    pub max_body_bytes: usize,

    /// Built-in vehicles: the share of reported tests without an event that
    /// the coordinator runs again to check them (drawn by a secret generator);
    /// every reported event is run again. A mismatch refuses the report and
    /// flags the worker (docs/operations.md, "Results are checked").
    #[arg(long, env = "TSLG_REPLAY_SHARE", default_value_t = 0.1)]
    pub replay_share: f64,

    /// External programs: the share of reported tests run again by a
    /// different worker (drawn by a secret generator) before the campaign's
    /// prefix passes them.
    #[arg(long, env = "TSLG_AUDIT_SHARE", default_value_t = 0.01)]
    pub audit_share: f64,

    /// External programs: an event is also run again by a different worker
    /// when it would carry at least this share of the estimate,
    /// `w ≥ share · (S₁ + w)`. 1 turns this off.
    #[arg(long, env = "TSLG_AUDIT_WEIGHT_SHARE", default_value_t = 0.05)]
    pub audit_weight_share: f64,
}

/// Whether workers enrol ([`Config::enrolment`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Enrolment {
    /// The worker token alone registers a worker (its own principal); an
    /// enrolment, when given, must be valid.
    Open,
    /// Registration needs an enrolment credential.
    Required,
}

/// Where a library build with a built-in surrogate runs
/// ([`Config::library_builds`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BuildPlace {
    /// In the coordinator's threads.
    Coordinator,
    /// On the workers: cell by cell (exhaustive), or whole on one.
    Workers,
}

impl Config {
    /// Settings for an embedded coordinator (the demo, tests).
    pub fn embedded(database_url: impl Into<String>) -> Self {
        // A few local workers: rechecks at most half a second apart, as
        // the local workers' polling was.
        Self::parse_from([
            "tslg-server",
            "--database-url",
            &database_url.into(),
            "--claim-recheck-seconds",
            "0.5",
        ])
    }

    /// Checks ranges clap cannot express.
    pub fn validate(&self) -> anyhow::Result<()> {
        anyhow::ensure!(
            (0.0..=tslg_api::MAX_CLAIM_WAIT_SECONDS).contains(&self.max_claim_wait_seconds),
            "--max-claim-wait-seconds {} must be in [0, {}]",
            self.max_claim_wait_seconds,
            tslg_api::MAX_CLAIM_WAIT_SECONDS
        );
        anyhow::ensure!(
            (0.05..=60.0).contains(&self.claim_recheck_seconds),
            "--claim-recheck-seconds {} must be in [0.05, 60]",
            self.claim_recheck_seconds
        );
        anyhow::ensure!(
            self.lease_ttl_seconds.is_finite() && self.lease_ttl_seconds >= 1.0,
            "--lease-ttl-seconds {} must be at least 1",
            self.lease_ttl_seconds
        );
        anyhow::ensure!(
            self.lease_target_seconds.is_finite() && self.lease_target_seconds > 0.0,
            "--lease-target-seconds {} must be > 0",
            self.lease_target_seconds
        );
        anyhow::ensure!(
            self.queue_target_seconds.is_finite() && self.queue_target_seconds >= 1.0,
            "--queue-target-seconds {} must be at least 1",
            self.queue_target_seconds
        );
        anyhow::ensure!(
            self.lease_size != Some(0),
            "--lease-size must be at least 1"
        );
        for (name, share) in [
            ("--replay-share", self.replay_share),
            ("--audit-share", self.audit_share),
            ("--audit-weight-share", self.audit_weight_share),
        ] {
            anyhow::ensure!(
                (0.0..=1.0).contains(&share),
                "{name} {share} must be in [0, 1]"
            );
        }
        for (name, token) in [
            ("TSLG_WORKER_TOKEN", &self.worker_token),
            ("TSLG_ADMIN_TOKEN", &self.admin_token),
            ("TSLG_READ_TOKEN", &self.read_token),
        ] {
            if let Some(t) = token {
                anyhow::ensure!(!t.is_empty(), "{name} is set but empty");
            }
        }
        // Protecting leases or reads while anyone may create and cancel
        // campaigns is a mistake, not a configuration.
        anyhow::ensure!(
            self.enrolment == Enrolment::Open || self.admin_token.is_some(),
            "TSLG_ENROLMENT=required without TSLG_ADMIN_TOKEN: anyone could issue \
             enrolments; set TSLG_ADMIN_TOKEN too"
        );
        anyhow::ensure!(
            self.admin_token.is_some()
                || (self.worker_token.is_none() && self.read_token.is_none()),
            "TSLG_WORKER_TOKEN or TSLG_READ_TOKEN is set without TSLG_ADMIN_TOKEN: anyone \
             could create and cancel campaigns; set TSLG_ADMIN_TOKEN too"
        );
        Ok(())
    }
}
