//! One vote per principal (issue 67): with `--enrolment required` a holder
//! of the worker token cannot mint voters. The Sybil attack of the issue
//! (one principal registering names that run nothing and report "no
//! event" everywhere, registering again whenever a name is flagged) moves
//! the answer by nothing, flags no honest worker, and its principal stays
//! flagged (docs/operations.md, "Who is trusted").

use crate::support::*;
use std::time::{Duration, Instant};
use tslg_api::{CampaignStatus, Method};
use tslg_client::{CallError, Client};

/// The program the honest workers run and the Sybil names claim to.
const PY_IDM: &str = "py-idm:cut-in:step";

/// What the Sybil principal got: the names it registered, the leases it
/// reported on, and the refusal that ended it (registering again).
struct SybilRun {
    names: Vec<String>,
    reports: u64,
    refused: Option<String>,
}

/// One principal, with enrolment secret `secret` (`None`: the worker token
/// alone), three names at a time: claims leases of the Python IDM, reports
/// every test without an event, and registers a new name for each one
/// refused, until registration itself is refused or `limit` passes.
async fn sybil(client: Client, secret: Option<String>, limit: Duration) -> SybilRun {
    let mut run = SybilRun {
        names: Vec::new(),
        reports: 0,
        refused: None,
    };
    let mut live: Vec<String> = Vec::new();
    let started = Instant::now();
    let mut turn = 0;
    while started.elapsed() < limit {
        while live.len() < 3 {
            let asked = format!("mallory-{}", run.names.len());
            match client.register_enrolled(&asked, secret.as_deref()).await {
                Ok(issued) => {
                    run.names.push(issued.name.clone());
                    live.push(issued.name);
                }
                Err(CallError::Refused {
                    status: 403,
                    detail,
                }) => {
                    run.refused = Some(detail);
                    return run;
                }
                Err(e) => panic!("{e}"),
            }
        }
        turn = (turn + 1) % live.len();
        let name = live[turn].clone();
        let refused = match client.claim(&ask(&name, &[PY_IDM])).await {
            Ok(Some(lease)) => match client
                .report(lease.id, &whole(&lease, &name, Vec::new()))
                .await
            {
                Ok(_) => {
                    run.reports += 1;
                    false
                }
                Err(CallError::Refused { status: 403, .. }) => true,
                // A lease the coordinator took back meanwhile.
                Err(CallError::Refused { status: 409, .. }) => false,
                Err(e) => panic!("{e}"),
            },
            Ok(None) => {
                tokio::time::sleep(Duration::from_millis(20)).await;
                false
            }
            Err(CallError::Refused { status: 403, .. }) => true,
            Err(e) => panic!("{e}"),
        };
        if refused {
            live.retain(|n| *n != name);
        }
    }
    run
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_enrolment_a_sybil_principal_moves_no_answer_and_flags_no_honest_worker() {
    let dir = scratch();
    // Enrolment needs an admin token (else anyone could enrol).
    let server = ServerProcess::start(
        &dir.path().join("db.sqlite"),
        &["--enrolment", "required", "--admin-token", "admin-secret"],
    );
    let client = Client::new(&server.url, Some("admin-secret".into())).unwrap();
    match server.client().enrol("intruder").await {
        Err(CallError::Refused { status: 401, .. }) => {}
        other => panic!("an enrolment without the admin token: {other:?}"),
    }
    let library = ready_library(&client, "idm", true).await;
    // Registering without an enrolment is refused, and says how to get one.
    match server.client().register("stranger").await {
        Err(CallError::Refused {
            status: 403,
            detail,
        }) => {
            assert!(detail.contains("tslg worker enrol"), "{detail}")
        }
        other => panic!("registered without an enrolment: {other:?}"),
    }
    // Two honest hosts, one principal each, and the attacker's principal.
    let mut secrets = Vec::new();
    for principal in ["host-a", "host-b", "mallory"] {
        secrets.push(client.enrol(principal).await.unwrap().secret);
    }
    match client.enrol("host-a").await {
        Err(CallError::Refused { status: 409, .. }) => {}
        other => panic!("a principal enrolled twice: {other:?}"),
    }
    let request = tslg_api::CreateCampaign {
        vut: serde_json::json!({"external": "py-idm"}),
        ..campaign(Method::Ndd, library.id, "idm", 0.2, 17)
    };
    let builtin = campaign(Method::Ndd, library.id, "idm", 0.2, 17);
    let id = client.create_campaign(&request).await.unwrap().id;
    let attacker = tokio::spawn(sybil(
        server.client(),
        Some(secrets[2].clone()),
        Duration::from_secs(300),
    ));
    let exec = python("py-idm", "examples/python/idm_vut.py", "");
    let _honest = [("honest-a", &secrets[0]), ("honest-b", &secrets[1])].map(|(name, secret)| {
        WorkerProcess::start_with(
            &server.url,
            1,
            name,
            &["--vut-exec", &exec, "--enrolment", secret],
        )
    });
    let view = finished(&client, id, Duration::from_secs(400)).await;
    assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
    let sybil = attacker.await.unwrap();
    eprintln!(
        "the Sybil principal registered {:?}, reported {} leases, then: {:?}",
        sybil.names, sybil.reports, sybil.refused
    );
    // It did report, and was stopped: its principal is flagged, so a new
    // name is refused.
    assert!(sybil.reports > 0);
    let refused = sybil.refused.expect("registering again was never refused");
    assert!(
        refused.contains("principal `mallory` is flagged"),
        "{refused}"
    );
    // The answer is the honest one, bit for bit (the Python IDM is the
    // built-in IDM): every result of every name of the principal was taken
    // back and run again by honest workers.
    assert_same(&view, &in_process(None, &builtin));
    let workers = client.workers().await.unwrap().workers;
    for worker in &workers {
        let honest = worker.name.starts_with("honest-");
        assert_eq!(worker.flagged.is_none(), honest, "{worker:?}");
        if !honest {
            assert_eq!(worker.principal.as_deref(), Some("mallory"), "{worker:?}");
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn without_enrolment_the_same_attack_outvotes_honest_workers() {
    // The control: the shared worker token alone (`--enrolment open`, one
    // trusted cluster). Each name is its own principal, so three names
    // are three partners, and an honest worker's evidence, leaving out any
    // one of them, still holds two that report nothing.
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let request = tslg_api::CreateCampaign {
        vut: serde_json::json!({"external": "py-idm"}),
        ..campaign(Method::Ndd, library.id, "idm", 0.2, 17)
    };
    let id = client.create_campaign(&request).await.unwrap().id;
    let attacker = tokio::spawn(sybil(server.client(), None, Duration::from_secs(120)));
    let exec = python("py-idm", "examples/python/idm_vut.py", "");
    let _honest = ["honest-a", "honest-b"]
        .map(|name| WorkerProcess::start_with(&server.url, 1, name, &["--vut-exec", &exec]));
    let started = Instant::now();
    let honest_flagged = loop {
        let workers = client.workers().await.unwrap().workers;
        let flagged: Vec<String> = workers
            .iter()
            .filter(|w| w.name.starts_with("honest-") && w.flagged.is_some())
            .map(|w| w.name.clone())
            .collect();
        if !flagged.is_empty() || started.elapsed() > Duration::from_secs(120) {
            break flagged;
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    };
    attacker.abort();
    eprintln!("open: honest flagged {honest_flagged:?}");
    assert!(!honest_flagged.is_empty(), "no honest worker was flagged");
    let _ = client.cancel_campaign(id).await;
}
