//! A worker cannot forge results (issue 20): the coordinator runs a
//! built-in vehicle's reported events and a secret sample of the rest again
//! and refuses a contradiction; an external program's tests are audited by
//! other workers, a disagreement is settled by a third, and the worker in
//! the minority is flagged, refused, and has every result it reported taken
//! back. Either way the campaign ends exactly where honest workers alone
//! take it.

use crate::support::*;
use std::path::Path;
use std::time::{Duration, Instant};
use tslg_api::{CampaignStatus, EventResult, Method};
use tslg_client::{CallError, Client};
use tslg_method::cases::open_case;
use tslg_method::registry::ExposureSource;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_forged_report_on_a_builtin_vehicle_is_refused_and_its_worker_undone() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &["--lease-size", "300"]);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let file = client.library_file(library.id).await.unwrap();
    let request = campaign(Method::Library, library.id, "fvdm", 0.1, 21);
    let id = client.create_campaign(&request).await.unwrap().id;
    let tests = open_case("cut-in", None, &ExposureSource::Builtin)
        .unwrap()
        .campaign(
            Some(&file),
            &request.vut,
            0.1,
            Default::default(),
            Default::default(),
            request.seed,
        )
        .unwrap();

    // An honest report first: accepted.
    let first = client.claim(&ask("forger", &[])).await.unwrap().unwrap();
    let events = honest_events(tests.as_ref(), &first);
    assert!(
        events.len() > 50,
        "a library campaign of the FVDM has many events"
    );
    let ack = client
        .report(first.id, &whole(&first, "forger", events))
        .await
        .unwrap();
    assert_eq!(ack.accepted, 300);
    // Then the adversary's report: the real events hidden, one made up.
    let second = client.claim(&ask("forger", &[])).await.unwrap().unwrap();
    let real = honest_events(tests.as_ref(), &second);
    let fake = (second.start..second.end)
        .find(|i| real.iter().all(|e| e.index != *i))
        .unwrap();
    let forged = vec![EventResult {
        index: fake,
        weight: tests.planned(fake).unwrap().weight,
    }];
    // The first test where the report and the truth part: a hidden event
    // or the made-up one.
    let caught = real[0].index.min(fake);
    match client
        .report(second.id, &whole(&second, "forger", forged))
        .await
    {
        Err(CallError::Refused {
            status: 422,
            detail,
        }) => {
            assert!(
                detail.contains(&format!("test {caught} was reported as")),
                "{detail}"
            );
            assert!(detail.contains("worker `forger` is flagged"), "{detail}");
        }
        other => panic!("a forged report was not refused: {other:?}"),
    }
    // Flagged: no more work, and its honest first report is taken back too.
    match client.claim(&ask("forger", &[])).await {
        Err(CallError::Refused {
            status: 403,
            detail,
        }) => {
            assert!(detail.contains("is flagged"), "{detail}")
        }
        other => panic!("a flagged worker got {other:?}"),
    }
    let listed = client.workers().await.unwrap().workers;
    let forger = listed.iter().find(|w| w.name == "forger").unwrap();
    assert!(
        forger
            .flagged
            .as_deref()
            .unwrap_or("")
            .contains(&format!("test {caught}")),
        "{forger:?}"
    );
    assert_eq!(client.campaign(id).await.unwrap().indices, 0);
    // A weight off in its last bits (a worker of another version, another
    // library): refused, and that worker flagged too.
    let third = client.claim(&ask("skewed", &[])).await.unwrap().unwrap();
    let mut events = honest_events(tests.as_ref(), &third);
    events[0].weight *= 1.0 + 1e-12;
    match client
        .report(third.id, &whole(&third, "skewed", events))
        .await
    {
        Err(CallError::Refused {
            status: 422,
            detail,
        }) => {
            assert!(
                detail.contains("but the coordinator's run gives an event of weight"),
                "{detail}"
            )
        }
        other => panic!("a skewed weight was not refused: {other:?}"),
    }
    let _workers = two_workers(&server.url);
    let view = finished(&client, id, Duration::from_secs(120)).await;
    assert_eq!(view.status, CampaignStatus::Converged);
    assert_same(&view, &in_process(Some("idm"), &request));

    // An operator clears the flag.
    let http = reqwest::Client::new();
    let clear = |name: &str| {
        http.delete(format!("{}/api/v1/workers/{name}/flag", server.url))
            .send()
    };
    assert_eq!(clear("forger").await.unwrap().status(), 204);
    assert_eq!(clear("forger").await.unwrap().status(), 404);
    assert!(client.claim(&ask("forger", &[])).await.is_ok());
}

/// Claims leases of the program `offer` as `name` and reports every test
/// without an event (hiding them all) until the coordinator refuses it;
/// the refusal it got.
async fn liar(client: Client, name: &str, offer: &str, limit: Duration) -> String {
    let started = Instant::now();
    while started.elapsed() < limit {
        match client.claim(&ask(name, &[offer])).await {
            Ok(Some(lease)) => {
                if let Err(CallError::Refused {
                    status: 403,
                    detail,
                }) = client
                    .report(lease.id, &whole(&lease, name, Vec::new()))
                    .await
                {
                    return detail;
                }
            }
            Ok(None) => tokio::time::sleep(Duration::from_millis(20)).await,
            Err(CallError::Refused {
                status: 403,
                detail,
            }) => return detail,
            Err(e) => panic!("{e}"),
        }
    }
    panic!("the liar was never caught")
}

/// The program the liars and honest workers of these tests offer.
const PY_IDM: &str = "py-idm:cut-in:step";

/// A library campaign of the Python IDM (`py-idm`) on the IDM library, as
/// the built-in IDM's campaign `builtin` (seed 8): its id and `builtin`.
async fn py_idm_campaign(client: &Client) -> (i64, tslg_api::CreateCampaign) {
    let library = ready_library(client, "idm", true).await;
    let builtin = campaign(Method::Library, library.id, "idm", 0.2, 8);
    let request = tslg_api::CreateCampaign {
        vut: serde_json::json!({"external": "py-idm"}),
        ..builtin.clone()
    };
    (client.create_campaign(&request).await.unwrap().id, builtin)
}

/// Two honest workers running the Python IDM.
fn honest_workers(url: &str) -> [WorkerProcess; 2] {
    let exec = format!(
        "py-idm=python3 {}",
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("examples/python/idm_vut.py")
            .display()
    );
    [
        WorkerProcess::start_with(url, 1, "honest-1", &["--vut-exec", &exec]),
        WorkerProcess::start_with(url, 1, "honest-2", &["--vut-exec", &exec]),
    ]
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_lying_worker_is_caught_by_replication_and_the_answer_is_the_honest_one() {
    let dir = scratch();
    let server = ServerProcess::start(
        &dir.path().join("db.sqlite"),
        &["--lease-size", "200", "--audit-share", "0.05"],
    );
    let client = server.client();
    let (id, builtin) = py_idm_campaign(&client).await;
    // The liar takes the first lease before anyone else is there.
    let offer = PY_IDM;
    let lease = client.claim(&ask("liar", &[offer])).await.unwrap().unwrap();
    assert_eq!(lease.start, 0);
    // Two honest workers running the Python IDM come.
    let _honest = honest_workers(&server.url);
    let started = Instant::now();
    while client
        .workers()
        .await
        .unwrap()
        .workers
        .iter()
        .filter(|w| w.name.starts_with("honest"))
        .count()
        < 2
    {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "the honest workers never came"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    // The liar reports its lease with every event hidden: accepted, and
    // held until others have run a secret twentieth of it again.
    let ack = client
        .report(lease.id, &whole(&lease, "liar", Vec::new()))
        .await
        .unwrap();
    assert_eq!(ack.accepted, 200);
    let held = client.campaign(id).await.unwrap();
    assert!(
        held.indices < 200,
        "the prefix waits for the audits: {held:?}"
    );
    // The liar goes on lying until it is refused.
    let refusal = liar(client.clone(), "liar", offer, Duration::from_secs(120)).await;
    assert!(refusal.contains("worker `liar` is flagged"), "{refusal}");
    assert!(
        refusal.contains("where two other workers found an event"),
        "{refusal}"
    );
    let view = finished(&client, id, Duration::from_secs(240)).await;
    assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
    // Exactly the campaign of the built-in IDM: nothing of the liar's stayed.
    assert_same(&view, &in_process(Some("idm"), &builtin));
    let audits = view.audits.unwrap();
    assert!(audits.settled >= 1 && audits.agreed >= 1, "{audits:?}");
    assert_eq!(audits.open, 0, "{audits:?}");
    let workers = client.workers().await.unwrap().workers;
    let flagged: Vec<&str> = workers
        .iter()
        .filter(|w| w.flagged.is_some())
        .map(|w| w.name.as_str())
        .collect();
    assert_eq!(flagged, ["liar"]);
}

/// The coordinator's sample of the quiet tests of a built-in vehicle's
/// NDD campaign: a worker that hides one event of each report is caught
/// when the hidden test is in the sample, each time with the replay share
/// (here 0.5), and the refusal names the hidden test. Reports of 20,000
/// tests are checked off the writer, reports of 100 on it (the decision
/// between the two is taken before the sample is drawn, so neither checks
/// less than the share); 40 of each with an event hidden: each count
/// Binomial(40, 0.5), between 8 and 32 (a chance of about 4 × 10⁻⁵ each to
/// fall outside), unless the sample is wired wrong on that path (a share
/// of 0 or 1 gives 0 or 40).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_ndd_worker_hiding_events_is_caught_at_the_replay_share() {
    let dir = scratch();
    let server = ServerProcess::start(
        &dir.path().join("db.sqlite"),
        &["--lease-size", "20000", "--replay-share", "0.5"],
    );
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let request = tslg_api::CreateCampaign {
        beta: tslg_method::estimator::MIN_BETA,
        max_tests: 1 << 40,
        ..campaign(Method::Ndd, library.id, "fvdm", 0.1, 5)
    };
    client.create_campaign(&request).await.unwrap();
    let tests = open_case("cut-in", None, &ExposureSource::Builtin)
        .unwrap()
        .campaign(
            None,
            &request.vut,
            0.1,
            Default::default(),
            Default::default(),
            request.seed,
        )
        .unwrap();
    let mut workers = 0;
    for lease_tests in [None, Some(100)] {
        let before = replay_metrics(&server.url).await;
        let (mut trials, mut caught, mut leases) = (0, 0, 0);
        while trials < 40 {
            let name = format!("hider-{workers}");
            let asked = tslg_api::LeaseRequest {
                max_tests: lease_tests,
                ..ask(&name, &[])
            };
            let lease = client.claim(&asked).await.unwrap().unwrap();
            leases += 1;
            assert!(leases < 20_000, "{trials} events hidden in {leases} leases");
            let mut events = honest_events(tests.as_ref(), &lease);
            if events.is_empty() {
                client
                    .report(lease.id, &whole(&lease, &name, events))
                    .await
                    .unwrap();
                continue;
            }
            let hidden = events.remove(events.len() / 2).index;
            trials += 1;
            match client.report(lease.id, &whole(&lease, &name, events)).await {
                Ok(ack) => assert_eq!(ack.accepted, lease.end - lease.resume_at),
                Err(CallError::Refused {
                    status: 422,
                    detail,
                }) => {
                    assert!(
                        detail.contains(&format!("test {hidden} was reported as no event")),
                        "{detail}"
                    );
                    caught += 1;
                    workers += 1;
                }
                Err(e) => panic!("{e}"),
            }
        }
        assert!(
            (8..=32).contains(&caught),
            "leases of {lease_tests:?} tests: caught {caught} of 40"
        );
        // Each report checked once, where the routing rule sends it: a
        // report of 20,000 tests (10,000 replays expected) to the blocking
        // pool, one of 100 (50) to the writer; and the sample chose the
        // share of the tests it was drawn from (5 sd).
        let after = replay_metrics(&server.url).await;
        let delta: Vec<f64> = (0..5).map(|k| after[k] - before[k]).collect();
        let (writer, request, pool, range, sampled) =
            (delta[0], delta[1], delta[2], delta[3], delta[4]);
        assert_eq!(writer + request + pool, leases as f64, "{delta:?}");
        match lease_tests {
            None => assert_eq!(pool, leases as f64, "{delta:?}"),
            Some(_) => assert!(writer >= 40.0, "{delta:?}"),
        }
        assert!(
            (sampled - range / 2.0).abs() < 5.0 * (range / 4.0).sqrt(),
            "{delta:?}"
        );
    }
}

/// The replay check's counters in `/metrics`: reports checked on the
/// writer, on the request's task and on the blocking pool; the tests the
/// samples were drawn from, and the tests they chose.
async fn replay_metrics(url: &str) -> [f64; 5] {
    let checks = |place: &str| format!("tslg_replay_checks_total{{place=\"{place}\"}}");
    [
        scraped(url, &checks("writer")).await,
        scraped(url, &checks("request")).await,
        scraped(url, &checks("pool")).await,
        scraped(url, "tslg_replay_sample_range_tests_total").await,
        scraped(url, "tslg_replay_sampled_tests_total").await,
    ]
}

/// The evasive liar of issue 47: it reports its ranges with every event
/// hidden and gives back every audit run it is handed (a lease of one
/// test). Before, giving back cost nothing and its hidden events were
/// caught only by the 1 % sample (escape about 0.99^k); now each run given
/// back makes it owe an audit of one of its unresolved tests (it gets
/// nothing until that is decided), doubles the share of its tests audited,
/// and past three in a row puts all its unresolved tests under audit: it
/// is flagged, and the answer is the honest one bit for bit.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_liar_that_gives_back_its_audits_is_caught_and_the_answer_is_the_honest_one() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &["--lease-size", "200"]);
    let client = server.client();
    let (id, builtin) = py_idm_campaign(&client).await;
    let offer = PY_IDM;
    let first = client
        .claim(&ask("dodger", &[offer]))
        .await
        .unwrap()
        .unwrap();
    let _honest = honest_workers(&server.url);
    // The dodger keeps its first range (heartbeats, no report): the
    // prefix waits at 0, so the campaign cannot end on what the honest
    // workers find before the dodger has had its chances to lie.
    let held = tslg_api::LeaseFence {
        worker: "dodger".into(),
        attempt: first.attempt,
        key: first.key.clone(),
    };
    let started = Instant::now();
    let mut given_back = 0;
    let refusal = loop {
        assert!(
            started.elapsed() < Duration::from_secs(180),
            "the dodger was never caught ({given_back} audit runs given back)"
        );
        match client.heartbeat(first.id, &held).await {
            Err(CallError::Refused {
                status: 403,
                detail,
            }) => break detail,
            other => assert!(other.is_ok(), "{other:?}"),
        }
        // An audit run first, if there is one (asked for alone: a range
        // of one test is no audit), given back; else a range, lied on.
        let audit_run = tslg_api::LeaseRequest {
            audits_only: true,
            ..ask("dodger", &[offer])
        };
        let (lease, is_audit) = match client.claim(&audit_run).await {
            Ok(Some(lease)) => (lease, true),
            // It lies on ranges only once it has given an audit run back:
            // caught lying before, it would have dodged nothing.
            Ok(None) if given_back == 0 => {
                tokio::time::sleep(Duration::from_millis(20)).await;
                continue;
            }
            Ok(None) => match client.claim(&ask("dodger", &[offer])).await {
                Ok(Some(lease)) => (lease, false),
                Ok(None) => {
                    tokio::time::sleep(Duration::from_millis(20)).await;
                    continue;
                }
                Err(CallError::Refused {
                    status: 403,
                    detail,
                }) => break detail,
                Err(e) => panic!("{e}"),
            },
            Err(CallError::Refused {
                status: 403,
                detail,
            }) => break detail,
            Err(e) => panic!("{e}"),
        };
        let outcome = if is_audit {
            let fence = tslg_api::LeaseFence {
                worker: "dodger".into(),
                attempt: lease.attempt,
                key: lease.key.clone(),
            };
            let released = client
                .release(lease.id, &fence.release(Some("not now".into())))
                .await;
            given_back += u32::from(released.is_ok());
            released
        } else {
            client
                .report(lease.id, &whole(&lease, "dodger", Vec::new()))
                .await
                .map(|_| ())
        };
        match outcome {
            Ok(()) => {}
            Err(CallError::Refused {
                status: 403,
                detail,
            }) => break detail,
            Err(CallError::Refused { status: 409, .. }) => {}
            Err(e) => panic!("{e}"),
        }
    };
    assert!(refusal.contains("worker `dodger` is flagged"), "{refusal}");
    assert!(
        given_back >= 1,
        "the dodger was handed audit runs to give back"
    );
    let workers = client.workers().await.unwrap().workers;
    let dodger = workers.iter().find(|w| w.name == "dodger").unwrap();
    assert!(dodger.audits_given_back >= 1, "{dodger:?}");
    let view = finished(&client, id, Duration::from_secs(240)).await;
    assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
    assert_same(&view, &in_process(Some("idm"), &builtin));
    eprintln!(
        "the dodger gave back {given_back} audit runs ({} counted) before it was flagged",
        dodger.audits_given_back
    );
}
