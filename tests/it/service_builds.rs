//! Library builds of built-in surrogates on workers (issue 22 part 4):
//! with `--library-builds workers` the coordinator leases an exhaustive
//! build's surrogate runs to the workers cell by cell, and a multistart
//! search or a car-following policy whole to one worker; it says it waits
//! while no worker is up, serves the library the command line builds, byte
//! for byte, whoever built it and whichever worker died meanwhile, and
//! refuses an upload that is not the library it asked for.

use crate::support::*;
use std::process::Command;
use std::time::{Duration, Instant};
use tslg_api::{
    CreateLibrary, LeaseRequest, LibraryStatus, LibraryUpload, LibraryView, Method, SearchRequest,
};

/// The library `id` once it is no longer building, within `limit`.
async fn settled(client: &tslg_client::Client, id: i64, limit: Duration) -> LibraryView {
    let started = Instant::now();
    loop {
        let view = client.library(id).await.unwrap();
        if view.status != LibraryStatus::Building {
            return view;
        }
        assert!(started.elapsed() < limit, "library {id} stuck: {view:?}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// The library file `tslg library build` writes for `args`.
fn offline(dir: &std::path::Path, name: &str, args: &[&str]) -> String {
    let out = dir.join(name);
    let o = Command::new(env!("CARGO_BIN_EXE_tslg"))
        .args(["library", "build", "-o", out.to_str().unwrap()])
        .args(args)
        .output()
        .expect("tslg runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    std::fs::read_to_string(out).unwrap()
}

fn request(
    case: &str,
    preset: Option<&str>,
    surrogate: &str,
    search: Option<SearchRequest>,
) -> CreateLibrary {
    CreateLibrary {
        case: case.into(),
        preset: preset.map(Into::into),
        surrogate: serde_json::json!({"model": surrogate}),
        exposure: Default::default(),
        search,
        threshold: None,
    }
}

/// The campaign that builds library `id` on workers.
async fn build_campaign(client: &tslg_client::Client, id: i64) -> tslg_api::CampaignView {
    let list = client.campaigns().await.unwrap();
    list.campaigns
        .into_iter()
        .find(|c| c.library_id == Some(id) && c.method == Method::Build)
        .expect("a build campaign")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn builds_of_builtin_surrogates_run_on_workers_and_equal_the_offline_ones() {
    let dir = scratch();
    let options = ["--library-builds", "workers", "--lease-size", "200"];
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &options);
    let client = server.client();
    let cutin = client
        .create_library(&request(
            "cut-in",
            None,
            "fvdm",
            Some(SearchRequest::Exhaustive),
        ))
        .await
        .unwrap();
    // Highway-exit's default search is exhaustive: it goes to workers too.
    let highway = client
        .create_library(&request("highway-exit", Some("coarse"), "mobil", None))
        .await
        .unwrap();
    // A multistart search picks each run from the last, and a policy
    // sweeps every state: one worker builds each whole.
    let multistart = client
        .create_library(&request(
            "cut-in",
            None,
            "idm",
            Some(SearchRequest::Multistart {
                starts: 50,
                seed: 0,
            }),
        ))
        .await
        .unwrap();
    let policy = client
        .create_library(&request("car-following", Some("risky"), "idm", None))
        .await
        .unwrap();
    // Every build waits, visibly, for a worker.
    for id in [cutin.id, highway.id, multistart.id, policy.id] {
        let view = client.library(id).await.unwrap();
        assert_eq!(view.status, LibraryStatus::Building, "{view:?}");
        let detail = view.status_detail.unwrap_or_default();
        assert!(detail.contains("waiting for a worker"), "{detail}");
    }
    let _workers = two_workers(&server.url);
    let cutin = settled(&client, cutin.id, Duration::from_secs(120)).await;
    let highway = settled(&client, highway.id, Duration::from_secs(120)).await;
    let multistart = settled(&client, multistart.id, Duration::from_secs(120)).await;
    let policy = settled(&client, policy.id, Duration::from_secs(120)).await;
    for view in [&cutin, &highway, &multistart, &policy] {
        assert_eq!(view.status, LibraryStatus::Ready, "{view:?}");
    }
    assert_eq!(
        build_campaign(&client, policy.id).await.status,
        tslg_api::CampaignStatus::Converged
    );
    assert!(cutin.size.unwrap() > 0 && highway.size.unwrap() > 0);
    // Whoever ran which cell, the library is the command line's.
    let served = |id| {
        let client = client.clone();
        async move { String::from_utf8(client.library_file(id).await.unwrap()).unwrap() }
    };
    assert_eq!(
        served(cutin.id).await,
        offline(
            dir.path(),
            "cutin.json",
            &["--surrogate", "fvdm", "--search", "exhaustive"]
        )
    );
    assert_eq!(
        served(highway.id).await,
        offline(
            dir.path(),
            "highway.json",
            &["--case", "highway-exit", "--preset", "coarse"]
        )
    );
    let served_bytes = |id| {
        let client = client.clone();
        async move { client.library_file(id).await.unwrap() }
    };
    assert_eq!(
        served(multistart.id).await,
        offline(
            dir.path(),
            "multistart.json",
            &[
                "--surrogate",
                "idm",
                "--search",
                "multistart",
                "--starts",
                "50"
            ]
        )
    );
    let policy_file = dir.path().join("policy.bin");
    let o = Command::new(env!("CARGO_BIN_EXE_tslg"))
        .args([
            "library",
            "build",
            "--case",
            "car-following",
            "--preset",
            "risky",
            "-o",
        ])
        .arg(&policy_file)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        served_bytes(policy.id).await,
        std::fs::read(&policy_file).unwrap()
    );
    // `campaign start` without --case takes its library's case.
    let highway_id = highway.id.to_string();
    let o = tslg(&[
        "campaign",
        "start",
        "--server",
        &server.url,
        "--library-id",
        &highway_id,
        "--vut",
        "gap-seeker",
        "--max-tests",
        "1000",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let started: tslg_api::CampaignView = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(started.case, "highway-exit");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_whole_build_survives_its_workers_death_and_is_the_offline_one() {
    let dir = scratch();
    let options = ["--library-builds", "workers", "--lease-ttl-seconds", "1"];
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &options);
    let client = server.client();
    // A multistart search of the paper's highway-exit grid: seconds long.
    let search = SearchRequest::Multistart {
        starts: 800,
        seed: 3,
    };
    let library = client
        .create_library(&request("highway-exit", None, "mobil", Some(search)))
        .await
        .unwrap();
    let doomed = WorkerProcess::start(&server.url, 1, "doomed");
    let started = Instant::now();
    while build_campaign(&client, library.id).await.leased == 0 {
        assert!(started.elapsed() < Duration::from_secs(30), "never leased");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    doomed.kill();
    let view = client.library(library.id).await.unwrap();
    assert_eq!(view.status, LibraryStatus::Building, "killed too late");
    // Another worker takes the expired lease and builds it from the start.
    let _rescuer = WorkerProcess::start(&server.url, 2, "rescuer");
    let view = settled(&client, library.id, Duration::from_secs(120)).await;
    assert_eq!(view.status, LibraryStatus::Ready, "{view:?}");
    let served = String::from_utf8(client.library_file(library.id).await.unwrap()).unwrap();
    let built = offline(
        dir.path(),
        "highway.json",
        &[
            "--case",
            "highway-exit",
            "--search",
            "multistart",
            "--starts",
            "800",
            "--seed",
            "3",
        ],
    );
    assert_eq!(served, built);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_upload_that_is_not_the_library_asked_for_changes_nothing() {
    let dir = scratch();
    let server = ServerProcess::start(
        &dir.path().join("db.sqlite"),
        &["--library-builds", "workers"],
    );
    let client = server.client();
    let search = SearchRequest::Multistart {
        starts: 50,
        seed: 0,
    };
    let library = client
        .create_library(&request("cut-in", None, "idm", Some(search)))
        .await
        .unwrap();
    // A worker of our own making takes the build.
    let lease = client
        .claim(&LeaseRequest {
            worker: "liar".into(),
            threads: 1,
            include_tests: false,
            offers: vec![],
            unhealthy: vec![],
            max_tests: None,
            wait_seconds: None,
            audits_only: false,
            noisy: Vec::new(),
        })
        .await
        .unwrap()
        .expect("the build is leased");
    assert_eq!((lease.start, lease.end), (0, 1));
    assert_eq!(
        client.plan(lease.campaign_id).await.unwrap().method,
        Method::Build
    );
    let fence = tslg_api::LeaseFence {
        worker: "liar".into(),
        attempt: lease.attempt,
        key: lease.key.clone(),
    };
    let refused = |e: tslg_client::CallError| match e {
        tslg_client::CallError::Refused { status, detail } => (status, detail),
        other => panic!("{other}"),
    };
    // The honest file, as the command line builds it.
    let honest = offline(
        dir.path(),
        "idm.json",
        &[
            "--surrogate",
            "idm",
            "--search",
            "multistart",
            "--starts",
            "50",
        ],
    );
    let mut cells: serde_json::Value = serde_json::from_str(&honest).unwrap();
    // Its first cell's criticality doubled, and W with it: a file that
    // reads well but is not what the IDM gives.
    let first = cells["cells"][0]["criticality"].as_f64().expect("a cell");
    cells["cells"][0]["criticality"] = serde_json::json!(2.0 * first);
    cells["w"] = serde_json::json!(cells["w"].as_f64().unwrap() + first);
    let cases: [(&str, Vec<u8>, &str); 4] = [
        ("not a library", b"{}".to_vec(), "is not library"),
        (
            "another surrogate's",
            offline(
                dir.path(),
                "fvdm.json",
                &[
                    "--surrogate",
                    "fvdm",
                    "--search",
                    "multistart",
                    "--starts",
                    "50",
                ],
            )
            .into_bytes(),
            "surrogate",
        ),
        (
            "a cell that is no failure",
            serde_json::to_vec(&cells).unwrap(),
            "the surrogate gives",
        ),
        (
            "the honest one with the wrong key",
            honest.clone().into_bytes(),
            "",
        ),
    ];
    for (what, file, says) in cases {
        let mut upload = LibraryUpload::of_file(&fence, 0.1, &file);
        if says.is_empty() {
            upload.key = tslg_api::LeaseKey("0".repeat(32));
            let (status, _) = refused(client.upload_library(lease.id, &upload).await.unwrap_err());
            assert_eq!(status, 403, "{what}");
            continue;
        }
        let (status, detail) = refused(client.upload_library(lease.id, &upload).await.unwrap_err());
        assert_eq!(status, 422, "{what}: {detail}");
        assert!(detail.contains(says), "{what}: {detail}");
        let view = client.library(library.id).await.unwrap();
        assert_eq!(view.status, LibraryStatus::Building, "{what}");
    }
    // Results are no way to answer a build.
    let report: tslg_api::ResultReport = serde_json::from_value(serde_json::json!({
        "worker": "liar", "attempt": lease.attempt, "key": lease.key,
        "from": 0, "to": 1, "events": [], "compute_seconds": 0.1, "threads": 1
    }))
    .unwrap();
    let (status, detail) = refused(client.report(lease.id, &report).await.unwrap_err());
    assert_eq!(status, 409, "{detail}");
    assert!(detail.contains("uploads the library"), "{detail}");
    // A failure fails the library with the worker's reason; it can go.
    let failure = LibraryUpload::of_failure(&fence, 0.1, "out of memory".into());
    client.upload_library(lease.id, &failure).await.unwrap();
    let view = client.library(library.id).await.unwrap();
    assert_eq!(view.status, LibraryStatus::Failed);
    let error = view.error.unwrap_or_default();
    assert!(
        error.contains("`liar` could not build it: out of memory"),
        "{error}"
    );
    // A second answer finds the build over.
    let (status, _) = refused(
        client
            .upload_library(
                lease.id,
                &LibraryUpload::of_file(&fence, 0.1, honest.as_bytes()),
            )
            .await
            .unwrap_err(),
    );
    assert_eq!(status, 409);
    client.delete_library(library.id).await.unwrap();
}
