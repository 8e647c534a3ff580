//! The dashboard in a real browser: headless Chromium (Debian's `chromium`
//! and `chromium-driver`, which `.ci/run` installs) loads the pages while a
//! campaign runs; the numbers on the page change as results arrive and
//! agree with the API, the figures are drawn and redrawn, and screenshots
//! are written to `target/tmp/artefacts/`.

use crate::browser_kinds::page_agrees;
use crate::browser_support::{eval, number, save, until, Driver};
use crate::support::*;
use serde_json::json;
use std::time::Duration;
use tslg_api::{CampaignStatus, CreateCampaign, Method};

/// Whether every row of figures on the page spans at least 90% of the
/// figures' section (they grow to the page's width, side by side or one per
/// row) and every drawing fills its figure's width.
const FIGURES_FILL_THE_PAGE: &str = "(() => {
    const shown = (n) => n.checkVisibility();
    const section = [...document.querySelectorAll('.figures')].find(shown).getBoundingClientRect().width;
    const rows = {};
    for (const f of [...document.querySelectorAll('.figures > .figure')].filter(shown)) {
        const r = f.getBoundingClientRect();
        rows[Math.round(r.top)] = (rows[Math.round(r.top)] ?? 0) + r.width;
        const svg = f.querySelector('svg').getBoundingClientRect().width;
        if (svg < 0.98 * r.width - 2) return false;
    }
    return Object.values(rows).every((w) => w >= 0.9 * section);
})()";

/// Points of the longest estimate-coloured line in the figure `figure`.
fn line_points(figure: &str) -> String {
    format!(
        "Math.max(0, ...[...document.querySelectorAll('#{figure} svg polyline[stroke=\"#1F5DA6\"]')]\
         .map(p => p.getAttribute('points').trim().split(/\\s+/).length))"
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_dashboard_follows_a_running_campaign_and_agrees_with_the_api() {
    let dir = scratch();
    // Library builds run on workers: the build's surrogate runs are a
    // campaign of their own, whose page is checked too.
    let server = ServerProcess::start(
        &dir.path().join("db.sqlite"),
        &["--lease-size", "3000", "--library-builds", "workers"],
    );
    let _worker = WorkerProcess::start(&server.url, 1, "w1");
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    // The NDD baseline to β = 0.001 needs about 5 × 10⁸ tests (z²/(β²P(A)),
    // P(A) = 5.4 × 10⁻³): it runs for as long as the test looks at it, and
    // is cancelled at the end. (At β = 0.005 it needed 2 × 10⁷, a few
    // seconds of a fast worker, about what the browser's looks take; the
    // default budget of 10⁷ tests would end it sooner still.)
    let mut request = campaign(Method::Ndd, library.id, "fvdm", 0.001, 1);
    request.max_tests = tslg_method::estimator::MAX_TESTS_LIMIT;
    let id = client.create_campaign(&request).await.unwrap().id;
    let ndd = id;
    let driver = Driver::start();
    let browser = driver.connect().await;

    // The list: the campaign's row, its numbers caught up with the API.
    browser
        .goto(&format!("{}/?refresh=300", server.url))
        .await
        .unwrap();
    let tests =
        format!("document.querySelector('#campaign-{id} [data-field=tests]')?.dataset.value");
    let before = wait_for(&client, id, Duration::from_secs(60), |v| v.tests > 0).await;
    let shown = number(
        &until(
            &browser,
            &format!("Number({tests}) >= {} && {tests}", before.tests),
            "the list catches up",
        )
        .await,
    );
    let after = client.campaign(id).await.unwrap();
    assert!(
        before.tests <= shown && shown <= after.tests,
        "{} ≤ {shown} ≤ {}",
        before.tests,
        after.tests
    );
    // … and it changes as results arrive.
    until(
        &browser,
        &format!("Number({tests}) > {shown}"),
        "the list's tests grow",
    )
    .await;
    let worker_tests = "document.querySelector('#worker-w1 [data-field=tests]')?.dataset.value";
    assert!(number(&until(&browser, worker_tests, "the worker is listed").await) > 0);
    save("dashboard.png", &browser.screenshot().await.unwrap());

    // The campaign page: both figures drawn, then redrawn with more points.
    browser
        .goto(&format!("{}/campaigns/{id}?refresh=300", server.url))
        .await
        .unwrap();
    let estimate = line_points("estimate-figure");
    until(
        &browser,
        &format!("{estimate} >= 2"),
        "the estimate is drawn",
    )
    .await;
    until(
        &browser,
        &format!("{} >= 2", line_points("half-width-figure")),
        "the half-width is drawn",
    )
    .await;
    // On a wide screen and a narrow one (720 px drawings left 45% of a
    // 1920 px page empty, and overflowed a phone's).
    for width in [2400, 640, 1560] {
        browser.set_window_size(width, 900).await.unwrap();
        assert_eq!(
            eval(&browser, FIGURES_FILL_THE_PAGE).await,
            json!(true),
            "at {width} px each row of figures spans the page and each drawing its figure"
        );
    }
    let legend = eval(&browser, "[...document.querySelectorAll('#half-width-figure svg text')].some(t => t.textContent.trim() === 'β = 0.001')").await;
    assert_eq!(legend, json!(true));
    // Redrawn as results arrive: its title counts the tests (the number of
    // points is capped, so it does not tell).
    let title = "document.querySelector('#estimate-figure svg text')?.textContent.trim()";
    let first = until(&browser, title, "the estimate has a title").await;
    let running = format!("Campaign {id}, fvdm: estimate of P(A), running");
    assert!(first.as_str().unwrap().starts_with(&running), "{first}");
    until(
        &browser,
        &format!("{title} !== {first}"),
        "the estimate figure is redrawn",
    )
    .await;
    let before = client.campaign(id).await.unwrap();
    let page_tests = "document.getElementById('tests').dataset.value";
    let shown = number(
        &until(
            &browser,
            &format!("Number({page_tests}) >= {} && {page_tests}", before.tests),
            "the page catches up",
        )
        .await,
    );
    let after = client.campaign(id).await.unwrap();
    assert!(before.tests <= shown && shown <= after.tests);
    // A rate once reports a second apart are in.
    let rate = "Number(document.getElementById('rate').dataset.value) > 0";
    until(&browser, rate, "a rate of tests per second").await;
    save("campaign.png", &browser.screenshot().await.unwrap());

    // Stopped: the page shows exactly the API's final numbers and stops polling.
    let cancelled = client.cancel_campaign(id).await.unwrap();
    assert_eq!(cancelled.status, CampaignStatus::Cancelled);
    until(
        &browser,
        "document.getElementById('status').textContent === 'cancelled'",
        "the page shows the stop",
    )
    .await;
    let last = client.campaign(id).await.unwrap();
    let shown = |field: &'static str| {
        let browser = &browser;
        async move {
            eval(
                browser,
                &format!("document.getElementById('{field}').dataset.value"),
            )
            .await
        }
    };
    assert_eq!(number(&shown("tests").await), last.tests);
    assert_eq!(number(&shown("events").await), last.events);
    let estimate: f64 = shown("estimate").await.as_str().unwrap().parse().unwrap();
    assert_eq!(estimate, last.estimate.unwrap());
    assert_eq!(
        shown("outside-upper").await,
        json!(""),
        "an NDD campaign has no outside"
    );
    // Which interval the page shows: this campaign's holds at its stop.
    let kind = "document.getElementById('interval-kind').textContent";
    assert_eq!(eval(&browser, kind).await, json!("interval (Wald)"));
    page_agrees(&browser, &server.url, &last, "ndd").await;
    // An anytime campaign's page says its interval holds at every n.
    let anytime = CreateCampaign {
        interval: tslg_api::IntervalKind::Anytime,
        ..campaign(Method::Ndd, library.id, "idm", 0.3, 5)
    };
    let anytime = client.create_campaign(&anytime).await.unwrap().id;
    let anytime_view = finished(&client, anytime, Duration::from_secs(120)).await;
    page_agrees(&browser, &server.url, &anytime_view, "anytime").await;
    let anytime = anytime_view.id;
    browser
        .goto(&format!("{}/campaigns/{anytime}?refresh=300", server.url))
        .await
        .unwrap();
    until(
        &browser,
        &format!("{kind} === 'anytime interval'"),
        "the anytime campaign's label",
    )
    .await;

    // A library campaign of a vehicle its surrogate does not cover: the
    // page shows the outside bound, the guarded interval and the warning.
    // 3,000 tests hold about 300 exploring ones, of which about 4% meet the
    // FVDM failing where the IDM passes: the mismatch the warning reports.
    let plain = CreateCampaign {
        n_min: Some(3000),
        ..campaign(Method::Library, library.id, "fvdm", 0.2, 3)
    };
    let id = client.create_campaign(&plain).await.unwrap().id;
    let view = finished(&client, id, Duration::from_secs(120)).await;
    browser
        .goto(&format!("{}/campaigns/{id}?refresh=300", server.url))
        .await
        .unwrap();
    until(
        &browser,
        "document.getElementById('status').textContent === 'converged'",
        "the library campaign's page",
    )
    .await;
    let upper: f64 = shown("outside-upper")
        .await
        .as_str()
        .unwrap()
        .parse()
        .unwrap();
    assert_eq!(upper, view.outside_upper.unwrap());
    let guarded: f64 = shown("guarded-interval")
        .await
        .as_str()
        .unwrap()
        .parse()
        .unwrap();
    assert_eq!(guarded, view.guarded_ci_high.unwrap());
    let warnings = eval(
        &browser,
        "[...document.querySelectorAll('#warnings li')].map(li => li.textContent)",
    )
    .await;
    // Every warning as the API words it, its `quoted` fields set as code.
    let unquoted: Vec<String> = view.warnings.iter().map(|w| w.replace('`', "")).collect();
    assert_eq!(
        warnings,
        json!(unquoted),
        "every warning, as the API words it"
    );
    let quoted = view.warnings.iter().filter(|w| w.contains('`')).count();
    let code = eval(
        &browser,
        "document.querySelectorAll('#warnings li code').length",
    )
    .await;
    assert!(code.as_u64().unwrap() as usize >= quoted, "{code}");
    assert!(!view.warnings.is_empty());
    let unpaired = eval(&browser, "document.getElementById('pair').hidden").await;
    assert_eq!(
        unpaired,
        json!(true),
        "a campaign without a pair shows none"
    );
    let library_page = page_agrees(&browser, &server.url, &view, "library").await;

    // The same library, guarded: the outside bound within β of the
    // estimate, by exposure (docs/statistics.md, "The guard").
    let guarded = CreateCampaign {
        guard_outside: Some(true),
        outside: Some(tslg_api::Outside::Ndd),
        ..campaign(Method::Library, library.id, "idm", 0.3, 4)
    };
    let guarded = client.create_campaign(&guarded).await.unwrap().id;
    let guarded = finished(&client, guarded, Duration::from_secs(180)).await;
    assert!(guarded.guarded_ci_high.is_some());
    page_agrees(&browser, &server.url, &guarded, "guarded").await;

    // An adaptive campaign: the header, its stages in numbers and the four
    // figures (its page showed none of them once).
    let adaptive = campaign(Method::Adaptive, library.id, "fvdm", 0.2, 0);
    let adaptive = client.create_campaign(&adaptive).await.unwrap().id;
    let adaptive = finished(&client, adaptive, Duration::from_secs(120)).await;
    let adaptive_page = page_agrees(&browser, &server.url, &adaptive, "adaptive").await;

    // The library build's surrogate runs: a header without an estimate.
    let build = client
        .campaigns()
        .await
        .unwrap()
        .campaigns
        .into_iter()
        .find(|c| c.method == Method::Enumerate)
        .expect("the build's campaign");
    page_agrees(&browser, &server.url, &build, "build").await;

    // The list counts an adaptive campaign's tests as the command line
    // does (all it used), and a build's line estimates nothing.
    browser
        .goto(&format!("{}/?refresh=300", server.url))
        .await
        .unwrap();
    let cell = |id: i64, field: &str| {
        format!("document.querySelector('#campaign-{id} [data-field={field}]')")
    };
    let adaptive_tests = until(
        &browser,
        &format!("{}?.dataset.value", cell(adaptive.id, "tests")),
        "the adaptive campaign's line",
    )
    .await;
    assert_eq!(number(&adaptive_tests), adaptive.indices);
    assert!(adaptive.indices > adaptive.tests, "{adaptive:?}");
    let build_line = eval(
        &browser,
        &format!(
            "[{m}.textContent, {e}.textContent, {e}.dataset.value]",
            m = cell(build.id, "method"),
            e = cell(build.id, "estimate")
        ),
    )
    .await;
    assert_eq!(
        build_line,
        json!([format!("building library {}", library.id), "–", ""]),
        "{build_line}"
    );

    // A paired regression campaign: the FVDM against the IDM on the IDM's
    // library. Its page shows both rates and the difference with the
    // paired interval, as the API gives them.
    let paired = CreateCampaign {
        paired_with: Some(json!("idm")),
        ..campaign(Method::Library, library.id, "fvdm", 0.2, 5)
    };
    let pair_id = client.create_campaign(&paired).await.unwrap().id;
    let pair = finished(&client, pair_id, Duration::from_secs(120))
        .await
        .pair
        .unwrap();
    browser
        .goto(&format!(
            "{}/campaigns/{}?refresh=300",
            server.url, pair.campaign_b
        ))
        .await
        .unwrap();
    until(
        &browser,
        "!document.getElementById('pair').hidden && document.querySelector('#pair-rates [data-row=\"b\"]')",
        "the pair section",
    )
    .await;
    let cell = |row: &str, field: &str| {
        format!("document.querySelector('#pair-rates [data-row=\"{row}\"] [data-field={field}]').dataset.value")
    };
    for (row, rate) in [
        ("a", pair.rate_a),
        ("b", pair.rate_b),
        ("a − b", pair.difference),
    ] {
        let shown: f64 = eval(&browser, &cell(row, "estimate"))
            .await
            .as_str()
            .unwrap()
            .parse()
            .unwrap();
        assert_eq!(shown, rate.unwrap().estimate, "row {row}");
    }
    let events = eval(&browser, &cell("a", "events")).await;
    assert_eq!(number(&events), pair.events_a);
    let link = eval(
        &browser,
        "document.querySelector('#pair-rates [data-row=\"a\"] a').getAttribute('href')",
    )
    .await;
    assert_eq!(link, json!(format!("/campaigns/{}", pair.campaign_a)));
    // Both vehicles by name, and the other vehicle's estimate drawn beside
    // this one's (campaign a's, on campaign b's page).
    let vehicles = eval(
        &browser,
        "[...document.querySelectorAll('#pair-rates [data-field=vehicle]')].map((c) => c.textContent)",
    )
    .await;
    assert_eq!(vehicles, json!(["fvdm", "idm", ""]), "{vehicles}");
    let other = until(
        &browser,
        "document.querySelector('#pair-figure svg text')?.textContent.trim()",
        "the other vehicle's estimate",
    )
    .await;
    assert!(
        other
            .as_str()
            .is_some_and(|t| t.contains(&format!("Campaign {}", pair.campaign_a))),
        "{other}"
    );
    let b = client.campaign(pair.campaign_b).await.unwrap();
    page_agrees(&browser, &server.url, &b, "paired").await;

    // The overview marks the campaign with its warnings (their number, the
    // texts on hover); the NDD campaign, which has none, is not marked.
    browser
        .goto(&format!("{}/?refresh=300", server.url))
        .await
        .unwrap();
    let mark = format!("document.querySelector('#campaign-{id} [data-field=warnings]')");
    let count = until(&browser, &format!("{mark}?.dataset.value"), "the mark").await;
    assert_eq!(number(&count), view.warnings.len() as u64);
    let title = eval(&browser, &format!("{mark}.title")).await;
    assert_eq!(title, json!(view.warnings.join("\n\n")));
    // … and lists them in words above the campaigns, each naming its campaign.
    let listed = eval(
        &browser,
        &format!("[...document.querySelectorAll('#warnings li[data-campaign=\"{id}\"]')].map(li => li.textContent)"),
    )
    .await;
    let worded: Vec<String> = view
        .warnings
        .iter()
        .map(|w| format!("campaign {id}: {}", w.replace('`', "")))
        .collect();
    assert_eq!(listed, json!(worded));
    let unmarked = eval(
        &browser,
        &format!("document.querySelector('#campaign-{ndd} [data-field=warnings]') === null"),
    )
    .await;
    assert_eq!(unmarked, json!(true));

    // The library's picture, looked at as the browser draws it: no label
    // meets a coloured cell or a step of a colour bar (the bars' middle
    // labels ran into them), and a screenshot is kept.
    browser
        .goto(&format!(
            "{}/libraries/{}?refresh=300",
            server.url, library.id
        ))
        .await
        .unwrap();
    until(
        &browser,
        "document.querySelectorAll('#picture svg rect').length > 100",
        "the library's picture",
    )
    .await;
    let overlapping = eval(&browser, LABELS_ON_COLOUR).await;
    assert_eq!(overlapping, json!([]), "labels drawn over colour");
    save("library.png", &browser.screenshot().await.unwrap());
    browser.close().await.unwrap();
    pictures_are_of_this_build(json!({
        "library": {"size": library.size, "mu_s": library.mu_s,
                    "sm_evaluations": library.sm_evaluations},
        "campaign-library": library_page,
        "campaign-adaptive": adaptive_page,
    }));
}

/// The README's pictures (`docs/img/`, copied from this test's screenshots
/// by `scripts/update-pictures`) show what this build shows: the numbers
/// this run's pages showed where they do not move (the library, the
/// stopped library and adaptive campaigns) are those the pictures were
/// taken with (`docs/img/pictures.json`, written beside them). A change
/// to those numbers fails here until the pictures are taken again
/// (`TSLG_UPDATE_PICTURES=1`, which the script sets, writes the file).
fn pictures_are_of_this_build(now: serde_json::Value) {
    let text = serde_json::to_string_pretty(&now).unwrap() + "\n";
    crate::browser_support::save("pictures.json", text.as_bytes());
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/img/pictures.json");
    if std::env::var_os("TSLG_UPDATE_PICTURES").is_some() {
        // scripts/update-pictures: the pictures are being taken again.
        std::fs::write(&path, text).unwrap();
        return;
    }
    let kept = path;
    let kept: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&kept).unwrap()).unwrap();
    assert_eq!(
        kept, now,
        "the README's pictures show other numbers than this build's pages: \
         run scripts/update-pictures and commit docs/img/"
    );
}

/// The texts of the library's picture whose box on the screen (after any
/// rotation), as the browser lays the text out, meets a coloured rectangle (a map's cell or a colour bar's
/// step); the white background is not coloured.
const LABELS_ON_COLOUR: &str = "(() => {
  const svg = document.querySelector('#picture svg');
  const coloured = [...svg.querySelectorAll('rect')]
    .filter(r => { const f = (r.getAttribute('fill') || 'none').toUpperCase(); return f !== 'NONE' && f !== '#FFFFFF'; })
    .map(r => r.getBoundingClientRect());
  const meets = (a, b) => a.left < b.right && b.left < a.right && a.top < b.bottom && b.top < a.bottom;
  return [...svg.querySelectorAll('text')]
    .filter(t => coloured.some(r => meets(t.getBoundingClientRect(), r)))
    .map(t => t.textContent.trim());
})()";
