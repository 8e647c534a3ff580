//! The `tslg` client commands against a real coordinator and worker, and
//! invalid outcomes through the service.

use crate::support::*;
use std::process::Command;
use tslg_api::{CampaignView, CreateCampaign, InvalidResult, LibraryView, Method, ResultReport};

#[test]
fn library_create_and_campaign_start_status_cancel_drive_a_coordinator() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let _worker = WorkerProcess::start(&server.url, 1, "w1");
    let url = server.url.as_str();
    let o = tslg(&[
        "library",
        "create",
        "--server",
        url,
        "--surrogate",
        "fvdm",
        "--search",
        "exhaustive",
        "--wait",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let library: LibraryView = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!((library.size, library.total_scenarios), (Some(329), 3420));
    let id = library.id.to_string();
    // Without --json, the summary `tslg library build` prints of a file.
    let o = tslg(&[
        "library",
        "create",
        "--server",
        url,
        "--surrogate",
        "fvdm",
        "--wait",
    ]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("surrogate          fvdm")
            && text.contains("of 3420 scenarios")
            && text.contains("mu_S               ")
            && !text.contains("\"mu_s\""),
        "{text}"
    );
    let o = tslg(&[
        "campaign",
        "start",
        "--server",
        url,
        "--library-id",
        &id,
        "--vut",
        "idm",
        "--seed",
        "7",
        "--wait",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let view: CampaignView = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(view.status.as_str(), "converged");
    assert_same(
        &view,
        &in_process(Some("fvdm"), &campaign(Method::Library, 0, "idm", 0.2, 7)),
    );
    let o = tslg(&["campaign", "status", &view.id.to_string(), "--server", url]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("converged")
            && text.contains(&format!(
                "{} tests used ({} valid",
                view.indices, view.tests
            )),
        "{text}"
    );
    let health = format!(
        "sampling health: {:.1} effective events of {}, largest weight {:.1}% of the estimate",
        view.effective_events.unwrap(),
        view.events,
        view.largest_weight_share.unwrap() * 100.0
    );
    assert!(text.contains(&health), "{text}");
    // A long NDD baseline, cancelled; cancelling again is refused.
    let o = tslg(&[
        "campaign",
        "start",
        "--server",
        url,
        "--method",
        "ndd",
        "--vut",
        "idm",
        "--beta",
        "0.001",
        "--max-tests",
        "1000000000",
        "--json",
    ]);
    let ndd: CampaignView = serde_json::from_slice(&o.stdout).unwrap();
    // Listed, a line each, and by state.
    let o = tslg(&["campaign", "list", "--server", url, "--status", "running"]);
    let text = String::from_utf8_lossy(&o.stdout);
    let lines: Vec<&str> = text.lines().skip(1).collect();
    assert_eq!(lines.len(), 1, "{text}");
    assert!(
        lines[0].trim_start().starts_with(&format!("{} ", ndd.id)) && lines[0].contains("ndd"),
        "{text}"
    );
    let o = tslg(&["campaign", "list", "--server", url]);
    assert_eq!(String::from_utf8_lossy(&o.stdout).lines().count(), 3);
    let o = tslg(&["campaign", "list", "--server", url, "--status", "runing"]);
    assert!(clean_refusal(&o));
    assert!(String::from_utf8_lossy(&o.stderr).contains("unknown variant `runing`"));
    let o = tslg(&["library", "list", "--server", url, "--status", "ready"]);
    assert_eq!(String::from_utf8_lossy(&o.stdout).lines().count(), 3);
    // A reader that stops early ends the command quietly, not in a panic.
    let mut head = Command::new(env!("CARGO_BIN_EXE_tslg"))
        .args(["campaign", "list", "--server", url])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(head.stdout.take());
    let o = head.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!String::from_utf8_lossy(&o.stderr).contains("panicked"));
    let o = tslg(&["campaign", "cancel", &ndd.id.to_string(), "--server", url]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("cancelled"));
    // A cancelled campaign's verdict says it is none.
    let o = tslg(&["campaign", "status", &ndd.id.to_string(), "--server", url]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.lines().any(|l| l.starts_with("  verdict: cancelled")
            && (l.contains("not a verdict") || l.contains("no verdict"))),
        "{text}"
    );
    let o = tslg(&["campaign", "cancel", &ndd.id.to_string(), "--server", url]);
    assert!(clean_refusal(&o));
    assert!(String::from_utf8_lossy(&o.stderr).contains("refused (409)"));
    let o = tslg(&[
        "campaign",
        "start",
        "--server",
        url,
        "--library-id",
        &id,
        "--vut",
        "idm",
        "--beta",
        "2",
    ]);
    assert!(clean_refusal(&o));
    assert!(String::from_utf8_lossy(&o.stderr).contains("beta = 2 must be in [0.0001, 0.99]"));
    // Into a log (stderr not a terminal), `--wait` prints the running
    // campaign's state every TSLG_PROGRESS_EVERY seconds, then its end.
    let mut command = Command::new(env!("CARGO_BIN_EXE_tslg"));
    command
        .args(["campaign", "start", "--server", url, "--method", "ndd"])
        .args(["--vut", "idm", "--beta", "0.1", "--seed", "3", "--wait"])
        .env("TSLG_PROGRESS_EVERY", "0.01")
        .env_remove("TSLG_NDD_TABLE");
    let o = output_within(command, COMMAND_LIMIT);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let log = String::from_utf8_lossy(&o.stderr);
    let running: Vec<&str> = log.lines().filter(|l| l.contains(" running ")).collect();
    assert!(
        !running.is_empty()
            && running
                .iter()
                .all(|l| l.contains("tests") && l.contains("→ β 0.1")),
        "{log}"
    );
    assert!(log.lines().any(|l| l.contains(" converged ")), "{log}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn invalid_tests_use_indices_but_are_not_counted_as_tests() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &["--lease-size", "100"]);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    // An external program's campaign: only its workers can say a test was
    // invalid (the coordinator runs a built-in vehicle's tests again).
    let request = tslg_api::CreateCampaign {
        vut: serde_json::json!({"external": "sim"}),
        ..campaign(Method::Ndd, library.id, "idm", 0.2, 1)
    };
    let id = client.create_campaign(&request).await.unwrap().id;
    let lease = client
        .claim(&tslg_api::LeaseRequest {
            worker: "w".into(),
            threads: 1,
            include_tests: false,
            offers: vec!["sim:cut-in:step".into()],
            unhealthy: Vec::new(),
            max_tests: None,
            wait_seconds: None,
            audits_only: false,
            noisy: Vec::new(),
        })
        .await
        .unwrap()
        .unwrap();
    let reason = |index| InvalidResult {
        index,
        reason: "simulator crashed".into(),
    };
    let report = ResultReport {
        next_lease: None,
        near_misses: Vec::new(),
        worker: "w".into(),
        attempt: 1,
        key: lease.key.clone(),
        from: 0,
        to: 100,
        events: vec![],
        packed_events: None,
        invalid: vec![reason(5), reason(6)],
        compute_seconds: 0.0,
        threads: 1,
    };
    client.report(lease.id, &report).await.unwrap();
    let view = client.campaign(id).await.unwrap();
    assert_eq!(
        (view.indices, view.tests, view.invalid, view.events),
        (100, 98, 2, 0)
    );
    // Alone, the worker's audits could not be run by another.
    assert_eq!(view.audits.unwrap().open, 0);
    // Reporting the same tests as valid now conflicts.
    let flipped = ResultReport {
        near_misses: Vec::new(),
        invalid: vec![reason(5)],
        ..report
    };
    let err = client.report(lease.id, &flipped).await.unwrap_err();
    assert!(
        err.to_string().contains("conflicting result for test 6"),
        "{err}"
    );
}

/// `campaign start --wait --fail-above P` as a pipeline's gate: 0 below,
/// 3 above (on the guarded bound where the campaign has one), 4 when the
/// campaign did not converge, 1 for a limit that is not a probability.
#[test]
fn a_campaign_gates_a_pipeline_on_its_upper_bound() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let _worker = WorkerProcess::start(&server.url, 1, "w1");
    let url = server.url.as_str();
    let o = tslg(&[
        "library",
        "create",
        "--server",
        url,
        "--surrogate",
        "idm",
        "--wait",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let library: LibraryView = serde_json::from_slice(&o.stdout).unwrap();
    let id = library.id.to_string();
    let gate = |limit: &str, extra: &[&str]| {
        let mut args = vec![
            "campaign",
            "start",
            "--server",
            url,
            "--library-id",
            &id,
            "--vut",
            "fvdm",
            "--seed",
            "3",
            "--wait",
            "--json",
            "--fail-above",
            limit,
        ];
        args.extend_from_slice(extra);
        tslg(&args)
    };
    let o = gate("1", &[]);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let view: CampaignView = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(view.status.as_str(), "converged");
    let (high, guarded) = (view.ci_high.unwrap(), view.guarded_ci_high.unwrap());
    assert!(
        guarded > high,
        "the FVDM fails where the IDM's library does not look"
    );
    assert!(String::from_utf8_lossy(&o.stderr).contains("gate passed"));
    // Between the plain and the guarded upper end: the plain interval would
    // pass, but it rests on the library covering the FVDM's failures.
    let between = format!("{:e}", (high + guarded) / 2.0);
    let o = gate(&between, &[]);
    assert_eq!(
        o.status.code(),
        Some(3),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let said = String::from_utf8_lossy(&o.stderr);
    assert!(
        said.contains("gate failed") && said.contains("guarded upper bound"),
        "{said}"
    );
    // The same campaign again (same seed): the state is printed as usual.
    let again: CampaignView = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(again.guarded_ci_high, view.guarded_ci_high);
    let above = format!("{:e}", guarded * 1.000001);
    assert_eq!(gate(&above, &[]).status.code(), Some(0));
    // A budget too small to converge: no verdict either way.
    let o = gate("1", &["--beta", "0.01", "--max-tests", "200"]);
    assert_eq!(
        o.status.code(),
        Some(4),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(String::from_utf8_lossy(&o.stderr).contains("without converging"));
    // Not a probability; and a gate needs --wait.
    for limit in ["1.5", "-1", "NaN"] {
        let o = gate(limit, &[]);
        assert_eq!(o.status.code(), Some(1), "{limit}");
        let said = String::from_utf8_lossy(&o.stderr);
        assert!(
            said.contains("--fail-above must be a probability"),
            "{said}"
        );
    }
    let o = tslg(&[
        "campaign",
        "start",
        "--server",
        url,
        "--vut",
        "fvdm",
        "--fail-above",
        "0.1",
    ]);
    assert!(clean_refusal(&o));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--wait"));
}

/// `campaign start --wait` with no worker says why the campaign waits (the
/// view's `no worker` warning) instead of a silent bar, and finishes once
/// a worker comes.
#[test]
fn a_waiting_command_says_why_the_campaign_does_not_move() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let url = server.url.as_str();
    let o = tslg(&["library", "create", "--server", url, "--wait", "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let library: LibraryView = serde_json::from_slice(&o.stdout).unwrap();
    let (waiting, said) = waiting_command(&[
        "campaign",
        "start",
        "--server",
        url,
        "--vut",
        "idm",
        "--wait",
        "--json",
        "--library-id",
        &library.id.to_string(),
    ]);
    let why = line_with(&said, "no worker", "the command says why it waits");
    assert!(
        why.starts_with("campaign 1: no worker: no worker has asked for work"),
        "{why}"
    );
    let _worker = WorkerProcess::start(url, 1, "w1");
    let done = wait_within(waiting, COMMAND_LIMIT);
    assert!(done.status.success());
    let view: CampaignView = serde_json::from_slice(&done.stdout)
        .unwrap_or_else(|_| panic!("{}", String::from_utf8_lossy(&done.stdout)));
    assert_eq!(view.status.as_str(), "converged");
}

/// `library create --wait` on a coordinator that leases builds to workers,
/// with none, says what the build waits for (it used to print nothing for
/// as long as it waited), and finishes once a worker comes.
#[test]
fn a_waiting_library_build_says_it_waits_for_a_worker() {
    let dir = scratch();
    let server = ServerProcess::start(
        &dir.path().join("db.sqlite"),
        &["--library-builds", "workers"],
    );
    let url = server.url.as_str();
    let (waiting, said) = waiting_command(&[
        "library",
        "create",
        "--server",
        url,
        "--search",
        "exhaustive",
        "--wait",
        "--json",
    ]);
    let why = line_with(
        &said,
        "waiting",
        "the command says what the build waits for",
    );
    assert!(
        why.starts_with("library 1: waiting for a worker: the coordinator leases this build's"),
        "{why}"
    );
    let _worker = WorkerProcess::start(url, 1, "w1");
    let done = wait_within(waiting, COMMAND_LIMIT);
    assert!(done.status.success());
    let view: LibraryView = serde_json::from_slice(&done.stdout)
        .unwrap_or_else(|_| panic!("{}", String::from_utf8_lossy(&done.stdout)));
    assert_eq!(view.status.as_str(), "ready");
    // It said so once, not at every poll.
    // The command has exited: its stderr is closed, and the reader ends.
    let again: Vec<String> = said.iter().filter(|l| l.contains("waiting")).collect();
    assert!(again.is_empty(), "{again:?}");
}

/// `tslg args` started with its output piped, and the lines of its stderr
/// as they come.
fn waiting_command(args: &[&str]) -> (std::process::Child, std::sync::mpsc::Receiver<String>) {
    use std::io::{BufRead, BufReader};
    let mut child = Command::new(env!("CARGO_BIN_EXE_tslg"))
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let (lines, said) = std::sync::mpsc::channel();
    let stderr = child.stderr.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines() {
            let _ = lines.send(line.unwrap());
        }
    });
    (child, said)
}

/// The first line of `said` that contains `needle` (within a minute).
fn line_with(said: &std::sync::mpsc::Receiver<String>, needle: &str, what: &str) -> String {
    loop {
        let line = said
            .recv_timeout(std::time::Duration::from_secs(60))
            .expect(what);
        if line.contains(needle) {
            return line;
        }
    }
}

/// A campaign names its vehicle with the parameters that differ from the
/// defaults, and says once when they change no accident of the preset
/// (the README's `{"model": "idm", "v0": 25}` on paper-code gave exactly
/// the plain IDM's answer without a word).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_campaign_names_its_vehicles_parameters_and_says_when_they_change_nothing() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let create = |vut: serde_json::Value| CreateCampaign {
        vut,
        max_tests: 100,
        ..campaign(Method::Ndd, library.id, "idm", 0.2, 1)
    };
    let inert = client
        .create_campaign(&create(serde_json::json!({"model": "idm", "v0": 25})))
        .await
        .unwrap();
    assert_eq!(inert.vut_label, "idm (v0 25)");
    assert_eq!(inert.parameters_inert, Some(true), "{inert:?}");
    let active = client
        .create_campaign(&create(serde_json::json!({"model": "idm", "s0": 4})))
        .await
        .unwrap();
    assert_eq!(active.vut_label, "idm (s0 4)");
    assert_eq!(active.parameters_inert, Some(false));
    let plain = client
        .create_campaign(&create(serde_json::json!({"model": "idm"})))
        .await
        .unwrap();
    assert_eq!(
        (plain.vut_label.as_str(), plain.parameters_inert),
        ("idm", None)
    );
    let o = tslg(&[
        "campaign",
        "status",
        &inert.id.to_string(),
        "--server",
        &server.url,
    ]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("vehicle idm (v0 25)"), "{text}");
    assert!(
        text.contains("note: the parameters of idm (v0 25) change no accident of this preset"),
        "{text}"
    );
    let o = tslg(&[
        "campaign",
        "status",
        &active.id.to_string(),
        "--server",
        &server.url,
    ]);
    assert!(!String::from_utf8_lossy(&o.stdout).contains("change no accident"));
}
