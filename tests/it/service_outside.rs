//! The outside bound through the service: a library campaign of a vehicle
//! that fails where its surrogate does not (the IDM library testing the
//! FVDM on cut-in) stops early with an interval far from the truth, which
//! only its guarded interval shows (no exploring test met a failure yet, so
//! there is no evidence to warn on); with the guard it keeps testing until the failure
//! mass outside the library is bounded, and every figure equals the
//! in-process run's to the bit, also for a campaign whose exploring tests
//! are counted again after an upgrade.

use crate::support::*;
use sqlx::sqlite::SqliteConnectOptions;
use sqlx::{ConnectOptions, Connection};
use std::time::Duration;
use tslg_api::{CampaignStatus, CreateCampaign, Method, Outside};

fn guarded(library_id: i64, beta: f64) -> CreateCampaign {
    CreateCampaign {
        epsilon: 0.5,
        outside: Some(Outside::Ndd),
        guard_outside: Some(true),
        ..campaign(Method::Library, library_id, "fvdm", beta, 3)
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_mismatched_surrogate_is_flagged_and_the_guard_keeps_testing_until_the_outside_is_bounded(
) {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let _workers = two_workers(&server.url);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let exact = exact("fvdm");

    // The plain rule: converged at n_min, the interval far below P(A),
    // but the outside bound and the guarded interval say what is unknown.
    // It warns only on evidence: an event among its three exploring tests.
    let plain = CreateCampaign {
        n_min: Some(30),
        ..campaign(Method::Library, library.id, "fvdm", 0.2, 3)
    };
    let id = client.create_campaign(&plain).await.unwrap().id;
    let view = finished(&client, id, Duration::from_secs(120)).await;
    assert_eq!(view.status, CampaignStatus::Converged);
    assert!(view.ci_high.unwrap() < exact, "{view:?}");
    assert!(view.guarded_ci_high.unwrap() >= exact, "{view:?}");
    assert!(view.outside_upper.unwrap() > 0.2 * view.estimate.unwrap());
    assert_eq!(view.outside_tests, 3, "{view:?}");
    assert_eq!(
        view.warnings
            .iter()
            .any(|w| w.contains("does not bound what the library leaves out")),
        view.outside_events > 0,
        "{view:?}"
    );
    assert_same(&view, &in_process(Some("idm"), &plain));

    // Guarded: many more tests, the vehicle's failures outside the library
    // found and flagged as a mismatch, the interval around P(A).
    let request = guarded(library.id, 0.2);
    let id = client.create_campaign(&request).await.unwrap().id;
    let view = finished(&client, id, Duration::from_secs(120)).await;
    assert_eq!(view.status, CampaignStatus::Converged);
    assert!(view.guard_outside);
    assert!(view.tests > 1000, "{view:?}");
    // The library stratum was known long before the outside: the campaign
    // switched to exploring nearly every test.
    assert!(
        view.explore_from
            .is_some_and(|from| from < view.indices / 2),
        "{view:?}"
    );
    assert!(view.mismatched_events > 0 && view.mismatched_events <= view.outside_events);
    assert!(view.outside_share.unwrap() > 0.5, "{view:?}");
    assert!(view
        .warnings
        .iter()
        .any(|w| w.contains("surrogate mismatch")));
    // It is not told to turn on the guard it runs with.
    assert!(
        !view.warnings.iter().any(|w| w.contains("guard_outside")),
        "{:?}",
        view.warnings
    );
    let (estimate, upper) = (view.estimate.unwrap(), view.outside_upper.unwrap());
    let seen = view.outside_share.unwrap() * estimate;
    assert!(upper - seen <= 0.2 * estimate * (1.0 + 1e-12), "{view:?}");
    assert!(view.ci_low.unwrap() <= exact && exact <= view.guarded_ci_high.unwrap());
    assert!(view
        .status_detail
        .as_deref()
        .unwrap()
        .contains("outside the library bounded"));
    assert_same(
        &view,
        &in_process_switched("idm", &request, view.explore_from),
    );

    // A surrogate that fails wherever the vehicle does (the FVDM's library
    // testing the IDM): whatever failures of the vehicle the guarded
    // campaign meets outside the library (about 11 % of its failure mass
    // lies there, and each exploring test finds it with probability near
    // 10⁻⁴, so a campaign of this size meets one or two, or none), none is
    // a mismatch, so no such warning; the guarded interval holds P(A).
    let covering = ready_library(&client, "fvdm", true).await;
    let exact_idm = crate::support::exact("idm");
    let request = CreateCampaign {
        vut: serde_json::json!({"model": "idm"}),
        ..guarded(covering.id, 0.2)
    };
    let id = client.create_campaign(&request).await.unwrap().id;
    let view = finished(&client, id, Duration::from_secs(120)).await;
    assert_eq!(view.status, CampaignStatus::Converged);
    assert!(view.outside_tests > 1000, "{view:?}");
    assert_eq!(view.mismatched_events, 0, "{view:?}");
    assert!(view.ci_low.unwrap() <= exact_idm && exact_idm <= view.guarded_ci_high.unwrap());
    assert!(
        !view
            .warnings
            .iter()
            .any(|w| w.contains("surrogate mismatch")),
        "{:?}",
        view.warnings
    );
    assert_same(
        &view,
        &in_process_switched("fvdm", &request, view.explore_from),
    );

    // The guard needs a library outside to bound.
    let ndd = CreateCampaign {
        method: Method::Ndd,
        ..guarded(library.id, 0.2)
    };
    let refused = client.create_campaign(&ndd).await.unwrap_err().to_string();
    assert!(
        refused.contains("422") && refused.contains("no outside to guard"),
        "{refused}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_campaign_started_before_the_outside_bound_is_counted_again_from_its_first_test() {
    let dir = scratch();
    let database = dir.path().join("db.sqlite");
    // The killed worker's lease holds the prefix until it expires: a short
    // TTL, so the test does not wait out the default 30 s.
    let options = ["--lease-size", "5000", "--lease-ttl-seconds", "2"];
    let server = ServerProcess::start(&database, &options);
    let worker = WorkerProcess::start(&server.url, 1, "w1");
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let request = guarded(library.id, 0.05);
    let id = client.create_campaign(&request).await.unwrap().id;
    let before = wait_for(&client, id, Duration::from_secs(120), |v| {
        v.indices >= 40_000
    })
    .await;
    assert_eq!(before.status, CampaignStatus::Running);
    assert!(before.outside_tests > 0);
    drop(worker);
    server.kill();

    // What the migration of the outside bound leaves for a campaign of the
    // release before it. (Its `S₂,out` stays: a campaign from before that
    // column keeps the pooled variance and the proportional split.)
    let mut conn = SqliteConnectOptions::new()
        .filename(&database)
        .connect()
        .await
        .unwrap();
    sqlx::query(
        "UPDATE campaigns SET outside_tests = 0, outside_events = 0, outside_s1 = 0, \
         outside_mismatches = 0, outside_upper = NULL",
    )
    .execute(&mut conn)
    .await
    .unwrap();
    conn.close().await.unwrap();

    let server = ServerProcess::start(&database, &options);
    let client = server.client();
    let blank = client.campaign(id).await.unwrap();
    assert_eq!((blank.outside_tests, blank.outside_upper), (0, None));
    let _worker = WorkerProcess::start(&server.url, 1, "w2");
    let view = finished(&client, id, Duration::from_secs(300)).await;
    assert_eq!(view.status, CampaignStatus::Converged);
    assert_same(
        &view,
        &in_process_switched("idm", &request, view.explore_from),
    );
    // What the view predicted at 40,000 tests counts the guard's tests,
    // not only the interval's (which had nearly reached β by then).
    let predicted = before.predicted_tests.unwrap() as f64;
    eprintln!(
        "predicted {predicted} at {}, stopped at {}",
        before.tests, view.tests
    );
    assert!(
        (0.7..1.5).contains(&(predicted / view.tests as f64)),
        "predicted {predicted} at {} tests, stopped at {}",
        before.tests,
        view.tests
    );
}

/// Reports that arrive out of order: the last range first, held behind
/// the others; then the first, whose fold passes only its own; then the
/// middle one, whose fold passes it and the last. Each fold takes the
/// exploring tests of the ranges it passes from the coordinator's own runs
/// of their reports, kept until then: it draws none again
/// (`tslg_fold_drawn_tests_total`), and the exploring tests counted, and
/// everything else, are the in-process campaign's.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ranges_folded_after_later_ones_count_the_same_exploring_tests_without_drawing_them_again()
{
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &["--lease-size", "4000"]);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let request = CreateCampaign {
        max_tests: 12_000,
        ..guarded(library.id, tslg_method::estimator::MIN_BETA)
    };
    let id = client.create_campaign(&request).await.unwrap().id;
    let mut leases = Vec::new();
    for worker in ["w1", "w2", "w3"] {
        let lease = client.claim(&ask(worker, &[])).await.unwrap().unwrap();
        leases.push((lease, worker));
    }
    let ranges: Vec<(u64, u64)> = leases.iter().map(|(l, _)| (l.start, l.end)).collect();
    assert_eq!(ranges, [(0, 4_000), (4_000, 8_000), (8_000, 12_000)]);
    for (k, prefix) in [(2, 0), (0, 4_000), (1, 12_000)] {
        let (lease, worker) = &leases[k];
        let events = real_events(&client, id, lease.start, lease.end).await;
        client
            .report(lease.id, &whole(lease, worker, events))
            .await
            .unwrap();
        let view = client.campaign(id).await.unwrap();
        assert_eq!(view.indices, prefix, "after range {k}: {view:?}");
    }
    let view = finished(&client, id, Duration::from_secs(60)).await;
    assert!(view.outside_tests > 1_000, "{view:?}");
    assert_same(
        &view,
        &in_process_switched("idm", &request, view.explore_from),
    );
    assert_eq!(
        scraped(&server.url, "tslg_fold_drawn_tests_total").await,
        0.0
    );
}
