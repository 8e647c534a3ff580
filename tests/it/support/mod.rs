//! Helpers of the end-to-end tests: the real `tslg-server` and
//! `tslg-worker` binaries started as processes on free ports with fresh
//! databases, and the in-process reference runs they are compared with.
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use tslg_api::{
    CampaignView, CreateCampaign, CreateLibrary, Lease, LeaseRequest, LibraryStatus, LibraryView,
    Method,
};
use tslg_client::Client;
use tslg_method::campaign::{run_campaign_tests, CampaignResult};
use tslg_method::cases::open_case;
use tslg_method::estimator::{default_n_min, StoppingRule};
use tslg_method::library::SearchMethod;
use tslg_method::registry::{BuildRequest, ExposureSource, LibrarySearch};

/// A `tslg-server` process; killed when dropped.
pub struct ServerProcess {
    child: Child,
    pub url: String,
    pub address: String,
    pub database: PathBuf,
    /// Everything the coordinator wrote to stderr (its log) so far.
    log: std::sync::Arc<std::sync::Mutex<String>>,
}

impl ServerProcess {
    /// Starts a coordinator on a free loopback port.
    pub fn start(database: &Path, extra: &[&str]) -> Self {
        Self::start_on(database, "127.0.0.1:0", extra)
    }

    /// Starts a coordinator on `bind`, waiting until it listens.
    pub fn start_on(database: &Path, bind: &str, extra: &[&str]) -> Self {
        let mut command = Command::new(env!("CARGO_BIN_EXE_tslg-server"));
        command
            .args(["--bind", bind, "--database-url"])
            .arg(format!("sqlite://{}", database.display()))
            .args(extra);
        Self::spawn(command, database)
    }

    /// Starts a prepared `tslg-server` command (its bind address must be
    /// free or port 0), waiting until it reports the address it listens on.
    pub fn spawn(mut command: Command, database: &Path) -> Self {
        if !command.get_envs().any(|(k, _)| k == "RUST_LOG") {
            command.env("RUST_LOG", "info");
        }
        let mut child = command
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start tslg-server");
        let stderr = child.stderr.take().expect("stderr");
        let (tx, rx) = mpsc::channel();
        let log = std::sync::Arc::new(std::sync::Mutex::new(String::new()));
        let sink = std::sync::Arc::clone(&log);
        std::thread::spawn(move || {
            let mut tx = Some(tx);
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                let mut log = sink.lock().unwrap();
                log.push_str(&line);
                log.push('\n');
                drop(log);
                if let Some(at) = line.find("address=") {
                    if let Some(tx) = tx.take() {
                        let address = line[at + 8..]
                            .split_whitespace()
                            .next()
                            .unwrap_or("")
                            .to_owned();
                        let _ = tx.send(address);
                    }
                }
            }
        });
        let address = rx
            .recv_timeout(Duration::from_secs(60))
            .expect("tslg-server did not report its address");
        Self {
            child,
            url: format!("http://{address}"),
            address,
            database: database.to_owned(),
            log,
        }
    }

    /// The coordinator's log so far.
    pub fn log(&self) -> String {
        self.log.lock().unwrap().clone()
    }

    /// The first line of the log that `wanted` picks, waiting for it up to
    /// ten seconds (the log arrives through a pipe, after the response).
    pub fn log_line(&self, wanted: impl Fn(&str) -> bool) -> Option<String> {
        let started = Instant::now();
        loop {
            if let Some(line) = self.log().lines().find(|l| wanted(l)) {
                return Some(line.to_owned());
            }
            if started.elapsed() > Duration::from_secs(10) {
                return None;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// SIGTERM, then waits (up to a minute, a hang guard) for the
    /// coordinator to exit by itself.
    pub fn terminate(mut self) -> std::process::ExitStatus {
        let _ = Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status();
        exited_within(&mut self.child, Duration::from_secs(60))
    }

    /// SIGKILL: no shutdown, no flush beyond what was committed.
    pub fn kill(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    pub fn client(&self) -> Client {
        Client::new(&self.url, None).expect("client")
    }
}

impl Drop for ServerProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A `tslg-worker` process; killed when dropped.
pub struct WorkerProcess(pub Child);

impl WorkerProcess {
    pub fn start(url: &str, threads: usize, name: &str) -> Self {
        Self::start_with(url, threads, name, &[])
    }

    /// A worker with `extra` arguments (such as `--vut-exec NAME=COMMAND`).
    pub fn start_with(url: &str, threads: usize, name: &str, extra: &[&str]) -> Self {
        let child = Command::new(env!("CARGO_BIN_EXE_tslg-worker"))
            .args([
                "--server",
                url,
                "--threads",
                &threads.to_string(),
                "--name",
                name,
            ])
            .args(["--max-backoff-seconds", "0.3"])
            .args(extra)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start tslg-worker");
        Self(child)
    }

    /// SIGKILL: the worker vanishes without releasing its lease.
    pub fn kill(mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }

    /// SIGTERM, then waits (up to a minute, a hang guard) for the worker
    /// to exit by itself.
    pub fn terminate(mut self) -> std::process::ExitStatus {
        self.signal_term();
        exited_within(&mut self.0, Duration::from_secs(60))
    }

    /// Sends SIGTERM, as Kubernetes or `scancel` do, without waiting.
    pub fn signal_term(&self) {
        let _ = Command::new("kill")
            .args(["-TERM", &self.0.id().to_string()])
            .status();
    }

    /// Waits for the worker to exit by itself; fails (and kills it) when
    /// it has not after `limit`, a guard against a hang, not a speed check.
    pub async fn exit_status(&mut self, limit: Duration) -> std::process::ExitStatus {
        let started = Instant::now();
        loop {
            if let Some(status) = self.0.try_wait().expect("try_wait") {
                return status;
            }
            assert!(
                started.elapsed() < limit,
                "the worker did not exit within {limit:?}"
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }
}

impl Drop for WorkerProcess {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Two one-thread workers, `w1` and `w2`, on the coordinator at `url`.
pub fn two_workers(url: &str) -> [WorkerProcess; 2] {
    [
        WorkerProcess::start(url, 1, "w1"),
        WorkerProcess::start(url, 1, "w2"),
    ]
}

/// The value of the metric `name` in the coordinator's `/metrics` at
/// `url` (with its labels, as the exposition writes them, if it has any).
pub async fn scraped(url: &str, name: &str) -> f64 {
    let metrics = reqwest::get(format!("{url}/metrics"))
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    metrics
        .lines()
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' '))
        .unwrap_or_else(|| panic!("{name} missing from /metrics:\n{metrics}"))
        .parse()
        .unwrap()
}

/// Waits (at most a minute) until the coordinator at `url` holds at least
/// `n` lease requests waiting for work (`tslg_lease_requests_waiting`):
/// workers that asked and found nothing. Tests wait for it where a fixed
/// sleep would come too soon on a loaded host.
pub async fn until_waiting(url: &str, n: f64) {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let waiting = scraped(url, "tslg_lease_requests_waiting").await;
        if waiting >= n {
            return;
        }
        assert!(
            Instant::now() < deadline,
            "{waiting} lease requests waiting after a minute, not {n}"
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

/// Waits for `child` to exit; kills it and fails after `limit`.
fn exited_within(child: &mut Child, limit: Duration) -> std::process::ExitStatus {
    let started = Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("try_wait") {
            return status;
        }
        if started.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("the process did not exit within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Whether a process refused cleanly: a non-zero exit of its own (1 for
/// an error, 2 for bad usage, 3 for a failed gate), not a panic (Rust's
/// exit 101) nor death by a signal, which `!status.success()` would accept.
pub fn clean_refusal(out: &std::process::Output) -> bool {
    matches!(out.status.code(), Some(code) if code != 0 && code != 101)
}

/// Runs the `tslg` command with `args` (without an exposure table from the
/// environment) and waits for it (up to [`COMMAND_LIMIT`]).
pub fn tslg(args: &[&str]) -> std::process::Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_tslg"));
    command.args(args).env_remove("TSLG_NDD_TABLE");
    output_within(command, COMMAND_LIMIT)
}

/// How long a command a test runs may take before the test fails: a guard
/// against a hang (a `--wait` that never ends), not a speed check.
pub const COMMAND_LIMIT: Duration = Duration::from_secs(30 * 60);

/// Runs `command` with its output captured, as `Command::output`, but
/// kills it and fails after `limit`.
pub fn output_within(mut command: Command, limit: Duration) -> std::process::Output {
    let child = command
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("{command:?}: {e}"));
    wait_within(child, limit)
}

/// Waits for `child` to exit by itself, reading what is left of its
/// stdout and stderr meanwhile (a full pipe would stop it); kills it and
/// fails after `limit`.
pub fn wait_within(mut child: Child, limit: Duration) -> std::process::Output {
    use std::io::Read;
    fn drain(pipe: Option<impl Read + Send + 'static>) -> std::thread::JoinHandle<Vec<u8>> {
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            if let Some(mut pipe) = pipe {
                let _ = pipe.read_to_end(&mut bytes);
            }
            bytes
        })
    }
    let (stdout, stderr) = (drain(child.stdout.take()), drain(child.stderr.take()));
    let status = exited_within(&mut child, limit);
    std::process::Output {
        status,
        stdout: stdout.join().expect("stdout read"),
        stderr: stderr.join().expect("stderr read"),
    }
}

pub fn scratch() -> tempfile::TempDir {
    tempfile::tempdir().expect("tempdir")
}

/// Builds a cut-in library on the coordinator and waits until it is ready.
pub async fn ready_library(client: &Client, surrogate: &str, exhaustive: bool) -> LibraryView {
    let request = CreateLibrary {
        case: "cut-in".into(),
        preset: None,
        surrogate: serde_json::json!({ "model": surrogate }),
        exposure: Default::default(),
        search: exhaustive.then_some(tslg_api::SearchRequest::Exhaustive),
        threshold: None,
    };
    build_library(client, &request).await
}

/// Builds the library `request` asks for and waits until it is ready.
pub async fn build_library(client: &Client, request: &CreateLibrary) -> LibraryView {
    let mut view = client
        .create_library(request)
        .await
        .expect("create library");
    let started = Instant::now();
    while view.status == LibraryStatus::Building {
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "library build hangs"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
        view = client.library(view.id).await.expect("library");
    }
    assert_eq!(view.status, LibraryStatus::Ready, "{:?}", view.error);
    view
}

/// A campaign request with the defaults the tests vary from.
pub fn campaign(
    method: Method,
    library_id: i64,
    vut: &str,
    beta: f64,
    seed: u64,
) -> CreateCampaign {
    CreateCampaign {
        library_id: Some(library_id),
        beta,
        seed,
        guard_outside: Some(false),
        ..CreateCampaign::new("cut-in", method, serde_json::json!({ "model": vut }))
    }
}

/// Polls a campaign until `ready` holds for it, failing after `limit`.
pub async fn wait_for(
    client: &Client,
    id: i64,
    limit: Duration,
    ready: impl Fn(&CampaignView) -> bool,
) -> CampaignView {
    let started = Instant::now();
    loop {
        let view = client.campaign(id).await.expect("campaign");
        if ready(&view) {
            return view;
        }
        assert!(
            started.elapsed() < limit,
            "campaign {id} not there in {limit:?}: {view:?}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// Polls a campaign until it stops.
pub async fn finished(client: &Client, id: i64, limit: Duration) -> CampaignView {
    wait_for(client, id, limit, |view| view.status.is_final()).await
}

/// Asks for a lease as `worker` (one thread, no inline tests).
/// A plain HTTP client that sends `worker`'s secret, as `client`
/// registered it, with every request (for requests built by hand).
pub fn worker_http(client: &Client, worker: &str) -> reqwest::Client {
    let secret = client
        .secret_of(worker)
        .unwrap_or_else(|| panic!("worker `{worker}` is not registered by this client"));
    let mut headers = reqwest::header::HeaderMap::new();
    headers.insert(
        tslg_api::WORKER_SECRET_HEADER,
        reqwest::header::HeaderValue::from_str(&secret).unwrap(),
    );
    reqwest::Client::builder()
        .default_headers(headers)
        .build()
        .unwrap()
}

pub async fn claim(client: &Client, worker: &str) -> Option<Lease> {
    client
        .claim(&LeaseRequest {
            worker: worker.into(),
            threads: 1,
            include_tests: false,
            offers: Vec::new(),
            unhealthy: Vec::new(),
            max_tests: None,
            wait_seconds: None,
            audits_only: false,
            noisy: Vec::new(),
        })
        .await
        .expect("lease request")
}

/// The events of tests `from..to` of campaign `id` as an honest worker
/// finds them: the campaign prepared from its plan, as a worker does, and
/// each test run in this process.
pub async fn real_events(
    client: &Client,
    id: i64,
    from: u64,
    to: u64,
) -> Vec<tslg_api::EventResult> {
    let prepared = tslg_worker::prepared::Cache::default()
        .get(client, id)
        .await
        .expect("the campaign's plan")
        .tests()
        .expect("a campaign of tests");
    (from..to)
        .filter_map(|index| {
            let outcome = prepared.tests.run(index);
            outcome.event.then_some(tslg_api::EventResult {
                index,
                weight: outcome.weight,
            })
        })
        .collect()
}

/// The exhaustive cut-in library of `surrogate` on the built-in exposure.
fn exhaustive_library(surrogate: &str) -> Vec<u8> {
    open_case("cut-in", None, &ExposureSource::Builtin)
        .unwrap()
        .build_library(
            &serde_json::json!({ "model": surrogate }),
            &BuildRequest {
                threshold: None,
                search: Some(LibrarySearch::Cells(SearchMethod::Exhaustive)),
            },
        )
        .unwrap()
        .file
}

/// The same campaign run in this process (built-in exposure, exhaustive
/// cut-in library of `surrogate` when `library`).
pub fn in_process(surrogate: Option<&str>, request: &CreateCampaign) -> CampaignResult {
    let library = surrogate.map(exhaustive_library);
    in_process_with_file(library.as_deref(), None, request)
}

/// [`in_process`] switched at `explore_from` as the service's campaign was
/// (an anytime library campaign's switch depends on when its leases were
/// handed out; given it, the run is the same to the bit).
pub fn in_process_switched(
    surrogate: &str,
    request: &CreateCampaign,
    explore_from: Option<u64>,
) -> CampaignResult {
    let tests = campaign_tests(Some(&exhaustive_library(surrogate)), None, request);
    assert!(tests.set_explore_from(explore_from));
    run_campaign_tests(tests.as_ref(), &rule_of(request), &|_| false)
}

/// The campaign `request` run in this process on the library `file` (the
/// NDD when `None`) of the case's `preset`.
pub fn in_process_with_file(
    file: Option<&[u8]>,
    preset: Option<&str>,
    request: &CreateCampaign,
) -> CampaignResult {
    in_process_with_invalid(file, preset, request, &|_| false)
}

/// [`in_process_with_file`] where the tests `invalid` picks have no valid
/// outcome, as a worker reports tests its vehicle failed to run.
pub fn in_process_with_invalid(
    file: Option<&[u8]>,
    preset: Option<&str>,
    request: &CreateCampaign,
    invalid: &(dyn Fn(u64) -> bool + Sync),
) -> CampaignResult {
    let tests = campaign_tests(file, preset, request);
    run_campaign_tests(tests.as_ref(), &rule_of(request), invalid)
}

/// The tests of campaign `request` as the coordinator builds them, on the
/// library `file` (the NDD when `None`) of the case's `preset`, with the
/// coordinator's default spread.
fn campaign_tests(
    file: Option<&[u8]>,
    preset: Option<&str>,
    request: &CreateCampaign,
) -> std::sync::Arc<dyn tslg_method::registry::CampaignTests> {
    let case = open_case(&request.case, preset, &ExposureSource::Builtin).unwrap();
    let outside = match request.outside {
        Some(o) => o.as_str().parse().unwrap(),
        None => tslg_method::sampling::default_outside(case.default_outside(), &rule_of(request)),
    };
    let split = request
        .split
        .map_or(Default::default(), tslg_client::wire::split);
    case.campaign(
        file,
        &request.vut,
        request.epsilon,
        outside,
        split,
        request.seed,
    )
    .unwrap()
}

/// The stopping rule of `request` with the coordinator's defaults.
pub fn rule_of(request: &CreateCampaign) -> StoppingRule {
    StoppingRule {
        beta: request.beta,
        confidence: request.confidence,
        n_min: request.n_min.unwrap_or_else(|| {
            default_n_min(
                tslg_method::cases::descriptor(&request.case)
                    .unwrap()
                    .exploring_share(request.method == Method::Library, request.epsilon),
                request.max_tests,
            )
        }),
        min_events: request.min_events.unwrap_or(10),
        max_tests: request.max_tests,
        guard_outside: tslg_client::wire::guard_outside(
            request,
            tslg_method::cases::descriptor(&request.case)
                .unwrap()
                .is_grid(),
        ),
        interval: tslg_client::wire::interval(request.interval),
    }
}

/// Asserts that a service campaign ended exactly where the in-process run did.
pub fn assert_same(view: &CampaignView, reference: &CampaignResult) {
    assert_eq!(view.indices, reference.indices, "stop index");
    assert_eq!(view.tests, reference.tests, "tests");
    assert_eq!(view.events, reference.events, "events");
    assert_eq!(view.invalid, reference.invalid, "invalid");
    let bits = |x: Option<f64>| x.map(f64::to_bits);
    assert_eq!(
        bits(view.estimate),
        Some(reference.estimate.to_bits()),
        "estimate"
    );
    assert_eq!(
        bits(view.ci_low),
        Some(reference.ci_low.to_bits()),
        "ci_low"
    );
    assert_eq!(
        bits(view.ci_high),
        Some(reference.ci_high.to_bits()),
        "ci_high"
    );
    assert_eq!(
        view.effective_events.map(f64::to_bits),
        (reference.events > 0).then(|| reference.effective_events.to_bits()),
        "effective events"
    );
    assert_eq!(
        view.largest_weight_share.map(f64::to_bits),
        reference.largest_weight_share.map(f64::to_bits),
        "largest weight share"
    );
    assert_eq!(
        (
            view.outside_tests,
            view.outside_events,
            view.mismatched_events
        ),
        (
            reference.outside_tests,
            reference.outside_events,
            reference.mismatched_events
        ),
        "exploring tests and their events"
    );
    for (name, served, own) in [
        ("outside share", view.outside_share, reference.outside_share),
        ("outside upper", view.outside_upper, reference.outside_upper),
        (
            "guarded ci_high",
            view.guarded_ci_high,
            reference.guarded_ci_high,
        ),
    ] {
        assert_eq!(served.map(f64::to_bits), own.map(f64::to_bits), "{name}");
    }
}

/// The exact P(A) of a built-in vehicle on the built-in exposure.
pub fn exact(vut: &str) -> f64 {
    open_case("cut-in", None, &ExposureSource::Builtin)
        .unwrap()
        .exact_event_probability(&serde_json::json!({ "model": vut }))
        .unwrap()
}

/// A library's picture from the coordinator, parsed: its texts, and the
/// coloured cells of the left map (exposure) and of the right map (the
/// library's distribution), told apart by position (each map's colour
/// bar, `COLOUR_STEPS` rectangles, left out).
pub async fn library_picture(url: &str, id: i64) -> (Vec<String>, usize, usize) {
    let response = reqwest::get(format!("{url}/api/v1/libraries/{id}/figures/picture.svg"))
        .await
        .unwrap();
    assert_eq!(response.status(), 200);
    assert_eq!(response.headers()["content-type"], "image/svg+xml");
    let svg = response.text().await.unwrap();
    let doc = roxmltree::Document::parse(&svg).expect("the picture is XML");
    let width: f64 = doc
        .root_element()
        .attribute("width")
        .unwrap()
        .parse()
        .unwrap();
    let texts = doc
        .descendants()
        .filter_map(|n| n.has_tag_name("text").then(|| n.text()).flatten())
        .map(|t| t.trim().to_owned())
        .collect();
    let (mut left, mut right) = (0, 0);
    for cell in doc
        .descendants()
        .filter(|n| n.has_tag_name("rect") && n.attribute("fill") != Some("#FFFFFF"))
    {
        let x: f64 = cell.attribute("x").unwrap().parse().unwrap();
        if x < width / 2.0 {
            left += 1;
        } else {
            right += 1;
        }
    }
    let bar = tslg_figures::COLOUR_STEPS;
    (texts, left - bar, right - bar)
}

/// The NDD campaign of the IDM that the recovery, backup and upgrade tests
/// disturb while it runs (β 0.02, seed 9). It stops at test 7,233,017 (by
/// `tslg evaluate`), far past the 60,000–200,000 tests after which they
/// disturb it: at β 0.04 it stopped at 1.8 × 10⁶, under 0.2 s of a fast
/// worker after the disturbance was due, so a fast host could miss it.
pub fn disturbed_ndd(library_id: i64) -> CreateCampaign {
    campaign(Method::Ndd, library_id, "idm", 0.02, 9)
}

/// A coordinator on `database` started with `options`, one worker `w1`,
/// and [`disturbed_ndd`] run past 100,000 tests and still running: the
/// set-up of the backup and upgrade tests.
pub struct MidCampaign {
    pub server: ServerProcess,
    pub worker: WorkerProcess,
    pub request: CreateCampaign,
    pub id: i64,
    pub view: CampaignView,
}

impl MidCampaign {
    pub async fn start(database: &Path, options: &[&str]) -> Self {
        let server = ServerProcess::start(database, options);
        let worker = WorkerProcess::start(&server.url, 1, "w1");
        let client = server.client();
        let library = ready_library(&client, "idm", false).await;
        let request = disturbed_ndd(library.id);
        let id = client.create_campaign(&request).await.unwrap().id;
        let view = wait_for(&client, id, Duration::from_secs(120), |v| {
            v.indices >= 100_000
        })
        .await;
        assert_eq!(
            view.status,
            tslg_api::CampaignStatus::Running,
            "the campaign stopped before the disturbance"
        );
        Self {
            server,
            worker,
            request,
            id,
            view,
        }
    }
}

/// `path` in the repository, as a string.
pub fn repo_path(path: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(path)
        .display()
        .to_string()
}

/// `NAME=python3 FILE ARGS` for `--vut-exec`.
pub fn python(name: &str, file: &str, args: &str) -> String {
    format!("{name}=python3 {} {args}", repo_path(file))
}

/// A worker's lease request: one thread, offering `offers`.
pub fn ask(worker: &str, offers: &[&str]) -> tslg_api::LeaseRequest {
    tslg_api::LeaseRequest {
        worker: worker.into(),
        threads: 1,
        include_tests: false,
        offers: offers.iter().map(|o| o.to_string()).collect(),
        unhealthy: Vec::new(),
        max_tests: None,
        wait_seconds: None,
        audits_only: false,
        noisy: Vec::new(),
    }
}

/// A report of `lease` whole, with `events`.
pub fn whole(
    lease: &tslg_api::Lease,
    worker: &str,
    events: Vec<tslg_api::EventResult>,
) -> tslg_api::ResultReport {
    tslg_api::ResultReport {
        next_lease: None,
        near_misses: Vec::new(),
        worker: worker.into(),
        attempt: lease.attempt,
        key: lease.key.clone(),
        from: lease.resume_at,
        to: lease.end,
        events,
        packed_events: None,
        invalid: Vec::new(),
        compute_seconds: 0.0,
        threads: 1,
    }
}

/// The events of `lease` as the campaign's tests really give them.
pub fn honest_events(
    tests: &dyn tslg_method::registry::CampaignTests,
    lease: &tslg_api::Lease,
) -> Vec<tslg_api::EventResult> {
    (lease.resume_at..lease.end)
        .filter_map(|index| {
            let outcome = tests.run(index);
            outcome.event.then_some(tslg_api::EventResult {
                index,
                weight: outcome.weight,
            })
        })
        .collect()
}

/// The debug build's example program `name` (`examples/NAME.rs`), built
/// with the tests.
pub fn example_binary(name: &str) -> PathBuf {
    built_example("this test", name)
}

/// The path of example `name`, built: a test that started workers on a
/// missing program would wait for them until its time ran out.
pub fn built_example(needed_by: &str, name: &str) -> PathBuf {
    let path = Path::new(env!("CARGO_BIN_EXE_tslg"))
        .parent()
        .expect("the binaries' folder")
        .join("examples")
        .join(name);
    assert!(
        path.is_file(),
        "{needed_by} needs the example `{name}`, which is not built ({}): `cargo test \
         --workspace` builds the examples; before `cargo test --test it` alone, run `cargo build \
         --workspace --examples`",
        path.display()
    );
    path
}
