//! What people watching a campaign see: `/metrics` (parsed by the official
//! Prometheus client's parser), the downsampled history, the SVG figures of
//! the dashboard and of `tslg campaign report`, library pictures and pages.

use crate::support::*;
use roxmltree::Document;
use serde_json::Value;
use std::io::Write;
use std::process::{Command, Stdio};
use std::time::Duration;
use tslg_api::{CampaignStatus, Method};

async fn get(url: &str) -> reqwest::Response {
    reqwest::get(url).await.expect("GET")
}

/// The exposition parsed by `prometheus_client.parser` (Python).
fn parse_metrics(text: &str) -> Vec<Value> {
    let mut parser = Command::new("python3")
        .arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/fixtures/parse_metrics.py"
        ))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python3");
    parser
        .stdin
        .take()
        .unwrap()
        .write_all(text.as_bytes())
        .unwrap();
    let out = parser.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "the parser rejects /metrics (needs `pip install prometheus-client`): {}\n{text}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// The value of the sample `name` with `labels` (a subset), if present.
fn sample(families: &[Value], name: &str, labels: &[(&str, &str)]) -> Option<f64> {
    families
        .iter()
        .flat_map(|f| f["samples"].as_array().unwrap())
        .find(|s| {
            s["name"] == name
                && labels
                    .iter()
                    .all(|(k, v)| s["labels"][*k].as_str() == Some(*v))
        })
        .map(|s| s["value"].as_f64().unwrap())
}

fn family<'a>(families: &'a [Value], name: &str) -> &'a Value {
    families
        .iter()
        .find(|f| f["name"] == name)
        .unwrap_or_else(|| panic!("no family {name}"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn metrics_parse_as_prometheus_exposition_and_agree_with_the_api() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let _workers = two_workers(&server.url);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let mut views = Vec::new();
    for method in [Method::Library, Method::Ndd] {
        let started = client
            .create_campaign(&campaign(method, library.id, "fvdm", 0.2, 3))
            .await
            .unwrap();
        views.push(finished(&client, started.id, Duration::from_secs(120)).await);
    }
    // One more, cancelled while pending or running. No campaign this test
    // cancels may stop on its own first: at β = 0.001 an NDD baseline needs
    // far more than the default budget of 10⁷ tests, and two workers can
    // use that up before the test looks (CI once found the campaign
    // exhausted at its cancel), so the budget is the largest allowed.
    let endless = |seed| {
        let mut request = campaign(Method::Ndd, library.id, "idm", 0.001, seed);
        request.max_tests = tslg_method::estimator::MAX_TESTS_LIMIT;
        request
    };
    let cancelled = client.create_campaign(&endless(4)).await.unwrap();
    client.cancel_campaign(cancelled.id).await.unwrap();
    let cancelled = client.campaign(cancelled.id).await.unwrap();
    let url = format!("{}/metrics", server.url);
    let response = get(&url).await;
    assert_eq!(response.status(), 200);
    let content_type = response.headers()["content-type"]
        .to_str()
        .unwrap()
        .to_owned();
    let text = response.text().await.unwrap();
    assert_eq!(content_type, "text/plain; version=0.0.4");
    let families = parse_metrics(&text);
    let converged = views
        .iter()
        .filter(|v| v.status == CampaignStatus::Converged)
        .count();
    assert_eq!(converged, 2);
    assert_eq!(
        sample(&families, "tslg_campaigns", &[("status", "converged")]),
        Some(2.0)
    );
    assert_eq!(
        sample(&families, "tslg_campaigns", &[("status", "cancelled")]),
        Some(1.0)
    );
    assert_eq!(
        sample(&families, "tslg_campaigns", &[("status", "running")]),
        Some(0.0)
    );
    assert_eq!(family(&families, "tslg_campaigns")["type"], "gauge");
    // Totals over campaigns are counters (the parser strips `_total`).
    let all = views.iter().chain([&cancelled]);
    let indices: u64 = all.clone().map(|v| v.indices).sum();
    let events: u64 = all.map(|v| v.events).sum();
    assert_eq!(family(&families, "tslg_tests_resolved")["type"], "counter");
    assert_eq!(
        sample(&families, "tslg_tests_resolved_total", &[]),
        Some(indices as f64)
    );
    assert_eq!(
        sample(&families, "tslg_events_total", &[]),
        Some(events as f64)
    );
    assert_eq!(
        sample(&families, "tslg_invalid_tests_total", &[]),
        Some(0.0)
    );
    assert_eq!(
        sample(&families, "tslg_libraries", &[("status", "ready")]),
        Some(1.0)
    );
    assert!(sample(&families, "tslg_leases_outstanding", &[]).is_some());
    assert!(sample(&families, "tslg_leases_expired", &[]).is_some());
    assert_eq!(
        sample(&families, "tslg_workers", &[("state", "live")]),
        Some(2.0)
    );
    // Request latency: a histogram by route template, not by id.
    let latency = family(&families, "tslg_http_request_duration_seconds");
    assert_eq!(latency["type"], "histogram");
    let leases = sample(
        &families,
        "tslg_http_request_duration_seconds_count",
        &[
            ("route", "/api/v1/leases"),
            ("method", "POST"),
            ("status", "200"),
        ],
    )
    .expect("lease requests observed");
    assert!(leases >= 2.0);
    assert!(sample(
        &families,
        "tslg_http_request_duration_seconds_count",
        &[("route", "/api/v1/campaigns/{id}"), ("method", "GET")],
    )
    .is_some());
    let ids = latency["samples"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|s| {
            s["labels"]["route"]
                .as_str()
                .unwrap()
                .contains(&cancelled.id.to_string())
        })
        .count();
    assert_eq!(ids, 0, "ids do not become labels");
    // A running campaign has series of its own, labelled by its id, case
    // and method; the stopped ones have none (bounded cardinality).
    assert!(!text.contains("tslg_campaign_tests{"), "{text}");
    let running = client.create_campaign(&endless(5)).await.unwrap();
    let labels = [
        ("campaign", running.id.to_string()),
        ("case", "cut-in".to_owned()),
        ("method", "ndd".to_owned()),
    ];
    let labels: Vec<(&str, &str)> = labels.iter().map(|(k, v)| (*k, v.as_str())).collect();
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    let (before, families, after) = loop {
        let before = client.campaign(running.id).await.unwrap();
        let families = parse_metrics(&get(&url).await.text().await.unwrap());
        let after = client.campaign(running.id).await.unwrap();
        if before.events > 0 || std::time::Instant::now() > deadline {
            break (before, families, after);
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    };
    assert!(before.events > 0, "the campaign ran");
    let tests = sample(&families, "tslg_campaign_tests", &labels).expect("its tests");
    assert!((before.tests as f64..=after.tests as f64).contains(&tests));
    let events = sample(&families, "tslg_campaign_events", &labels).expect("its events");
    assert!((before.events as f64..=after.events as f64).contains(&events));
    assert_eq!(
        sample(&families, "tslg_campaign_beta", &labels),
        Some(0.001)
    );
    let estimate = sample(&families, "tslg_campaign_estimate", &labels).expect("its estimate");
    // An NDD estimate is events / tests (every weight 1), both taken between
    // the two reads.
    let low = before.events as f64 / after.tests as f64;
    let high = after.events as f64 / before.tests as f64;
    assert!(
        (low * (1.0 - 1e-12)..=high * (1.0 + 1e-12)).contains(&estimate),
        "{estimate} between {low} and {high}"
    );
    assert!(sample(&families, "tslg_campaign_relative_half_width", &labels).unwrap() > 0.001);
    assert_eq!(
        sample(&families, "tslg_campaign_series_omitted", &[]),
        Some(0.0)
    );
    client.cancel_campaign(running.id).await.unwrap();
    let text = get(&url).await.text().await.unwrap();
    assert!(!text.contains("tslg_campaign_tests{"), "gone when it stops");
    // Deleting a stopped campaign does not take back what the counters
    // counted (a falling counter reads as a reset).
    let totals = |text: &str| {
        let families = parse_metrics(text);
        ["tslg_tests_resolved_total", "tslg_events_total"]
            .map(|name| sample(&families, name, &[]).unwrap())
    };
    let counted = totals(&text);
    let gone = client.campaign(running.id).await.unwrap();
    assert!(gone.indices > 0);
    client.delete_campaign(running.id).await.unwrap();
    let text = get(&url).await.text().await.unwrap();
    assert_eq!(totals(&text), counted);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn history_is_log_downsampled_and_each_point_is_the_estimate_of_its_prefix() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &["--lease-size", "5000"]);
    let _workers = two_workers(&server.url);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let request = campaign(Method::Ndd, library.id, "idm", 0.15, 5);
    let started = client.create_campaign(&request).await.unwrap();
    let view = finished(&client, started.id, Duration::from_secs(120)).await;
    assert_eq!(view.status, CampaignStatus::Converged);
    // Every stored point (fewer than the 5000 a read may return).
    let url = format!("{}/api/v1/campaigns/{}/history", server.url, view.id);
    let full: tslg_api::History = get(&format!("{url}?points=5000"))
        .await
        .json()
        .await
        .unwrap();
    let full = full.points;
    assert!(full.len() < 5000, "{}", full.len());
    // Reports of 5000 tests still give points inside them (at events).
    assert!(
        full.len() > 2 * view.indices as usize / 5000,
        "{}",
        full.len()
    );
    let few: tslg_api::History = get(&format!("{url}?points=20")).await.json().await.unwrap();
    let bad = get(&format!("{url}?points=1")).await;
    let unknown = get(&format!("{url}?size=3")).await;
    // The first stored point at or after each of 20 log-spaced targets
    // between the first and the last (fewer where the stored points are
    // coarser than the targets), the last included.
    let (first, last) = (full[0].indices.max(1) as f64, view.indices as f64);
    let mut expected: Vec<u64> = (0..20)
        .filter_map(|k| {
            let target = first * (last / first).powf(k as f64 / 19.0);
            full.iter()
                .map(|p| p.indices)
                .find(|&i| i as f64 >= target * (1.0 - 1e-12))
        })
        .collect();
    expected.push(view.indices);
    expected.dedup();
    let chosen: Vec<u64> = few.points.iter().map(|p| p.indices).collect();
    assert!(few.points.len() <= 20, "{}", few.points.len());
    assert_eq!(chosen, expected);
    assert_eq!(few.points.first(), full.first());
    assert_eq!(few.points.last().unwrap().indices, view.indices);
    assert!(few.points.windows(2).all(|w| w[0].indices < w[1].indices));
    // A selection of the stored points (the spacing is tested in the
    // server's unit tests: stored points are sparse where nothing happened).
    assert!(few.points.iter().all(|p| full.contains(p)));
    for (response, words) in [
        (bad, "points = 1 must be in 2..=5000"),
        (unknown, "unknown field `size`"),
    ] {
        assert_eq!(response.status(), 400);
        let problem: Value = response.json().await.unwrap();
        assert!(
            problem["detail"].as_str().unwrap().contains(words),
            "{problem}"
        );
    }
    // Each point is the estimate of its prefix: the same campaign run in
    // this process with the budget ending there gives the same numbers.
    for point in [&full[1], &full[full.len() / 2], &full[full.len() - 2]] {
        let mut prefix = request.clone();
        prefix.max_tests = point.indices;
        let reference = in_process(None, &prefix);
        assert_eq!(reference.indices, point.indices);
        assert_eq!(reference.estimate, point.estimate, "at {}", point.indices);
        assert_eq!(reference.ci_high, point.ci_high);
    }
}

/// The point lists of the polylines stroked in the estimate colour.
fn series(doc: &Document) -> Vec<usize> {
    doc.descendants()
        .filter(|n| n.has_tag_name("polyline") && n.attribute("stroke") == Some("#1F5DA6"))
        .map(|n| n.attribute("points").unwrap().split_whitespace().count())
        .collect()
}

fn texts(doc: &Document) -> Vec<String> {
    doc.descendants()
        .filter_map(|n| n.has_tag_name("text").then(|| n.text()).flatten())
        .map(|t| t.trim().to_owned())
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_report_writes_the_dashboard_figures_as_svg_with_the_numbers_as_csv() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let _workers = two_workers(&server.url);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let started = client
        .create_campaign(&campaign(Method::Ndd, library.id, "fvdm", 0.2, 9))
        .await
        .unwrap();
    let view = finished(&client, started.id, Duration::from_secs(120)).await;
    let history = client.history(view.id).await.unwrap();
    let out = dir.path().join("report");
    let o = Command::new(env!("CARGO_BIN_EXE_tslg"))
        .args([
            "campaign",
            "report",
            &view.id.to_string(),
            "--server",
            &server.url,
        ])
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let plotted = history.points.iter().filter(|p| p.tests > 0).count();
    let with_r = history
        .points
        .iter()
        .filter(|p| p.relative_half_width.is_some())
        .count();
    let estimate = std::fs::read_to_string(out.join("estimate.svg")).unwrap();
    let doc = Document::parse(&estimate).expect("estimate.svg is XML");
    assert_eq!(doc.root_element().tag_name().name(), "svg");
    assert!(
        series(&doc).contains(&plotted),
        "{:?} vs {plotted}",
        series(&doc)
    );
    let words = texts(&doc);
    // A built-in vehicle on cut-in: the coordinator enumerated the grid at
    // the start and the figure draws that exact P(A).
    assert_eq!(view.exact_probability, Some(exact("fvdm")));
    let exact_label = format!("exact P(A) = {:.2e}", exact("fvdm"));
    for label in ["estimate", "90% interval", "tests", &exact_label] {
        assert!(words.iter().any(|t| t == label), "{label} in {words:?}");
    }
    let half_width = std::fs::read_to_string(out.join("relative-half-width.svg")).unwrap();
    let doc = Document::parse(&half_width).expect("relative-half-width.svg is XML");
    assert!(
        series(&doc).contains(&with_r),
        "{:?} vs {with_r}",
        series(&doc)
    );
    assert!(texts(&doc).iter().any(|t| t == "β = 0.2"));
    // The dashboard serves the very same figure.
    let url = format!(
        "{}/api/v1/campaigns/{}/figures/estimate.svg",
        server.url, view.id
    );
    let served = get(&url).await.text().await.unwrap();
    assert_eq!(served, estimate);
    // The summary for a reader: the verdict first (an NDD campaign that
    // converged reports its plain interval), the numbers as the view gives
    // them, and the figures beside it.
    let answer = view.answer.as_ref().unwrap();
    assert!(
        view.verdict.starts_with(&format!(
            "report P(A) in [{:.3e}, {:.3e}] at 90% confidence: its interval",
            answer.low, answer.high
        )),
        "{}",
        view.verdict
    );
    let summary = std::fs::read_to_string(out.join("summary.md")).unwrap();
    for line in [
        format!("# Campaign {}: fvdm on cut-in (ndd)", view.id),
        format!("**Verdict:** {}", view.verdict),
        format!(
            "| tests | {} tests used ({} valid, {} events, 0 invalid) |",
            view.indices, view.tests, view.events
        ),
        format!("| events | {} |", view.events),
        format!("| estimate | {:.4e} |", view.estimate.unwrap()),
        format!(
            "| exact P(A), by enumeration | {:.4e} (inside the answer) |",
            exact("fvdm")
        ),
        "![estimate.svg](estimate.svg)".to_owned(),
        "![relative-half-width.svg](relative-half-width.svg)".to_owned(),
    ] {
        assert!(summary.lines().any(|l| l == line), "{line} in\n{summary}");
    }
    // `tslg campaign status` says the verdict after its state.
    let status = Command::new(env!("CARGO_BIN_EXE_tslg"))
        .args([
            "campaign",
            "status",
            &view.id.to_string(),
            "--server",
            &server.url,
        ])
        .output()
        .unwrap();
    let status = String::from_utf8_lossy(&status.stdout);
    assert_eq!(
        status.lines().nth(1),
        Some(format!("  verdict: {}", view.verdict).as_str()),
        "{status}"
    );
    // The numbers: one row per history point, the last the final estimate.
    let csv = std::fs::read_to_string(out.join("history.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().collect();
    assert_eq!(rows.len(), history.points.len() + 1);
    let last: Vec<&str> = rows.last().unwrap().split(',').collect();
    assert_eq!(last[1].parse::<u64>().unwrap(), view.indices);
    assert_eq!(last[3].parse::<f64>().unwrap(), view.estimate.unwrap());
    let saved: tslg_api::CampaignView =
        serde_json::from_str(&std::fs::read_to_string(out.join("campaign.json")).unwrap()).unwrap();
    assert_eq!(saved.estimate, view.estimate);
    // `tslg campaign watch` of a stopped campaign: its final line on stderr
    // (no terminal: no bar), its state on stdout.
    let o = Command::new(env!("CARGO_BIN_EXE_tslg"))
        .args([
            "campaign",
            "watch",
            &view.id.to_string(),
            "--json",
            "--server",
            &server.url,
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let watched: tslg_api::CampaignView = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        (watched.indices, watched.estimate),
        (view.indices, view.estimate)
    );
    let line = String::from_utf8_lossy(&o.stderr);
    assert!(
        line.contains("converged") && line.contains(&format!("{} tests", view.tests)),
        "{line}"
    );
    assert!(
        !out.join("stages.svg").exists(),
        "an NDD campaign has no stages"
    );
    // An adaptive campaign's report adds its stages and support, the
    // figures its page serves, and the stages' numbers.
    let adaptive = client
        .create_campaign(&campaign(Method::Adaptive, library.id, "fvdm", 0.2, 2))
        .await
        .unwrap();
    let adaptive = finished(&client, adaptive.id, Duration::from_secs(120)).await;
    let out = dir.path().join("adaptive-report");
    let o = Command::new(env!("CARGO_BIN_EXE_tslg"))
        .args(["campaign", "report", &adaptive.id.to_string()])
        .args(["--server", &server.url])
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for figure in ["stages.svg", "support.svg", "estimate.svg"] {
        let written = std::fs::read_to_string(out.join(figure)).unwrap();
        let url = format!(
            "{}/api/v1/campaigns/{}/figures/{figure}",
            server.url, adaptive.id
        );
        assert_eq!(written, get(&url).await.text().await.unwrap(), "{figure}");
    }
    let stages: tslg_api::AdaptiveStages =
        serde_json::from_str(&std::fs::read_to_string(out.join("stages.json")).unwrap()).unwrap();
    assert_eq!(stages, client.stages(adaptive.id).await.unwrap());
    assert_eq!(
        stages.stages.len() as u64,
        adaptive.adaptive.as_ref().unwrap().stages
    );
    // A campaign that does not exist: a message and a non-zero exit.
    let o = Command::new(env!("CARGO_BIN_EXE_tslg"))
        .args([
            "campaign",
            "report",
            "999",
            "--server",
            &server.url,
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(clean_refusal(&o));
    assert!(String::from_utf8_lossy(&o.stderr).contains("campaign 999 does not exist"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn library_pictures_and_pages_are_served_and_unknown_ids_are_404() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let base = server.url.clone();
    let id = library.id;
    let response = get(&format!("{base}/api/v1/libraries/{id}/figures/picture.svg")).await;
    assert_eq!(response.headers()["content-type"], "image/svg+xml");
    let svg = response.text().await.unwrap();
    let doc = Document::parse(&svg).expect("XML");
    // Exposure: every cell with P(x) > 0; library: its 286 cells.
    let cells = doc
        .descendants()
        .filter(|n| n.has_tag_name("rect") && n.attribute("fill") != Some("#FFFFFF"))
        .count();
    let exposed = 45 * 76; // the built-in exposure is positive everywhere
    assert_eq!(
        cells,
        exposed + 286 + 2 * tslg_figures::COLOUR_STEPS,
        "{cells}: the cells and a colour bar per map"
    );
    let words = texts(&doc);
    // The axes with their units.
    for axis in ["range R (m)", "range rate Ṙ (m/s)"] {
        assert!(words.iter().any(|t| t == axis), "{axis} in {words:?}");
    }
    assert!(
        words.iter().any(|t| t.starts_with("exposure P(x)")),
        "{words:?}"
    );
    assert!(
        words.iter().any(|t| t.starts_with("library q(x)")),
        "{words:?}"
    );
    for page in ["/".to_owned(), format!("/libraries/{id}")] {
        let response = get(&format!("{base}{page}")).await;
        assert_eq!(response.status(), 200, "{page}");
        let html = response.text().await.unwrap();
        assert!(
            html.contains("<script src=\"/assets/dashboard.js\">"),
            "{page}"
        );
        // Without JavaScript the page says so and where the API has the
        // same, and claims no empty list it has not read.
        assert!(
            html.contains("<noscript><p class=\"noscript\">This dashboard needs JavaScript"),
            "{page}"
        );
        assert!(!html.contains("no campaigns yet"), "{page}");
        assert!(!html.contains("no libraries yet"), "{page}");
    }
    let script = get(&format!("{base}/assets/dashboard.js")).await;
    assert_eq!(
        script.headers()["content-type"],
        "text/javascript; charset=utf-8"
    );
    for missing in [
        "/campaigns/1".to_owned(),
        format!("/libraries/{}", id + 1),
        format!("/api/v1/libraries/{}/figures/picture.svg", id + 1),
        "/api/v1/campaigns/5/figures/estimate.svg".to_owned(),
        "/api/v1/campaigns/5/figures/stages.svg".to_owned(),
        "/api/v1/campaigns/5/figures/support.svg".to_owned(),
        "/api/v1/campaigns/5/stages".to_owned(),
    ] {
        let response = get(&format!("{base}{missing}")).await;
        assert_eq!(response.status(), 404, "{missing}");
        assert_eq!(
            response.headers()["content-type"],
            "application/problem+json"
        );
        let problem: Value = response.json().await.unwrap();
        assert!(problem["detail"]
            .as_str()
            .unwrap()
            .contains("does not exist"));
    }
}
