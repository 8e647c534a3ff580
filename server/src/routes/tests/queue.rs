//! `GET /api/v1/queue` and the gauge `tslg_workers_wanted`: nothing wanted
//! while idle, at least one for a campaign that nobody serves, the work
//! sized once it is predicted, and nothing again once it stops.

use super::*;

async fn queue(app: &App) -> Value {
    let (status, queue) = app.call("GET", "/api/v1/queue", None).await;
    assert_eq!(status, StatusCode::OK, "{queue}");
    queue
}

fn program<'a>(queue: &'a Value, name: &str) -> &'a Value {
    queue["programs"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["program"] == name)
        .unwrap_or_else(|| panic!("no {name} in {queue}"))
}

/// The gauge's value for `program`, from `/metrics`.
async fn gauge(app: &App, program: &str) -> Option<i64> {
    // The vehicle label is the program's NAME (a Kubernetes label value).
    let vehicle = program.split(':').next().unwrap();
    let name = format!("tslg_workers_wanted{{program=\"{program}\",vehicle=\"{vehicle}\"}} ");
    series(app, &name).await
}

/// The value of the series `name` (its labels included), from `/metrics`.
async fn series(app: &App, name: &str) -> Option<i64> {
    let body = crate::telemetry::metrics::exposition(&app.state)
        .await
        .unwrap();
    let text = String::from_utf8(body).unwrap();
    text.lines()
        .find_map(|l| l.strip_prefix(name))
        .map(|v| v.trim().parse().unwrap())
}

/// The gauge of the sum over programs.
async fn fleet_gauge(app: &App) -> Option<i64> {
    series(app, "tslg_fleet_workers_wanted ").await
}

#[tokio::test]
async fn the_queue_wants_nobody_when_idle_and_workers_for_the_work_that_waits() {
    let app = app(|c| c.queue_target_seconds = 60.0).await;
    let q = queue(&app).await;
    assert_eq!(q["workers_wanted"], 0, "{q}");
    assert_eq!(q["target_seconds"], 60.0);
    assert_eq!(q["programs"], json!([]));
    assert_eq!(fleet_gauge(&app).await, Some(0), "present, 0, when idle");

    // A program's campaign that no worker offers: one worker wanted.
    let (status, view) = app
        .call(
            "POST",
            "/api/v1/campaigns",
            Some(json!({"case": "cut-in", "method": "ndd", "beta": 0.05,
                        "vut": {"external": "rig", "mode": "episode"}})),
        )
        .await;
    assert_eq!(status, StatusCode::CREATED, "{view}");
    let q = queue(&app).await;
    let rig = program(&q, "rig:cut-in:episode");
    assert_eq!(
        (
            &rig["campaigns"],
            &rig["workers"],
            &rig["unpredicted"],
            &rig["workers_wanted"]
        ),
        (&json!(1), &json!(0), &json!(1), &json!(1)),
        "{q}"
    );
    assert_eq!(gauge(&app, "rig:cut-in:episode").await, Some(1));

    // A built-in vehicle's campaign, served by a worker of 2 threads that
    // reports its first lease: its cost is then known, and the rest of
    // its predicted tests are sized in workers.
    let (status, view) = app
        .call(
            "POST",
            "/api/v1/campaigns",
            Some(json!({"case": "cut-in", "method": "ndd", "beta": 0.02,
                        "vut": {"model": "fvdm"}})),
        )
        .await;
    assert_eq!(status, StatusCode::CREATED, "{view}");
    // Leases until the campaign is predicted (its first leases are one
    // test a thread, until a report measures the cost).
    let tests = app
        .state
        .samplers
        .cached(view["id"].as_i64().unwrap())
        .unwrap();
    for _ in 0..30 {
        let ask = json!({"worker": "w", "threads": 2, "max_tests": 5000});
        let (status, lease) = app.call("POST", "/api/v1/leases", Some(ask)).await;
        assert_eq!(status, StatusCode::OK, "{lease}");
        let (start, end) = (
            lease["start"].as_u64().unwrap(),
            lease["end"].as_u64().unwrap(),
        );
        let events: Vec<Value> = (start..end)
            .filter_map(|i| {
                let o = tests.run(i);
                o.event.then(|| json!({"index": i, "weight": o.weight}))
            })
            .collect();
        let mut report = quiet_report("w", &lease);
        report["events"] = json!(events);
        report["compute_seconds"] = json!(0.01);
        report["threads"] = json!(2);
        accepted(&app, &lease, report).await;
        if program(&queue(&app).await, "builtin")["unpredicted"] == 0 {
            break;
        }
    }
    let q = queue(&app).await;
    let builtin = program(&q, "builtin");
    assert_eq!(
        (&builtin["workers"], &builtin["threads"]),
        (&json!(1), &json!(2)),
        "{q}"
    );
    let needed = builtin["tests_needed"].as_f64().unwrap();
    let seconds = builtin["worker_seconds"].as_f64().unwrap();
    let cost = seconds / needed;
    assert!(needed > 0.0 && cost > 0.0, "{q}");
    // ⌈S / (T · threads per worker)⌉, at least 1.
    let expected = (seconds / (60.0 * 2.0)).ceil().max(1.0);
    assert_eq!(builtin["workers_wanted"].as_f64().unwrap(), expected, "{q}");
    assert_eq!(gauge(&app, "builtin").await, Some(expected as i64));
    // The worker offers no program: the rig still wants its one.
    assert_eq!(program(&q, "rig:cut-in:episode")["workers_wanted"], 1);
    assert_eq!(q["workers_wanted"].as_f64().unwrap(), expected + 1.0, "{q}");
    assert_eq!(fleet_gauge(&app).await, Some(expected as i64 + 1));

    // Both stopped: nothing is wanted, and the gauge says 0 for the
    // program the worker serves.
    for id in [view["id"].as_i64().unwrap(), 1] {
        let (status, _) = app
            .call("POST", &format!("/api/v1/campaigns/{id}/cancel"), None)
            .await;
        assert_eq!(status, StatusCode::OK);
    }
    let q = queue(&app).await;
    assert_eq!(q["workers_wanted"], 0, "{q}");
    assert_eq!(program(&q, "builtin")["workers_wanted"], 0, "{q}");
    assert_eq!(gauge(&app, "builtin").await, Some(0));
    assert_eq!(fleet_gauge(&app).await, Some(0));
}

#[tokio::test]
async fn a_worker_that_leaves_is_out_of_the_fleet_at_once_and_back_when_it_asks_again() {
    let app = app(|c| c.queue_target_seconds = 60.0).await;
    app.external_campaign().await;
    let ask =
        json!({"worker": "pod-7", "threads": 2, "offers": ["x:cut-in:step"], "max_tests": 10});
    let (status, lease) = app.call("POST", "/api/v1/leases", Some(ask.clone())).await;
    assert_eq!(status, StatusCode::OK, "{lease}");
    let x = |q: &Value| program(q, "x:cut-in:step")["workers"].clone();
    assert_eq!(x(&queue(&app).await), 1);
    // Without its secret, or with another's: refused, and still counted.
    let leave = axum::http::Request::builder()
        .method("POST")
        .uri("/api/v1/workers/pod-7/leave");
    let (status, problem) = app.send(leave, None).await;
    assert_eq!(status, StatusCode::FORBIDDEN, "{problem}");
    let other = app.secret("pod-8").await;
    let leave = axum::http::Request::builder()
        .method("POST")
        .uri("/api/v1/workers/pod-7/leave")
        .header(tslg_api::WORKER_SECRET_HEADER, other);
    let (status, _) = app.send(leave, None).await;
    assert_eq!(status, StatusCode::FORBIDDEN);
    assert_eq!(x(&queue(&app).await), 1);
    // With it: gone from the fleet, the queue and the live list at once.
    let leave = axum::http::Request::builder()
        .method("POST")
        .uri("/api/v1/workers/pod-7/leave")
        .header(tslg_api::WORKER_SECRET_HEADER, app.secret("pod-7").await);
    let (status, _) = app.send(leave, None).await;
    assert_eq!(status, StatusCode::NO_CONTENT);
    let q = queue(&app).await;
    assert_eq!(x(&q), 0, "{q}");
    assert_eq!(program(&q, "x:cut-in:step")["workers_wanted"], 1, "{q}");
    let (_, list) = app.call("GET", "/api/v1/workers", None).await;
    let pod = list["workers"]
        .as_array()
        .unwrap()
        .iter()
        .find(|w| w["name"] == "pod-7")
        .unwrap();
    assert_eq!(pod["live"], false, "{list}");
    // Asking for work again brings it back.
    let (status, _) = app.call("POST", "/api/v1/leases", Some(ask)).await;
    assert!(status.is_success());
    assert_eq!(x(&queue(&app).await), 1);
}

#[tokio::test]
async fn the_queue_of_one_program_is_its_entries_and_bad_names_are_refused() {
    let app = app(|c| c.queue_target_seconds = 60.0).await;
    app.external_campaign().await;
    let (status, x) = app.call("GET", "/api/v1/queue?program=x", None).await;
    assert_eq!(status, StatusCode::OK, "{x}");
    assert_eq!(x["programs"].as_array().unwrap().len(), 1, "{x}");
    assert_eq!(x["workers_wanted"], 1, "{x}");
    let (_, none) = app.call("GET", "/api/v1/queue?program=nobody", None).await;
    assert_eq!(none["workers_wanted"], 0, "{none}");
    assert_eq!(none["programs"], json!([]));
    for bad in [
        "/api/v1/queue?program=",
        "/api/v1/queue?program=%07",
        "/api/v1/queue?size=3",
    ] {
        let (status, problem) = app.call("GET", bad, None).await;
        assert_eq!(status, StatusCode::BAD_REQUEST, "{bad}: {problem}");
        assert!(problem["detail"].as_str().is_some(), "{problem}");
    }
}

/// `worker` says it is leaving, with its secret.
async fn leave(app: &App, worker: &str) -> StatusCode {
    let request = axum::http::Request::builder()
        .method("POST")
        .uri(format!("/api/v1/workers/{worker}/leave"))
        .header(tslg_api::WORKER_SECRET_HEADER, app.secret(worker).await);
    app.send(request, None).await.0
}

/// A worker stopped by its scheduler drops its held lease request and
/// leaves; the coordinator, which does not see that connection close,
/// must not hand work to it. A lease still its own at its leaving (granted
/// to a wait it had dropped) goes to another worker at once, not at its
/// 30 s TTL; and a request it held from before its leaving takes nothing
/// when work appears.
#[tokio::test]
async fn a_leaving_worker_s_lease_and_dropped_wait_go_to_the_others_at_once() {
    let app = app(|c| c.lease_size = Some(1_000_000)).await;
    let id = app.idm_ndd_campaign().await;
    let ask = |w: &str, wait: f64| json!({"worker": w, "threads": 1, "wait_seconds": wait});
    // pod-1 holds the whole campaign, and leaves without giving it back.
    let (status, held) = app
        .call("POST", "/api/v1/leases", Some(ask("pod-1", 0.0)))
        .await;
    assert_eq!(status, StatusCode::OK, "{held}");
    assert_eq!(
        (held["campaign_id"].as_i64(), held["start"].as_u64()),
        (Some(id), Some(0))
    );
    let (status, _) = app
        .call("POST", "/api/v1/leases", Some(ask("pod-2", 0.0)))
        .await;
    assert_eq!(status, StatusCode::NO_CONTENT, "nothing else to take");
    assert_eq!(leave(&app, "pod-1").await, StatusCode::NO_CONTENT);
    let (status, again) = app
        .call("POST", "/api/v1/leases", Some(ask("pod-2", 0.0)))
        .await;
    assert_eq!(status, StatusCode::OK, "handed out at once: {again}");
    assert_eq!(again["resume_at"], held["resume_at"], "{again}");
    // pod-3 waits; it leaves, then pod-2 gives its lease back (which wakes
    // one waiting request): pod-3's request ends empty at its deadline.
    let waited = app.call("POST", "/api/v1/leases", Some(ask("pod-3", 2.0)));
    let meanwhile = async {
        for _ in 0..1000 {
            if app.state.work.waiting() == 1 {
                break;
            }
            tokio::time::sleep(std::time::Duration::from_millis(5)).await;
        }
        assert_eq!(app.state.work.waiting(), 1, "pod-3's request is held");
        assert_eq!(leave(&app, "pod-3").await, StatusCode::NO_CONTENT);
        let release = json!({"worker": "pod-2", "attempt": again["attempt"], "key": again["key"],
                             "reason": "stopping"});
        let path = format!("/api/v1/leases/{}/release", again["id"]);
        let (status, _) = app.call("POST", &path, Some(release)).await;
        assert_eq!(status, StatusCode::NO_CONTENT);
    };
    let ((status, body), ()) = tokio::join!(waited, meanwhile);
    assert_eq!(status, StatusCode::NO_CONTENT, "a dropped wait took {body}");
    let (status, last) = app
        .call("POST", "/api/v1/leases", Some(ask("pod-4", 0.0)))
        .await;
    assert_eq!(status, StatusCode::OK, "{last}");
    assert_eq!(last["resume_at"], held["resume_at"], "{last}");
}
