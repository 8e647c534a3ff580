//! Anytime intervals through the service (issue 49): a campaign created
//! with `interval: anytime` stops on its confidence sequence, and the
//! coordinator's answer equals the in-process run's to the last bit, also
//! when the coordinator is killed and folds the sequences again from its
//! database. Campaigns the sequence does not cover are refused.

use crate::support::*;
use std::time::{Duration, Instant};
use tslg_api::{CampaignStatus, CampaignView, IntervalKind, Method};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn anytime_campaigns_stop_on_their_sequence_and_survive_a_coordinator_restart() {
    let dir = scratch();
    let database = dir.path().join("db.sqlite");
    let flags = ["--lease-size", "20000"];
    let server = ServerProcess::start(&database, &flags);
    let address = server.address.clone();
    let _worker = WorkerProcess::start(&server.url, 2, "w1");
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let exact = exact("idm");
    let requests = [Method::Ndd, Method::Library].map(|method| {
        let mut request = campaign(method, library.id, "idm", 0.3, 3);
        request.interval = IntervalKind::Anytime;
        request
    });
    let ids = [
        client.create_campaign(&requests[0]).await.unwrap().id,
        client.create_campaign(&requests[1]).await.unwrap().id,
    ];
    // The library campaign's spread defaults to `ndd` (the only one whose
    // exploring weights are bounded by P(X \ Φ)).
    let created = client.campaign(ids[1]).await.unwrap();
    assert_eq!(created.outside, tslg_api::Outside::Ndd);
    assert_eq!(created.interval, IntervalKind::Anytime);
    // Killed while the NDD campaign runs: the restarted coordinator has no
    // sequences in memory and folds them again from the stored outcomes.
    let started = Instant::now();
    loop {
        let view = client.campaign(ids[0]).await.unwrap();
        // The first report's range (20,000 tests): the NDD campaign needs
        // several more, so it is surely still running (at 40,000 a loaded
        // machine once saw it converge between two polls).
        if view.indices >= 20_000 {
            assert_eq!(view.status, CampaignStatus::Running, "killed too late");
            break;
        }
        assert!(started.elapsed() < Duration::from_secs(120), "{view:?}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    server.kill();
    let server = ServerProcess::start_on(&database, &address, &flags);
    let client = server.client();
    for (id, request) in ids.into_iter().zip(&requests) {
        let view = finished(&client, id, Duration::from_secs(300)).await;
        assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
        assert_eq!(view.interval, IntervalKind::Anytime);
        let (low, high) = (view.ci_low.unwrap(), view.ci_high.unwrap());
        assert!(
            low <= exact && exact <= high,
            "[{low:e}, {high:e}] misses {exact:e}"
        );
        // Stopped on the sequence: (U − L)/2 ≤ β μ̂.
        let half = view.half_width.unwrap();
        assert_eq!(half.to_bits(), ((high - low) / 2.0).to_bits());
        assert!(half <= 0.3 * view.estimate.unwrap());
        // The library campaign switched to exploring nearly every test once
        // its library stratum was known; the NDD campaign has no strata.
        let reference = match request.method {
            Method::Library => {
                let from = view.explore_from.expect("the library campaign switched");
                // At the first test not yet leased when the library
                // stratum was known: the end of a lease, the first or a
                // later one (when the first report lands depends on the
                // machine's load: a CI run once switched at 40,000).
                assert!(
                    from < view.indices && from % 20_000 == 0,
                    "switched at {from} of {}",
                    view.indices
                );
                // Before the switch ε of the tests explore, from it on the
                // late share (the in-process replay below checks the
                // count exactly; this bound reads it in numbers).
                let late = tslg_method::sampling::LATE_SHARE;
                let explored = 0.1 * from as f64 + 0.9 * late * (view.indices - from) as f64;
                assert!(view.outside_tests as f64 >= explored - 1.0, "{view:?}");
                in_process_switched("idm", request, Some(from))
            }
            _ => {
                assert_eq!(view.explore_from, None);
                in_process(None, request)
            }
        };
        assert_eq!(
            reference.interval,
            tslg_method::estimator::Interval::Anytime
        );
        assert_same(&view, &reference);
        // The history's points carry the sequence's interval.
        let history = client.history(id).await.unwrap();
        let last = history.points.last().unwrap();
        assert_eq!((last.ci_low, last.ci_high), (low, high));
        assert!(history.points.len() >= 10, "{}", history.points.len());
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn anytime_is_refused_where_no_sequence_is_defined() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    let library = ready_library(&client, "idm", false).await;
    let mut adaptive = campaign(Method::Adaptive, library.id, "idm", 0.2, 1);
    adaptive.interval = IntervalKind::Anytime;
    let mut paired = campaign(Method::Ndd, library.id, "idm", 0.2, 1);
    paired.interval = IntervalKind::Anytime;
    paired.paired_with = Some(serde_json::json!({ "model": "fvdm" }));
    let mut random = campaign(Method::Library, library.id, "idm", 0.2, 1);
    random.interval = IntervalKind::Anytime;
    random.split = Some(tslg_api::Split::Random);
    for (request, says) in [
        (adaptive, "adaptive campaign's stages"),
        (paired, "paired_with stops on the difference"),
        (random, "needs split `stratified`"),
    ] {
        let error = client
            .create_campaign(&request)
            .await
            .unwrap_err()
            .to_string();
        assert!(error.contains(says), "{error}");
    }
    let mut carfollow = campaign(Method::Ndd, library.id, "idm", 0.2, 1);
    carfollow.case = "car-following".into();
    carfollow.library_id = None;
    carfollow.interval = IntervalKind::Anytime;
    let error = client
        .create_campaign(&carfollow)
        .await
        .unwrap_err()
        .to_string();
    assert!(error.contains("no known largest value"), "{error}");
}

/// `--fail-above` on an anytime campaign decides as soon as the interval
/// lies wholly on one side of the limit, in both directions, long before
/// the campaign could reach its β; the campaign the command started is
/// cancelled. A Wald campaign is judged only at its stop.
#[test]
fn an_anytime_gate_decides_early_in_both_directions() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let _worker = WorkerProcess::start(&server.url, 1, "w1");
    let url = server.url.as_str();
    // β 0.01 needs about 10⁸ NDD tests of the IDM (P(A) 9.3e-4): the gate
    // must decide on the way.
    let gate = |limit: &str| {
        tslg(&[
            "campaign",
            "start",
            "--server",
            url,
            "--method",
            "ndd",
            "--vut",
            "idm",
            "--beta",
            "0.01",
            "--interval",
            "anytime",
            "--wait",
            "--json",
            "--fail-above",
            limit,
        ])
    };
    for (limit, code, said) in [
        ("1e-4", 3, "gate failed early"),
        ("0.01", 0, "gate passed early"),
    ] {
        let o = gate(limit);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(code), "{limit}: {stderr}");
        assert!(stderr.contains(said), "{stderr}");
        let view: CampaignView = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(view.status, CampaignStatus::Cancelled, "{view:?}");
        assert!(view.tests < 5_000_000, "decided after {} tests", view.tests);
        let (low, high) = (view.ci_low.unwrap(), view.ci_high.unwrap());
        let limit: f64 = limit.parse().unwrap();
        assert!(
            low > limit || high < limit,
            "[{low:e}, {high:e}] vs {limit}"
        );
    }
}
