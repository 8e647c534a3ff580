//! End-to-end: the real coordinator and worker binaries drive campaigns to
//! convergence over HTTP, and the answers equal the in-process runner's to
//! the last bit, whatever the number of workers or the lease size.

use crate::support::*;
use std::time::Duration;
use tslg_api::{CampaignStatus, Method};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn library_and_ndd_campaigns_converge_through_the_service_and_cover_the_exact_value() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let _workers = two_workers(&server.url);
    let client = server.client();
    let library = ready_library(&client, "fvdm", true).await;
    let exact = exact("idm");
    for method in [Method::Library, Method::Ndd] {
        let request = campaign(method, library.id, "idm", 0.2, 7);
        let started = client.create_campaign(&request).await.unwrap();
        let view = finished(&client, started.id, Duration::from_secs(120)).await;
        assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
        assert!(view.relative_half_width.unwrap() <= 0.2);
        let (lo, hi) = (view.ci_low.unwrap(), view.ci_high.unwrap());
        assert!(
            lo <= exact && exact <= hi,
            "{method:?}: [{lo:e}, {hi:e}] misses {exact:e}"
        );
        assert_same(
            &view,
            &in_process(Some("fvdm").filter(|_| method == Method::Library), &request),
        );
        let history = client.history(view.id).await.unwrap();
        let last = history.points.last().expect("history");
        assert_eq!(
            (last.indices, last.estimate),
            (view.indices, view.estimate.unwrap())
        );
        assert!(history
            .points
            .windows(2)
            .all(|w| w[0].indices < w[1].indices));
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_stop_index_and_estimate_do_not_depend_on_workers_or_lease_sizes() {
    let setups: [(usize, &[&str]); 4] = [
        (1, &[]),
        (3, &[]),
        (2, &["--lease-size", "37"]),
        (3, &["--lease-size", "1000"]),
    ];
    let mut outcomes = Vec::new();
    for (workers, flags) in setups {
        let dir = scratch();
        let server = ServerProcess::start(&dir.path().join("db.sqlite"), flags);
        let _workers: Vec<_> = (0..workers)
            .map(|k| WorkerProcess::start(&server.url, 1, &format!("w{k}")))
            .collect();
        let client = server.client();
        let library = ready_library(&client, "fvdm", true).await;
        let mut views = Vec::new();
        // Both campaigns at once: they share the workers.
        let ids = [
            client
                .create_campaign(&campaign(Method::Library, library.id, "idm", 0.15, 11))
                .await
                .unwrap()
                .id,
            client
                .create_campaign(&campaign(Method::Ndd, library.id, "acc-aeb", 0.2, 11))
                .await
                .unwrap()
                .id,
        ];
        for id in ids {
            views.push(finished(&client, id, Duration::from_secs(120)).await);
        }
        outcomes.push(views);
    }
    let reference = [
        in_process(Some("fvdm"), &campaign(Method::Library, 0, "idm", 0.15, 11)),
        in_process(None, &campaign(Method::Ndd, 0, "acc-aeb", 0.2, 11)),
    ];
    for views in &outcomes {
        for (view, reference) in views.iter().zip(&reference) {
            assert_eq!(view.status, CampaignStatus::Converged);
            assert_same(view, reference);
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_ndd_baseline_of_over_a_million_tests_stores_far_fewer_rows_than_tests() {
    let dir = scratch();
    let database = dir.path().join("db.sqlite");
    let server = ServerProcess::start(&database, &[]);
    let _workers = two_workers(&server.url);
    let client = server.client();
    let library = ready_library(&client, "idm", false).await;
    let request = campaign(Method::Ndd, library.id, "idm", 0.045, 5);
    let id = client.create_campaign(&request).await.unwrap().id;
    let view = finished(&client, id, Duration::from_secs(600)).await;
    assert_eq!(view.status, CampaignStatus::Converged);
    assert!(view.tests > 1_000_000, "{} tests", view.tests);
    let exact = exact("idm");
    assert!(
        view.ci_low.unwrap() <= exact && exact <= view.ci_high.unwrap(),
        "{view:?}"
    );
    assert_same(&view, &in_process(None, &request));

    use sqlx::Connection;
    let mut db =
        sqlx::SqliteConnection::connect(&format!("sqlite://{}?mode=ro", database.display()))
            .await
            .unwrap();
    let mut rows = 0i64;
    for table in ["reports", "invalid_tests", "leases", "history"] {
        let (n,): (i64,) = sqlx::query_as(&format!("SELECT COUNT(*) FROM {table}"))
            .fetch_one(&mut db)
            .await
            .unwrap();
        eprintln!("{table}: {n} rows");
        rows += n;
    }
    eprintln!("{} tests, {rows} rows", view.tests);
    assert!(
        rows * 200 < view.tests as i64,
        "{rows} rows for {} tests",
        view.tests
    );
}
