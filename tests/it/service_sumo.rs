//! The cut-in in SUMO, the open traffic simulator (issue 22 part 5):
//! `examples/cases/cutin_sumo.py` drives SUMO's IDM through libsumo as the
//! program of the user-defined case `examples/cases/cut-in-sumo.toml`.
//! Through the real coordinator and workers its library is built with the
//! SUMO vehicle as the surrogate (the command line's library, byte for
//! byte), and a library campaign and an NDD campaign of it agree with each
//! other and with the exact answer the command line enumerates.
//! SUMO comes from PyPI (scripts/install-test-deps, target/sumo-venv); the
//! test says SKIPPED when it is not there.

use crate::support::*;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;
use tslg_api::{CampaignStatus, CreateCampaign, CreateLibrary, LibraryStatus, Method};

fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

/// The interpreter that has SUMO, or why the test cannot run.
fn sumo_python() -> Result<PathBuf, String> {
    let python = repo("target/sumo-venv/bin/python");
    let ok = Command::new(&python)
        .args(["-c", "import libsumo, sumo"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if ok {
        Ok(python)
    } else {
        Err(format!(
            "SUMO (PyPI eclipse-sumo, libsumo) is not installed at {}: run \
             scripts/install-test-deps",
            python.display()
        ))
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_sumo_vehicle_is_a_surrogate_and_its_library_and_ndd_campaigns_agree() {
    let python = match sumo_python() {
        Ok(p) => p,
        Err(why) => {
            tslg_testkit::skip("sumo", &why);
            return;
        }
    };
    let dir = scratch();
    let script = repo("examples/cases/cutin_sumo.py");
    let command = format!("{} {} --model IDM", python.display(), script.display());
    // The example case file with its program run by SUMO's interpreter.
    let case_file = dir.path().join("cut-in-sumo.toml");
    let text = std::fs::read_to_string(repo("examples/cases/cut-in-sumo.toml"))
        .unwrap()
        .replace("python3 cutin_sumo.py --model IDM", &command)
        .replace(
            "exposure = \"cut-in-sumo-exposure.csv\"",
            &format!(
                "exposure = \"{}\"",
                repo("examples/cases/cut-in-sumo-exposure.csv").display()
            ),
        );
    std::fs::write(&case_file, text).unwrap();
    let case_file = case_file.to_str().unwrap();

    // The command line: SUMO's library and exact answer, running it itself.
    let offline = dir.path().join("offline.json");
    let o = tslg(&[
        "library",
        "build",
        "--case-file",
        case_file,
        "-o",
        offline.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = tslg(&["exact", "--case-file", case_file]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let exact: f64 = String::from_utf8_lossy(&o.stdout)
        .lines()
        .find(|l| l.starts_with("sumo-idm"))
        .and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        .expect("the exact row");
    assert!(exact > 0.01, "SUMO's IDM has accidents here: {exact}");

    // The service: the case defined, its library built by two workers
    // running SUMO.
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    let o = tslg(&["case", "create", case_file, "--server", &server.url]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let exec = format!("sumo-idm={command}");
    let _workers = [
        WorkerProcess::start_with(&server.url, 1, "sumo-1", &["--vut-exec", &exec]),
        WorkerProcess::start_with(&server.url, 1, "sumo-2", &["--vut-exec", &exec]),
    ];
    let library = client
        .create_library(&CreateLibrary {
            case: "cut-in-sumo".into(),
            preset: None,
            surrogate: serde_json::json!({"external": "sumo-idm"}),
            exposure: Default::default(),
            search: None,
            threshold: None,
        })
        .await
        .unwrap();
    let started = std::time::Instant::now();
    let library = loop {
        let view = client.library(library.id).await.unwrap();
        if view.status != LibraryStatus::Building {
            break view;
        }
        assert!(started.elapsed() < Duration::from_secs(120), "{view:?}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    assert_eq!(library.status, LibraryStatus::Ready, "{library:?}");
    assert_eq!(
        String::from_utf8(client.library_file(library.id).await.unwrap()).unwrap(),
        std::fs::read_to_string(&offline).unwrap()
    );

    // A library campaign and the NDD baseline of the SUMO vehicle.
    let campaign = |method, seed| CreateCampaign {
        library_id: Some(library.id),
        max_tests: 1_000_000,
        seed,
        guard_outside: Some(false),
        ..CreateCampaign::new(
            "cut-in-sumo",
            method,
            serde_json::json!({"external": "sumo-idm"}),
        )
    };
    let mut views = Vec::new();
    for (method, seed) in [(Method::Library, 1), (Method::Ndd, 2)] {
        let id = client
            .create_campaign(&campaign(method, seed))
            .await
            .unwrap()
            .id;
        let view = finished(&client, id, Duration::from_secs(240)).await;
        assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
        views.push(view);
    }
    let (by_library, by_ndd) = (&views[0], &views[1]);
    assert!(
        by_ndd.tests > 10 * by_library.tests,
        "the library needs far fewer tests: {} against {}",
        by_library.tests,
        by_ndd.tests
    );
    // They agree: the intervals overlap, and each estimate is within three
    // half-widths of the exact answer.
    assert!(
        by_library.ci_low.unwrap() <= by_ndd.ci_high.unwrap()
            && by_ndd.ci_low.unwrap() <= by_library.ci_high.unwrap(),
        "{by_library:?} {by_ndd:?}"
    );
    for view in &views {
        let (estimate, half_width) = (view.estimate.unwrap(), view.half_width.unwrap());
        assert!(
            (estimate - exact).abs() < 3.0 * half_width,
            "{estimate} ± {half_width} vs {exact}"
        );
    }
}
