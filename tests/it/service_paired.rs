//! Paired regression campaigns through the service: two campaigns drawing
//! the same tests, folded by the coordinator into the difference of the
//! two vehicles' rates. The pair must stop exactly where the same paired
//! campaign run in this process stops, with the same sums, whichever
//! worker reported which campaign's tests first; cancelling or deleting
//! either campaign takes the other with it.

use crate::support::*;
use serde_json::{json, Value};
use std::time::Duration;
use tslg_api::{CampaignStatus, CampaignView, CreateCampaign, Method, PairStop, PairView};
use tslg_method::cases::open_case;
use tslg_method::paired::{run_paired, PairedResult, PairedStop};
use tslg_method::registry::ExposureSource;

/// The paired campaign `request` asks for, run in this process on the
/// library `file` (the NDD when `None`).
fn paired_in_process(file: Option<&[u8]>, request: &CreateCampaign) -> PairedResult {
    let case = open_case(&request.case, None, &ExposureSource::Builtin).unwrap();
    let tests = |vut: &Value| {
        let vut = case
            .normalise_vehicle(&tslg_api::vehicle_spec(vut))
            .unwrap();
        case.campaign(
            file,
            &vut,
            request.epsilon,
            case.default_outside(),
            Default::default(),
            request.seed,
        )
        .unwrap()
    };
    let a = tests(&request.vut);
    let b = tests(request.paired_with.as_ref().unwrap());
    run_paired(a.as_ref(), b.as_ref(), &rule_of(request))
}

/// The pair's numbers equal the in-process run's, bit for bit: both fold
/// the same outcomes in index order.
fn assert_same_pair(pair: &PairView, reference: &PairedResult) {
    let triple = |i: Option<tslg_api::PairedInterval>| {
        let i = i.expect("an interval");
        (i.estimate, i.ci_low, i.ci_high)
    };
    assert_eq!(pair.tests, reference.tests, "{pair:?}\n{reference:?}");
    assert_eq!(
        (pair.events_a, pair.events_b, pair.discordant),
        reference.events
    );
    assert_eq!(triple(pair.rate_a), reference.rate_a);
    assert_eq!(triple(pair.rate_b), reference.rate_b);
    assert_eq!(triple(pair.difference), reference.difference);
    assert_eq!(pair.look_confidence, reference.look_confidence);
    let stop = match reference.stop {
        PairedStop::Precision => PairStop::Precision,
        PairedStop::Significant => PairStop::Significant,
        PairedStop::Exhausted => PairStop::Exhausted,
    };
    assert_eq!(pair.stop, Some(stop));
}

fn ndd_regression() -> CreateCampaign {
    CreateCampaign {
        method: Method::Ndd,
        library_id: None,
        vut: json!({"model": "idm", "s0": 0.5}),
        paired_with: Some(json!("idm")),
        ..campaign(Method::Ndd, 0, "idm", 0.2, 1)
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_paired_campaign_stops_where_the_same_pair_in_process_stops_and_stops_both() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let _workers = two_workers(&server.url);
    let client = server.client();

    // A regression under the NDD, started with the command line as a user
    // would: today's IDM with a 0.5 m jam distance against yesterday's.
    let o = tslg(&[
        "campaign",
        "start",
        "--server",
        &server.url,
        "--method",
        "ndd",
        "--vut",
        r#"{"model": "idm", "s0": 0.5}"#,
        "--paired-with",
        "idm",
        "--seed",
        "1",
        "--wait",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let a: CampaignView = serde_json::from_slice(&o.stdout).unwrap();
    let pair = a.pair.clone().expect("a paired campaign shows its pair");
    assert_eq!(pair.campaign_a, a.id);
    assert_eq!(pair.status, CampaignStatus::Converged);
    assert_same_pair(&pair, &paired_in_process(None, &ndd_regression()));
    // Both campaigns stopped with the pair, and each says why.
    let b = client.campaign(pair.campaign_b).await.unwrap();
    for view in [&a, &b] {
        assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
        let detail = view.status_detail.as_deref().unwrap();
        assert!(detail.starts_with("paired with campaign"), "{detail}");
        assert!(view.indices >= pair.indices, "{view:?}");
    }
    assert_eq!(b.pair.as_ref(), Some(&pair));
    assert_eq!(b.vut["s0"], json!(2.0));
    // The grid enumerates: the exact difference is shown beside it.
    let exact = a.exact_probability.unwrap() - b.exact_probability.unwrap();
    assert_eq!(pair.exact_difference, Some(exact));
    // Far fewer tests than two separate campaigns would need.
    assert!(
        pair.independent_tests.unwrap() > 10.0 * pair.tests as f64,
        "{pair:?}"
    );
    // The text form says the same.
    let o = tslg(&[
        "campaign",
        "status",
        &b.id.to_string(),
        "--server",
        &server.url,
    ]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains(&format!("paired: a = campaign {}", a.id)),
        "{text}"
    );
    assert!(text.contains("difference a - b"), "{text}");
    // A campaign that resolved more than the pair decided on says so.
    assert_eq!(
        text.contains(&format!(
            "(the pair decides on its first {} tests; this campaign's own figures above \
             count all {} it resolved)",
            pair.tests, b.indices
        )),
        b.indices > pair.tests,
        "{text}"
    );

    // As a pipeline's gate the pair is judged on the difference's upper end.
    let gate = |limit: &str| {
        tslg(&[
            "campaign",
            "watch",
            &a.id.to_string(),
            "--server",
            &server.url,
            "--fail-above",
            limit,
        ])
    };
    let above = gate("0.00005");
    assert_eq!(
        above.status.code(),
        Some(3),
        "{}",
        String::from_utf8_lossy(&above.stderr)
    );
    let passed = gate("0.001");
    assert_eq!(passed.status.code(), Some(0));
    let said = String::from_utf8_lossy(&passed.stderr);
    assert!(
        said.contains("the difference a - b's upper bound"),
        "{said}"
    );

    // A pair whose other vehicle no worker offers: the campaign workers can
    // run takes at most a lease ahead of it (the pair uses only the tests
    // both resolved), stays running, and says what the pair waits for.
    let waiting = CreateCampaign {
        paired_with: Some(json!({"external": "nobody"})),
        max_tests: 1_000_000,
        ..ndd_regression()
    };
    let a = client.create_campaign(&waiting).await.unwrap();
    wait_for(&client, a.id, Duration::from_secs(30), |v| v.indices > 0).await;
    // A worker found nothing more to take: the campaign is at its limit.
    until_waiting(&server.url, 1.0).await;
    let ahead = client.campaign(a.id).await.unwrap();
    assert_eq!(ahead.status, CampaignStatus::Running);
    assert!(ahead.leased <= 4096, "{ahead:?}");
    assert!(
        ahead
            .warnings
            .iter()
            .any(|w| w.starts_with("its pair's campaign") && w.contains("nobody")),
        "{:?}",
        ahead.warnings
    );
    let r = reqwest::Client::new()
        .post(format!("{}/api/v1/campaigns/{}/cancel", server.url, a.id))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 200);

    // The same vehicle twice never differs: both campaigns reach max_tests,
    // the first waits (running) for the other, and the pair's last fold
    // comes with the later one.
    let same = CreateCampaign {
        vut: json!("idm"),
        paired_with: Some(json!("idm")),
        max_tests: 20_000,
        ..ndd_regression()
    };
    let id = client.create_campaign(&same).await.unwrap().id;
    // Neither campaign stops before the pair: the first to reach max_tests
    // waits, running, for the other.
    let view = finished(&client, id, Duration::from_secs(120)).await;
    let pair = view.pair.clone().unwrap();
    assert_eq!(view.status, CampaignStatus::Exhausted, "{view:?}");
    assert_eq!(pair.stop, Some(PairStop::Exhausted));
    assert_eq!((pair.tests, pair.discordant), (20_000, 0));
    assert_eq!(pair.events_a, pair.events_b);
    assert_eq!(pair.difference.unwrap().estimate, 0.0);
    let partner = client.campaign(pair.campaign_b).await.unwrap();
    assert_eq!(partner.status, CampaignStatus::Exhausted);
    assert!(partner
        .status_detail
        .unwrap()
        .starts_with("paired with campaign"));

    // Under a library: the FVDM against the IDM on the IDM's library.
    let library = ready_library(&client, "idm", true).await;
    let request = CreateCampaign {
        paired_with: Some(json!({"model": "idm"})),
        ..campaign(Method::Library, library.id, "fvdm", 0.2, 5)
    };
    let id = client.create_campaign(&request).await.unwrap().id;
    let view = finished(&client, id, Duration::from_secs(120)).await;
    let file = client.library_file(library.id).await.unwrap();
    let pair = view.pair.clone().unwrap();
    assert_same_pair(&pair, &paired_in_process(Some(&file), &request));
    // The warnings' advice is the guard, which a pair takes only as two
    // campaigns of their own.
    let partner = client.campaign(pair.campaign_b).await.unwrap();
    let reruns: Vec<&String> = [&view, &partner]
        .into_iter()
        .flat_map(|v| &v.warnings)
        .filter(|w| w.contains("Rerun"))
        .collect();
    assert!(
        !reruns.is_empty(),
        "{:?} {:?}",
        view.warnings,
        partner.warnings
    );
    for w in reruns {
        assert!(
            w.contains("Rerun each vehicle as a campaign of its own"),
            "{w}"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pair_is_cancelled_and_deleted_whole_and_refuses_what_it_cannot_pair() {
    let dir = scratch();
    // No worker: the pair waits.
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    let a = client.create_campaign(&ndd_regression()).await.unwrap();
    let pair = a.pair.expect("the answer shows the pair");
    assert_eq!(pair.status, CampaignStatus::Running);
    assert_eq!((pair.tests, pair.difference), (0, None));
    let b = pair.campaign_b;
    assert_eq!(
        client.campaign(b).await.unwrap().pair.unwrap().campaign_a,
        a.id
    );

    // Deleting one while the other runs is refused; cancelling one cancels
    // both.
    let http = reqwest::Client::new();
    let url = |path: String| format!("{}/api/v1/campaigns/{path}", server.url);
    let cancelled: CampaignView = http
        .post(url(format!("{b}/cancel")))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(cancelled.status, CampaignStatus::Cancelled);
    assert_eq!(cancelled.pair.unwrap().stop, Some(PairStop::Cancelled));
    assert_eq!(
        client.campaign(a.id).await.unwrap().status,
        CampaignStatus::Cancelled
    );
    let r = http.delete(url(a.id.to_string())).send().await.unwrap();
    assert_eq!(r.status().as_u16(), 204);
    for id in [a.id, b] {
        let r = http.get(url(id.to_string())).send().await.unwrap();
        assert_eq!(r.status().as_u16(), 404, "campaign {id} went with its pair");
    }

    // A campaign of a running pair cannot be deleted.
    let a = client.create_campaign(&ndd_regression()).await.unwrap();
    let r = http.delete(url(a.id.to_string())).send().await.unwrap();
    assert_eq!(r.status().as_u16(), 409);

    // What cannot be paired is refused with the reason.
    let library = ready_library(&client, "idm", true).await;
    let refused = [
        (
            CreateCampaign {
                paired_with: Some(json!("idm")),
                ..campaign(Method::Adaptive, library.id, "fvdm", 0.2, 1)
            },
            "paired_with runs methods `library` and `ndd`",
        ),
        (
            CreateCampaign {
                paired_with: Some(json!("idm")),
                guard_outside: Some(true),
                ..campaign(Method::Library, library.id, "fvdm", 0.2, 1)
            },
            "no guard is defined for a difference",
        ),
        (
            CreateCampaign {
                paired_with: Some(json!({"model": "nope"})),
                ..campaign(Method::Library, library.id, "fvdm", 0.2, 1)
            },
            "paired_with: ",
        ),
    ];
    for (request, reason) in refused {
        let r = http
            .post(format!("{}/api/v1/campaigns", server.url))
            .json(&request)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status().as_u16(), 422);
        let problem: Value = r.json().await.unwrap();
        let detail = problem["detail"].as_str().unwrap();
        assert!(detail.contains(reason), "{detail}");
    }
}

/// A pair of a built-in vehicle and an external program: today's build is
/// a program workers offer (the Python IDM, examples/python/idm_vut.py),
/// yesterday's the built-in FVDM. The Python IDM is the built-in IDM test
/// for test, so the pair is the in-process pair of the FVDM and the IDM.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pair_with_an_external_program_is_the_same_pair_in_process() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let exec = python("py-idm", "examples/python/idm_vut.py", "");
    let _workers = [
        WorkerProcess::start_with(&server.url, 1, "py1", &["--vut-exec", &exec]),
        WorkerProcess::start_with(&server.url, 1, "py2", &["--vut-exec", &exec]),
    ];
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let request = CreateCampaign {
        vut: json!({"external": "py-idm"}),
        paired_with: Some(json!("fvdm")),
        ..campaign(Method::Library, library.id, "idm", 0.2, 11)
    };
    let id = client.create_campaign(&request).await.unwrap().id;
    let view = finished(&client, id, Duration::from_secs(240)).await;
    let pair = view.pair.clone().unwrap();
    let file = client.library_file(library.id).await.unwrap();
    let reference = CreateCampaign {
        vut: json!("idm"),
        ..request
    };
    assert_same_pair(&pair, &paired_in_process(Some(&file), &reference));
    // The program's campaign has no exact answer (the coordinator does not
    // run programs), so neither has the difference.
    assert_eq!(pair.exact_difference, None);
}

/// A worker caught forging after its honest results helped stop a pair:
/// its results are taken back, the pair runs again (both campaigns), and
/// honest workers take it to exactly the stop the in-process pair makes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pair_stopped_on_a_flagged_workers_results_runs_again_to_the_honest_stop() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &["--lease-size", "300"]);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let file = client.library_file(library.id).await.unwrap();
    let request = CreateCampaign {
        paired_with: Some(json!("idm")),
        ..campaign(Method::Library, library.id, "fvdm", 0.2, 5)
    };
    let a = client.create_campaign(&request).await.unwrap().id;
    let case = open_case("cut-in", None, &ExposureSource::Builtin).unwrap();
    let tests_of = |vut: &Value, seed| {
        case.campaign(
            Some(&file),
            vut,
            0.1,
            Default::default(),
            Default::default(),
            seed,
        )
        .unwrap()
    };

    // The worker reports its first lease, of campaign a, honestly.
    let first = client.claim(&ask("forger", &[])).await.unwrap().unwrap();
    assert_eq!(first.campaign_id, a);
    let events = honest_events(tests_of(&request.vut, 5).as_ref(), &first);
    client
        .report(first.id, &whole(&first, "forger", events))
        .await
        .unwrap();
    // Honest workers take the pair to its stop.
    let workers = two_workers(&server.url);
    let stopped = wait_for(&client, a, Duration::from_secs(120), |v| {
        v.pair.as_ref().is_some_and(|p| p.stop.is_some())
    })
    .await;
    let reference = paired_in_process(Some(&file), &request);
    assert_same_pair(stopped.pair.as_ref().unwrap(), &reference);
    drop(workers);

    // Then it forges a report of another campaign: refused, flagged, and
    // its results taken back everywhere, the pair's first lease too.
    let other = campaign(Method::Library, library.id, "fvdm", 0.2, 77);
    let c = client.create_campaign(&other).await.unwrap().id;
    let lease = client.claim(&ask("forger", &[])).await.unwrap().unwrap();
    assert_eq!(lease.campaign_id, c);
    let refused = client
        .report(lease.id, &whole(&lease, "forger", Vec::new()))
        .await;
    assert!(refused.is_err(), "a report hiding every event is refused");
    let reopened = client.campaign(a).await.unwrap();
    let pair = reopened.pair.clone().unwrap();
    assert_eq!(pair.stop, None, "the pair runs again: {pair:?}");
    assert_eq!(reopened.status, CampaignStatus::Running);
    assert_eq!(
        client.campaign(pair.campaign_b).await.unwrap().status,
        CampaignStatus::Running
    );

    // Honest workers run the taken-back tests again: the same stop.
    let _workers = two_workers(&server.url);
    let view = finished(&client, a, Duration::from_secs(120)).await;
    assert_same_pair(view.pair.as_ref().unwrap(), &reference);
    let b = client.campaign(pair.campaign_b).await.unwrap();
    assert!(b.status.is_final(), "{b:?}");
}
