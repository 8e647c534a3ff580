//! Library builds of built-in surrogates on workers (issue 22 part 4):
//! with `--library-builds workers` the coordinator leases an exhaustive
//! build's surrogate runs to the workers, says it waits while none is up,
//! and serves the library the command line builds, byte for byte; searches
//! that choose their next run from the last (multistart) stay on the
//! coordinator.

use crate::support::*;
use std::process::Command;
use std::time::{Duration, Instant};
use tslg_api::{CreateLibrary, LibraryStatus, LibraryView, SearchRequest};

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

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn exhaustive_builds_of_builtin_surrogates_run_on_workers_and_equal_the_offline_ones() {
    let dir = scratch();
    let options = ["--library-builds", "workers", "--lease-size", "200"];
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &options);
    let client = server.client();
    let request = |case: &str, preset: Option<&str>, surrogate: &str, search| CreateLibrary {
        case: case.into(),
        preset: preset.map(Into::into),
        surrogate: serde_json::json!({"model": surrogate}),
        exposure: Default::default(),
        search,
        threshold: None,
    };
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
    // A multistart search picks each run from the last: the coordinator
    // builds it with no worker up.
    let multistart = settled(
        &client,
        client
            .create_library(&request(
                "cut-in",
                None,
                "idm",
                Some(SearchRequest::Multistart { starts: 5, seed: 0 }),
            ))
            .await
            .unwrap()
            .id,
        Duration::from_secs(60),
    )
    .await;
    assert_eq!(multistart.status, LibraryStatus::Ready, "{multistart:?}");
    // The exhaustive builds wait, visibly, for a worker.
    for id in [cutin.id, highway.id] {
        let view = client.library(id).await.unwrap();
        assert_eq!(view.status, LibraryStatus::Building, "{view:?}");
        let detail = view.status_detail.unwrap_or_default();
        assert!(detail.contains("waiting for a worker"), "{detail}");
        assert_eq!(view.progress.map(|p| p.done), Some(0));
    }
    let _workers = two_workers(&server.url);
    let cutin = settled(&client, cutin.id, Duration::from_secs(120)).await;
    let highway = settled(&client, highway.id, Duration::from_secs(120)).await;
    assert_eq!(cutin.status, LibraryStatus::Ready, "{cutin:?}");
    assert_eq!(highway.status, LibraryStatus::Ready, "{highway:?}");
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
}
