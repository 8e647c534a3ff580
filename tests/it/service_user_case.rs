//! A user-defined case through the real coordinator and workers (issue 22
//! part 3): `tslg case create` defines the example cut-in case, the
//! coordinator lists it and keeps it over a restart, a worker offering its
//! program runs an NDD campaign of it, and the answer is the in-process
//! one, test for test.

use crate::support::*;
use std::path::Path;
use std::process::Command;
use std::time::Duration;
use tslg_api::{CampaignStatus, CreateCampaign, CreateCase, Method};

fn repo(path: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(path)
        .display()
        .to_string()
}

fn tslg(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_tslg"))
        .args(args)
        .output()
        .expect("tslg runs")
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
            table,
            table_name: None,
        })
        .await
        .unwrap_err()
        .to_string();
    assert!(bad.contains("step = 0 must be > 0"), "{bad}");

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
        case: "cut-in-py".into(),
        method: Method::Ndd,
        library_id: None,
        vut: serde_json::json!({"external": "cutin-idm"}),
        epsilon: 0.1,
        outside: None,
        split: None,
        beta: 0.3,
        confidence: 0.9,
        max_tests: 1_000_000,
        seed: 5,
        n_min: None,
        min_events: None,
        guard_outside: false,
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
}
