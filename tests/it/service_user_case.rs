//! A user-defined case through the real coordinator and workers (issue 22
//! part 3): `tslg case create` defines the example cut-in case, the
//! coordinator lists it and keeps it over a restart, a worker offering its
//! program runs an NDD campaign of it, and the answer is the in-process
//! one, test for test.

use crate::support::*;
use std::path::Path;
use std::time::Duration;
use tslg_api::{CampaignStatus, CreateCampaign, CreateCase, Method};

fn repo(path: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(path)
        .display()
        .to_string()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_user_defined_case_is_defined_listed_and_run_by_workers_offering_its_program() {
    let dir = scratch();
    let database = dir.path().join("db.sqlite");
    let server = ServerProcess::start(&database, &[]);
    let client = server.client();
    let case_file = repo("examples/cases/cut-in.toml");
    let o = tslg(&["case", "create", &case_file, "--server", &server.url]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("case cut-in-py defined"));
    // The same again is accepted; another definition under its name is not.
    assert!(
        tslg(&["case", "create", &case_file, "--server", &server.url])
            .status
            .success()
    );
    let file = std::fs::read_to_string(&case_file).unwrap();
    let table = std::fs::read_to_string(repo("examples/cases/cut-in-exposure.csv")).unwrap();
    let other = client
        .create_case(&CreateCase {
            file: file.replace("objective_weight = 1.0", "objective_weight = 2.0"),
            table: table.clone(),
            table_name: None,
        })
        .await
        .unwrap_err()
        .to_string();
    assert!(other.contains("already defined, differently"), "{other}");
    let bad = client
        .create_case(&CreateCase {
            file: file
                .replace("name = \"cut-in-py\"", "name = \"other\"")
                .replacen("step = 2", "step = 0", 1),
            table: table.clone(),
            table_name: None,
        })
        .await
        .unwrap_err()
        .to_string();
    assert!(bad.contains("step = 0 must be > 0"), "{bad}");
    // 10¹² × 10²⁰ cells wrapped to 0 and aborted the coordinator; a 12 MB
    // summary was stored and served by every list. Both are 422s now.
    let other = file.replace("name = \"cut-in-py\"", "name = \"other\"");
    for (file, expected) in [
        (
            other
                .replacen("upper = 89\nstep = 2", "upper = 1e12\nstep = 1", 1)
                .replacen("upper = 10\nstep = 0.4", "upper = 1e20\nstep = 1", 1),
            "the grid has more than 10000000 scenarios",
        ),
        (
            other
                .lines()
                .map(|line| match line.starts_with("summary = ") {
                    true => format!("summary = \"{}\"", "a".repeat(12_000_000)),
                    false => line.to_owned(),
                })
                .collect::<Vec<_>>()
                .join("\n"),
            "summary is 12000000 bytes; at most 2000 are kept",
        ),
    ] {
        let refused = client
            .create_case(&CreateCase {
                file,
                table: table.clone(),
                table_name: None,
            })
            .await
            .unwrap_err();
        assert!(
            matches!(&refused, tslg_client::CallError::Refused { status: 422, detail } if detail.contains(expected)),
            "{refused}"
        );
    }
    assert!(client.health().await.is_ok(), "the coordinator still runs");

    // A restart keeps it.
    drop(server);
    let server = ServerProcess::start(&database, &[]);
    let client = server.client();
    let cases = client.cases().await.unwrap();
    let mine = cases
        .iter()
        .find(|c| c.name == "cut-in-py")
        .expect("listed");
    assert!(mine.user_defined);
    assert_eq!(mine.default_surrogate, "cutin-idm");
    assert_eq!(
        mine.picture_axes,
        ["range (m)".to_owned(), "range_rate (m/s)".to_owned()]
    );
    assert!(
        !cases
            .iter()
            .find(|c| c.name == "cut-in")
            .unwrap()
            .user_defined
    );

    // An NDD campaign of the program, run by the worker that offers it.
    let exec = format!(
        "cutin-idm=python3 {} cut-in-py",
        repo("examples/cases/cutin_idm.py")
    );
    let _worker = WorkerProcess::start_with(&server.url, 2, "py", &["--vut-exec", &exec]);
    let request = CreateCampaign {
        beta: 0.3,
        max_tests: 1_000_000,
        seed: 5,
        guard_outside: Some(false),
        ..CreateCampaign::new(
            "cut-in-py",
            Method::Ndd,
            serde_json::json!({"external": "cutin-idm"}),
        )
    };
    let view = client.create_campaign(&request).await.unwrap();
    assert_eq!(
        view.vut,
        serde_json::json!({"external": "cutin-idm", "mode": "episode"})
    );
    let view = finished(&client, view.id, Duration::from_secs(240)).await;
    assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
    // The same campaign in this process, the command line running the
    // program itself.
    let o = tslg(&[
        "evaluate",
        "--case-file",
        &case_file,
        "--method",
        "ndd",
        "--vut",
        "cutin-idm",
        "--beta",
        "0.3",
        "--seed",
        "5",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let own: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(view.tests, own["tests"].as_u64().unwrap());
    assert_eq!(view.events, own["events"].as_u64().unwrap());
    assert_eq!(
        view.estimate.unwrap().to_bits(),
        own["estimate"].as_f64().unwrap().to_bits()
    );
    // A running campaign is not deleted; once cancelled it is, with its
    // records.
    let running = client.create_campaign(&request).await.unwrap().id;
    let refused = client
        .delete_campaign(running)
        .await
        .unwrap_err()
        .to_string();
    assert!(refused.contains("cancel it first"), "{refused}");
    client.cancel_campaign(running).await.unwrap();
    client.delete_campaign(running).await.unwrap();
    assert!(client.campaign(running).await.is_err());
    let o = tslg(&[
        "campaign",
        "delete",
        &view.id.to_string(),
        "--server",
        &server.url,
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(client.campaign(view.id).await.is_err());
}

/// The library view of `id` once `done` holds, within `limit`.
async fn library_when(
    client: &tslg_client::Client,
    id: i64,
    limit: Duration,
    done: impl Fn(&tslg_api::LibraryView) -> bool,
) -> tslg_api::LibraryView {
    let started = std::time::Instant::now();
    loop {
        let view = client.library(id).await.unwrap();
        if done(&view) {
            return view;
        }
        assert!(started.elapsed() < limit, "library {id} stuck: {view:?}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_program_surrogates_library_is_built_by_workers_and_is_the_offline_one() {
    use tslg_api::{CreateLibrary, LibraryStatus, SearchRequest};
    let dir = scratch();
    // Short leases and a 1 s lease time-out: a killed worker's cells go to
    // another worker soon.
    let options = ["--lease-size", "300", "--lease-ttl-seconds", "1"];
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &options);
    let client = server.client();
    let case_file = repo("examples/cases/cut-in.toml");
    assert!(
        tslg(&["case", "create", &case_file, "--server", &server.url])
            .status
            .success()
    );
    let request = |search| CreateLibrary {
        case: "cut-in-py".into(),
        preset: None,
        surrogate: serde_json::json!({"external": "cutin-idm"}),
        exposure: Default::default(),
        search,
        threshold: None,
    };
    // Multistart descends through the program's answers: one worker
    // offering it runs the whole search.
    let multistart = client
        .create_library(&request(Some(SearchRequest::Multistart {
            starts: 20,
            seed: 4,
        })))
        .await
        .unwrap();
    let library = client.create_library(&request(None)).await.unwrap();
    // No worker offers the program yet: the build says so.
    let waiting = library_when(&client, library.id, Duration::from_secs(10), |v| {
        v.status_detail.is_some()
    })
    .await;
    assert!(
        waiting
            .status_detail
            .as_deref()
            .unwrap()
            .contains("waiting for a worker offering cutin-idm:cut-in-py:episode"),
        "{waiting:?}"
    );
    // A slow worker starts the build and is killed in the middle of it.
    let slow = format!(
        "cutin-idm=python3 {} slow cut-in-py",
        repo("tests/fixtures/faulty_case.py")
    );
    let doomed = WorkerProcess::start_with(&server.url, 1, "doomed", &["--vut-exec", &slow]);
    let started = library_when(&client, library.id, Duration::from_secs(60), |v| {
        v.progress.as_ref().is_some_and(|p| p.done >= 300)
    })
    .await;
    assert_eq!(started.status, LibraryStatus::Building, "killed too late");
    assert_eq!(started.progress.unwrap().total, 3420);
    doomed.kill();
    let exec = format!(
        "cutin-idm=python3 {} cut-in-py",
        repo("examples/cases/cutin_idm.py")
    );
    // Two workers finish it: each audits the other's events (an external
    // program's results are checked by another worker, docs/operations.md).
    let rescuers = [
        WorkerProcess::start_with(&server.url, 1, "rescuer-1", &["--vut-exec", &exec]),
        WorkerProcess::start_with(&server.url, 1, "rescuer-2", &["--vut-exec", &exec]),
    ];
    let ready = library_when(&client, library.id, Duration::from_secs(120), |v| {
        v.status != LibraryStatus::Building
    })
    .await;
    assert_eq!(ready.status, LibraryStatus::Ready, "{ready:?}");
    // The library is the one the command line builds running the program
    // itself, byte for byte.
    let served = client.library_file(library.id).await.unwrap();
    let offline = dir.path().join("offline.json");
    let o = tslg(&[
        "library",
        "build",
        "--case-file",
        &case_file,
        "-o",
        offline.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        String::from_utf8(served).unwrap(),
        std::fs::read_to_string(&offline).unwrap()
    );
    assert_eq!(ready.size, Some(286));
    let searched = library_when(&client, multistart.id, Duration::from_secs(120), |v| {
        v.status != LibraryStatus::Building
    })
    .await;
    assert_eq!(searched.status, LibraryStatus::Ready, "{searched:?}");
    let offline = dir.path().join("multistart.json");
    let o = tslg(&[
        "library",
        "build",
        "--case-file",
        &case_file,
        "--search",
        "multistart",
        "--starts",
        "20",
        "--seed",
        "4",
        "-o",
        offline.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        String::from_utf8(client.library_file(multistart.id).await.unwrap()).unwrap(),
        std::fs::read_to_string(&offline).unwrap()
    );
    assert!(searched.size.unwrap() > 0, "{searched:?}");

    // A program that crashes on a cell fails the build with its reason.
    let crash = format!(
        "cutin-idm=python3 {} crash cut-in-py",
        repo("tests/fixtures/faulty_case.py")
    );
    let broken = client
        .create_library(&CreateLibrary {
            threshold: Some(tslg_api::ThresholdRequest::Relative { m: 2.0 }),
            ..request(None)
        })
        .await
        .unwrap();
    drop(rescuers);
    let _crashers = [
        WorkerProcess::start_with(&server.url, 1, "crasher-1", &["--vut-exec", &crash]),
        WorkerProcess::start_with(&server.url, 1, "crasher-2", &["--vut-exec", &crash]),
    ];
    let failed = library_when(&client, broken.id, Duration::from_secs(120), |v| {
        v.status != LibraryStatus::Building
    })
    .await;
    assert_eq!(failed.status, LibraryStatus::Failed, "{failed:?}");
    let error = failed.error.unwrap();
    assert!(error.contains("injected crash at R = 51 m"), "{error}");
    // A failed library can be deleted, with the campaign that built it; the
    // ready one only once no campaign uses it.
    client.delete_library(broken.id).await.unwrap();
    let gone = client.library(broken.id).await.unwrap_err().to_string();
    assert!(gone.contains("does not exist"), "{gone}");
    // A campaign on the library keeps it.
    let user = client
        .create_campaign(&CreateCampaign {
            library_id: Some(library.id),
            max_tests: 100_000,
            seed: 1,
            guard_outside: Some(false),
            ..CreateCampaign::new(
                "cut-in-py",
                Method::Library,
                serde_json::json!({"external": "cutin-idm"}),
            )
        })
        .await
        .unwrap()
        .id;
    client.cancel_campaign(user).await.unwrap();
    let kept = client
        .delete_library(library.id)
        .await
        .unwrap_err()
        .to_string();
    assert!(
        kept.contains(&format!("used by campaign(s) {user}")),
        "{kept}"
    );
    client.delete_campaign(user).await.unwrap();
    let o = tslg(&[
        "library",
        "delete",
        &library.id.to_string(),
        "--server",
        &server.url,
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(client.library(library.id).await.is_err());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_program_surrogate_of_a_builtin_case_is_built_by_workers_in_step_mode() {
    use tslg_api::{CreateLibrary, LibraryStatus};
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    let exec = format!("py-idm=python3 {}", repo("examples/python/idm_vut.py"));
    let _workers = [
        WorkerProcess::start_with(&server.url, 1, "py-1", &["--vut-exec", &exec]),
        WorkerProcess::start_with(&server.url, 1, "py-2", &["--vut-exec", &exec]),
    ];
    let request = |surrogate| CreateLibrary {
        case: "cut-in".into(),
        preset: None,
        surrogate,
        exposure: Default::default(),
        search: Some(tslg_api::SearchRequest::Exhaustive),
        threshold: None,
    };
    let by_program = client
        .create_library(&request(serde_json::json!({"external": "py-idm"})))
        .await
        .unwrap();
    let builtin = build_library(&client, &request(serde_json::json!({"model": "idm"}))).await;
    let by_program = library_when(&client, by_program.id, Duration::from_secs(120), |v| {
        v.status != LibraryStatus::Building
    })
    .await;
    assert_eq!(by_program.status, LibraryStatus::Ready, "{by_program:?}");
    // The Python IDM, driven step by step by the workers, fails where the
    // built-in IDM does.
    assert_eq!(by_program.size, builtin.size);
    assert_eq!(by_program.mu_s, builtin.mu_s);
    assert_eq!(
        by_program.surrogate,
        serde_json::json!({"external": "py-idm", "mode": "step"})
    );
}
