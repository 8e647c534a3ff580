//! External vehicles under test through the real coordinator and workers:
//! the Python IDM of `examples/python` drives cut-in and car-following
//! campaigns in step mode and the Rust FVDM of `examples/fvdm_vut.rs` drives
//! cut-in in step and episode mode, each giving exactly the campaign of the
//! built-in model (same model, another process); a program that crashes,
//! hangs, prints garbage or exits early costs only the tests it spoiled;
//! one that keeps failing is reported unhealthy instead of burning the
//! campaign; a worker killed outright takes its programs with it; and only
//! workers offering a program get its tests.

use crate::support::*;
use std::path::Path;
use std::time::{Duration, Instant};
use tslg_api::{CampaignStatus, CreateCampaign, CreateLibrary, LeaseRequest, Method};
use tslg_client::Client;

fn with_vut(request: CreateCampaign, vut: serde_json::Value) -> CreateCampaign {
    CreateCampaign { vut, ..request }
}

async fn converged(client: &Client, id: i64) -> tslg_api::CampaignView {
    let view = finished(client, id, Duration::from_secs(240)).await;
    assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
    view
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_python_idm_runs_cut_in_and_car_following_exactly_like_the_builtin_idm() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let exec = python("py-idm", "examples/python/idm_vut.py", "");
    let _worker = WorkerProcess::start_with(&server.url, 2, "py", &["--vut-exec", &exec]);
    let client = server.client();

    // Cut-in: the library campaign of the program is the built-in IDM's,
    // test for test, and its interval holds the exact P(A).
    let library = ready_library(&client, "idm", true).await;
    let builtin = campaign(Method::Library, library.id, "idm", 0.2, 17);
    let request = with_vut(builtin.clone(), serde_json::json!({"external": "py-idm"}));
    let view = client.create_campaign(&request).await.unwrap();
    assert_eq!(
        view.vut,
        serde_json::json!({"external": "py-idm", "mode": "step"})
    );
    let view = converged(&client, view.id).await;
    assert_same(&view, &in_process(Some("idm"), &builtin));
    let exact = exact("idm");
    assert!(
        view.ci_low.unwrap() <= exact && exact <= view.ci_high.unwrap(),
        "{exact} outside {view:?}"
    );
    // The coordinator does not run programs: it knows no exact answer.
    assert_eq!(view.exact_probability, None);

    // Car-following in step mode, on the risky preset's library.
    let library = build_library(
        &client,
        &CreateLibrary {
            case: "car-following".into(),
            preset: Some("risky".into()),
            surrogate: serde_json::json!({"model": "idm"}),
            exposure: Default::default(),
            search: None,
            threshold: None,
        },
    )
    .await;
    let file = client.library_file(library.id).await.unwrap();
    let builtin = CreateCampaign {
        case: "car-following".into(),
        max_tests: 200_000,
        ..campaign(Method::Library, library.id, "idm", 0.2, 5)
    };
    let request = with_vut(builtin.clone(), serde_json::json!({"external": "py-idm"}));
    let id = client.create_campaign(&request).await.unwrap().id;
    let view = converged(&client, id).await;
    assert_same(
        &view,
        &in_process_with_file(Some(&file), Some("risky"), &builtin),
    );
    assert!(view.events >= 10, "{view:?}");

    // The worker says what it offers.
    let workers = client.workers().await.unwrap().workers;
    let py = workers.iter().find(|w| w.name == "py").unwrap();
    assert_eq!(
        py.offers,
        ["py-idm:car-following:step", "py-idm:cut-in:step"]
    );
    assert!(py.live && py.unhealthy.is_empty(), "{py:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_rust_fvdm_runs_cut_in_episodes_and_steps_exactly_like_the_builtin_fvdm() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let exec = format!("rs-fvdm={}", example_binary("fvdm_vut").display());
    let _worker = WorkerProcess::start_with(&server.url, 2, "rs", &["--vut-exec", &exec]);
    let client = server.client();
    let library = ready_library(&client, "fvdm", true).await;
    // n_min 30: a seed whose interval covers at that stop (the test is
    // about the external program matching the built-in bit for bit).
    let builtin = CreateCampaign {
        n_min: Some(30),
        ..campaign(Method::Library, library.id, "fvdm", 0.2, 23)
    };
    let reference = in_process(Some("fvdm"), &builtin);
    let exact = exact("fvdm");
    assert!(reference.covers(exact), "{exact} outside {reference:?}");
    for mode in ["episode", "step"] {
        let vut = serde_json::json!({"external": "rs-fvdm", "mode": mode});
        let id = client
            .create_campaign(&with_vut(builtin.clone(), vut))
            .await
            .unwrap()
            .id;
        assert_same(&converged(&client, id).await, &reference);
    }
}

/// The invalid tests' reasons as the coordinator stored them.
async fn invalid_reasons(database: &Path, campaign: i64) -> Vec<(u64, String)> {
    let pool = sqlx::SqlitePool::connect(&format!("sqlite://{}?mode=ro", database.display()))
        .await
        .unwrap();
    let rows: Vec<(i64, String)> = sqlx::query_as(
        "SELECT test_index, reason FROM invalid_tests WHERE campaign_id = ? ORDER BY test_index",
    )
    .bind(campaign)
    .fetch_all(&pool)
    .await
    .unwrap();
    rows.into_iter().map(|(i, r)| (i as u64, r)).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn crashes_hangs_garbage_and_early_exits_cost_only_the_tests_they_spoil() {
    let dir = scratch();
    let database = dir.path().join("db.sqlite");
    let server = ServerProcess::start(&database, &[]);
    let client = server.client();
    // Each fault strikes the tests with index ≡ 3 (mod `every`) when their
    // reset arrives; the program is then killed and restarted (a refusal
    // keeps it) and the test tried once more before it is reported
    // invalid.
    let markers = dir.path().join("markers");
    std::fs::create_dir(&markers).unwrap();
    let faults = [
        ("crash", 7, "exited (exit status: 1); stderr: Traceback"),
        ("hang", 20, "no answer within the per-test timeout of 1.5 s"),
        (
            "garbage",
            7,
            "`this is not a protocol message` is not a protocol message",
        ),
        ("exit", 7, "exited (exit status: 0)"),
        ("refuse", 7, "reported an error: injected refusal"),
        // Fails the first try only: the retry on a new process succeeds.
        ("crash-once", 7, ""),
    ];
    let _workers: Vec<WorkerProcess> = faults
        .iter()
        .map(|(fault, every, _)| {
            let exec = python(
                &format!("py-{fault}"),
                "tests/fixtures/faulty_vut.py",
                &format!("{fault} {every} 3 {}", markers.display()),
            );
            // Only the hang needs a short timeout; the others get room for
            // a loaded machine (six Python programs restarting on 2 cores),
            // where a fresh program's handshake must fit in a test's time.
            let timeout = if *fault == "hang" { "1.5" } else { "10" };
            WorkerProcess::start_with(
                &server.url,
                1,
                fault,
                &["--vut-exec", &exec, "--vut-timeout", timeout],
            )
        })
        .collect();
    let library = ready_library(&client, "idm", true).await;
    let builtin = campaign(Method::Library, library.id, "idm", 0.2, 41);
    let mut ids = Vec::new();
    for (fault, _, _) in &faults {
        let vut = serde_json::json!({"external": format!("py-{fault}")});
        let view = client
            .create_campaign(&with_vut(builtin.clone(), vut))
            .await
            .unwrap();
        ids.push(view.id);
    }
    let exact = exact("idm");
    for ((fault, every, reason), id) in faults.iter().zip(ids) {
        let view = converged(&client, id).await;
        // Exactly the spoiled tests are invalid, and the estimate is the
        // one of the same campaign with those tests left out.
        let once = *fault == "crash-once";
        let spoiled = |i: u64| !once && i % every == 3;
        let reference = in_process_with_invalid(
            Some(&library_file(&client, library.id).await),
            None,
            &builtin,
            &spoiled,
        );
        assert_same(&view, &reference);
        assert_eq!(view.invalid == 0, once, "{fault}: {view:?}");
        assert!(
            view.ci_low.unwrap() <= exact && exact <= view.ci_high.unwrap(),
            "{fault}: {exact} outside {view:?}"
        );
        // Tests past the stop index may have run too; all are recorded.
        let reasons = invalid_reasons(&database, id).await;
        let in_prefix = reasons.iter().filter(|(i, _)| *i < view.indices).count();
        assert_eq!(in_prefix as u64, view.invalid);
        for (index, text) in reasons {
            assert!(spoiled(index), "{fault}: test {index} invalid: {text}");
            assert!(
                text.starts_with(&format!("external program `py-{fault}`: the program"))
                    && text.contains(reason)
                    && text.ends_with("(tried 2 times)"),
                "{fault}: {text}"
            );
            if *fault == "crash" {
                assert!(
                    text.contains("RuntimeError: injected crash in test"),
                    "{text}"
                );
            }
        }
    }
}

/// A worker killed outright (SIGKILL: no chance to stop its programs)
/// takes them with it: a program stuck in a scenario does not run on,
/// orphaned, for as long as it is stuck (here an hour). Linux: the kernel's
/// `PR_SET_PDEATHSIG`, and `/proc`.
#[cfg(target_os = "linux")]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_killed_worker_takes_its_programs_with_it() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    // Every test hangs, and the stuck process leaves `hanging-PID` here.
    let markers = dir.path().join("markers");
    std::fs::create_dir(&markers).unwrap();
    let exec = python(
        "py-stuck",
        "tests/fixtures/faulty_vut.py",
        &format!("hang 1 0 {}", markers.display()),
    );
    let worker = WorkerProcess::start_with(
        &server.url,
        1,
        "stuck",
        &["--vut-exec", &exec, "--vut-timeout", "600"],
    );
    let library = ready_library(&client, "idm", true).await;
    let request = with_vut(
        campaign(Method::Library, library.id, "idm", 0.2, 1),
        serde_json::json!({"external": "py-stuck"}),
    );
    client.create_campaign(&request).await.unwrap();
    let started = Instant::now();
    let pid: u32 = loop {
        let stuck = std::fs::read_dir(&markers).unwrap().find_map(|e| {
            let name = e.unwrap().file_name().into_string().unwrap();
            name.strip_prefix("hanging-").map(|p| p.parse().unwrap())
        });
        if let Some(pid) = stuck {
            break pid;
        }
        assert!(started.elapsed() < Duration::from_secs(60), "never stuck");
        tokio::time::sleep(Duration::from_millis(20)).await;
    };
    // Running, or a zombie not yet reaped by whoever inherited it.
    let running = || {
        std::fs::read_to_string(format!("/proc/{pid}/stat"))
            .is_ok_and(|stat| !stat.rsplit(") ").next().unwrap().starts_with('Z'))
    };
    assert!(running(), "the stuck program runs while its worker does");
    worker.kill();
    let started = Instant::now();
    while running() && started.elapsed() < Duration::from_secs(20) {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let orphan = running();
    if orphan {
        let _ = std::process::Command::new("kill")
            .args(["-KILL", &pid.to_string()])
            .status();
    }
    assert!(!orphan, "program {pid} outlived its killed worker");
}

async fn library_file(client: &Client, id: i64) -> Vec<u8> {
    client.library_file(id).await.unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_program_that_keeps_failing_is_reported_unhealthy_instead_of_burning_the_campaign() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    let exec = python("py-broken", "tests/fixtures/faulty_vut.py", "crash 1");
    let _worker = WorkerProcess::start_with(
        &server.url,
        1,
        "broken",
        &["--vut-exec", &exec, "--vut-max-failures", "3"],
    );
    let library = ready_library(&client, "idm", true).await;
    let request = with_vut(
        campaign(Method::Library, library.id, "idm", 0.2, 3),
        serde_json::json!({"external": "py-broken"}),
    );
    let id = client.create_campaign(&request).await.unwrap().id;
    let started = Instant::now();
    let worker = loop {
        let workers = client.workers().await.unwrap().workers;
        if let Some(w) = workers.into_iter().find(|w| !w.unhealthy.is_empty()) {
            break w;
        }
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "never unhealthy"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    assert_eq!(worker.name, "broken");
    assert!(worker.offers.is_empty(), "{worker:?}");
    let unhealthy = &worker.unhealthy[0];
    assert_eq!(
        (unhealthy.name.as_str(), unhealthy.failures),
        ("py-broken", 3)
    );
    assert!(unhealthy.reason.contains("injected crash"), "{unhealthy:?}");
    // Three tests were spent; the campaign waits for a healthy program
    // instead of filling with invalid tests: the worker, offering nothing
    // now, asked again and is held with no work.
    until_waiting(&server.url, 1.0).await;
    let view = client.campaign(id).await.unwrap();
    assert_eq!(view.status, CampaignStatus::Running);
    assert_eq!(
        (view.invalid, view.indices, view.tests),
        (3, 3, 0),
        "{view:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn only_workers_offering_a_program_get_its_tests() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let request = with_vut(
        campaign(Method::Library, library.id, "idm", 0.2, 3),
        serde_json::json!({"external": "track", "mode": "episode"}),
    );
    let id = client.create_campaign(&request).await.unwrap().id;
    let ask = |offers: &[&str]| LeaseRequest {
        worker: "probe".into(),
        threads: 1,
        include_tests: false,
        offers: offers.iter().map(|s| s.to_string()).collect(),
        unhealthy: Vec::new(),
        max_tests: None,
        wait_seconds: None,
        audits_only: false,
        noisy: Vec::new(),
    };
    for offers in [
        &[][..],
        &["track:cut-in:step"],
        &["track:highway-exit:episode"],
        &["other:cut-in:episode"],
    ] {
        let lease = client.claim(&ask(offers)).await.unwrap();
        assert!(lease.is_none(), "{offers:?} got {lease:?}");
    }
    let lease = client
        .claim(&ask(&["other:cut-in:step", "track:cut-in:episode"]))
        .await
        .unwrap()
        .expect("a lease for the offering worker");
    assert_eq!(lease.campaign_id, id);
    // A lease given back is handed out again only to an offering worker.
    let fence = tslg_api::LeaseFence {
        worker: "probe".into(),
        attempt: lease.attempt,
        key: lease.key.clone(),
    };
    client
        .release(lease.id, &fence.release(None))
        .await
        .unwrap();
    assert!(client.claim(&ask(&[])).await.unwrap().is_none());
    let again = client
        .claim(&ask(&["track:cut-in:episode"]))
        .await
        .unwrap()
        .expect("the released lease");
    assert_eq!((again.id, again.attempt), (lease.id, lease.attempt + 1));
    // Bad offers and vehicles are refused with the reason.
    let err = client.claim(&ask(&["track:cut-in"])).await.unwrap_err();
    assert!(err.to_string().contains("must be NAME:case:mode"), "{err}");
    let err = client
        .claim(&ask(&["track:cut-in:batch"]))
        .await
        .unwrap_err();
    assert!(err.to_string().contains("step or episode"), "{err}");
    for (case, vut, detail) in [
        (
            "cut-in",
            serde_json::json!({"external": "has space"}),
            "must be 1 to 64",
        ),
        (
            "cut-in",
            serde_json::json!({"external": "x", "mode": "batch"}),
            "unknown variant",
        ),
    ] {
        let request = CreateCampaign {
            case: case.into(),
            ..with_vut(campaign(Method::Library, library.id, "idm", 0.2, 1), vut)
        };
        let err = client.create_campaign(&request).await.unwrap_err();
        assert!(err.to_string().contains(detail), "{err}");
    }
    let request = CreateCampaign {
        case: "car-following".into(),
        library_id: None,
        ..with_vut(
            campaign(Method::Ndd, 0, "idm", 0.2, 1),
            serde_json::json!({"external": "x", "mode": "episode"}),
        )
    };
    let err = client.create_campaign(&request).await.unwrap_err();
    assert!(err.to_string().contains("step mode only"), "{err}");
}

#[test]
fn a_worker_refuses_to_start_with_a_program_it_cannot_use() {
    for (exec, detail) in [
        ("no-equals-sign".to_owned(), "must be NAME=COMMAND"),
        (
            "ghost=/nonexistent/vut --flag".to_owned(),
            "--vut-exec ghost: the program could not be started: /nonexistent/vut",
        ),
        (
            python("old", "tests/fixtures/faulty_vut.py", "bad-hello 1"),
            "it speaks protocol version 99; this worker speaks versions 1 to 2",
        ),
    ] {
        let output = std::process::Command::new(env!("CARGO_BIN_EXE_tslg-worker"))
            .args(["--server", "http://127.0.0.1:9", "--vut-exec", &exec])
            .output()
            .unwrap();
        assert!(clean_refusal(&output), "{exec}");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(stderr.contains(detail), "{exec}: {stderr}");
    }
}
