//! Fair sharing: campaigns running at once get comparable worker time,
//! and a campaign started while a long one runs is not starved by it.

use crate::support::*;
use std::time::Duration;
use tslg_api::{CampaignStatus, Method};

const LIMIT: Duration = Duration::from_secs(60);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_long_campaigns_share_the_workers_in_comparable_worker_time() {
    let dir = scratch();
    // Short leases, so a few seconds hold many turns.
    let server = ServerProcess::start(
        &dir.path().join("db.sqlite"),
        &["--lease-target-seconds", "0.2"],
    );
    let _workers = two_workers(&server.url);
    let client = server.client();
    let library = ready_library(&client, "fvdm", true).await;
    // β so small that neither campaign can stop during the test: the
    // smallest allowed. (At β = 0.001 the library campaign converged after
    // 2.1 × 10⁷ tests, about 4 s of two workers on a fast host; at 10⁻⁴
    // it needs about a hundred times more.)
    let long = |method| {
        let mut request = campaign(
            method,
            library.id,
            "idm",
            tslg_method::estimator::MIN_BETA,
            5,
        );
        request.max_tests = 1 << 50;
        request
    };
    let first = client.create_campaign(&long(Method::Ndd)).await.unwrap();
    // The first campaign has the workers to itself for a while.
    let alone = wait_for(&client, first.id, LIMIT, |v| v.worker_seconds > 1.0).await;
    let second = client
        .create_campaign(&long(Method::Library))
        .await
        .unwrap();
    wait_for(&client, second.id, LIMIT, |v| v.worker_seconds > 0.0).await;
    let first_mark = client.campaign(first.id).await.unwrap().worker_seconds;
    let second_mark = client.campaign(second.id).await.unwrap().worker_seconds;
    tokio::time::sleep(Duration::from_secs(6)).await;
    let a = client.cancel_campaign(first.id).await.unwrap();
    let b = client.cancel_campaign(second.id).await.unwrap();
    for view in [&a, &b] {
        assert_eq!(view.status, CampaignStatus::Cancelled, "{view:?}");
        assert!(view.indices > 0, "no progress: {view:?}");
    }
    let spent_a = a.worker_seconds - first_mark;
    let spent_b = b.worker_seconds - second_mark;
    assert!(
        spent_a > 0.5 && spent_b > 0.5,
        "both advance: {spent_a:.2} s and {spent_b:.2} s of worker time"
    );
    // Within a factor of 2: lease sizes follow a noisy cost estimate, and
    // the time a worker waits for a report's acknowledgement (longer for
    // the library campaign's many events) is not simulation time.
    let share = spent_a.min(spent_b) / spent_a.max(spent_b);
    assert!(
        share > 0.5,
        "unfair split of worker time while both ran: {spent_a:.2} s vs {spent_b:.2} s \
         (first campaign alone before: {:.2} s)",
        alone.worker_seconds
    );
    // Worker time is what is shared, not test counts: the two methods
    // cost differently per test, and both counts still grew.
    assert!(a.leased > alone.leased && b.leased > 0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn leases_before_a_prediction_do_not_run_far_past_the_stop() {
    // Cheap tests (a cut-in NDD run is a few hundred nanoseconds): a lease
    // sized by time alone would hold millions before the campaign has the
    // events to predict its stop.
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let _workers = two_workers(&server.url);
    let client = server.client();
    for (beta, seed) in [(0.2, 1), (0.3, 2), (0.1, 3)] {
        let mut request = campaign(Method::Ndd, 0, "idm", beta, seed);
        request.library_id = None;
        request.max_tests = 1 << 40;
        let id = client.create_campaign(&request).await.unwrap().id;
        let view = finished(&client, id, LIMIT).await;
        assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
        // Leased: what the workers were given; a few leases in flight at
        // the stop are the price of not waiting for each report.
        assert!(
            view.leased <= 3 * view.indices + 4096,
            "β {beta}: {} tests leased for a stop at {}",
            view.leased,
            view.indices
        );
    }
}
