//! A campaign's page, whatever its kind (library, NDD, guarded, adaptive,
//! paired, a library build's surrogate runs), checked against the API: the
//! header is on screen and shows the view's numbers, the parts that do not
//! apply are not shown, and every figure shown draws its data (not only its
//! axes, legend and reference lines). The adaptive page once showed none of
//! its header and figures holding only the β and exact lines.

use crate::browser_support::{eval, save, until};
use fantoccini::Client as Browser;
use serde_json::{json, Value};
use tslg_api::{CampaignView, Method};

/// What the page shows: each field's exact value (`data-value`, or its
/// text) when it is on screen, `null` when it is not; and which sections
/// are on screen.
const SHOWN: &str = "(() => {
  const on = (n) => n !== null && n.checkVisibility();
  const field = (id) => { const n = document.getElementById(id);
    return on(n) ? (n.dataset.value ?? n.textContent) : null; };
  const ids = ['status', 'tests', 'indices', 'events', 'invalid', 'estimate',
    'relative-half-width', 'outside-upper', 'guarded-interval', 'library-tests',
    'search-tests', 'estimation-tests', 'stages', 'support', 'answer', 'answer-reason'];
  const sections = ['summary', 'pair', 'adaptive', 'estimate-figures'];
  return {
    fields: Object.fromEntries(ids.map((id) => [id, field(id)])),
    sections: Object.fromEntries(sections.map((id) => [id, on(document.getElementById(id))])),
  };
})()";

/// For each figure on screen: the most points of a data line (the
/// estimate's or the support's colours; a legend's key has 2), its
/// polygons (the interval band) and its rectangles in a stage's colour
/// standing on the x axis (each stage's strip, and the bars of those that
/// met events).
const DRAWN: &str = "(() => {
  const out = {};
  for (const f of document.querySelectorAll('figure.figure')) {
    if (!f.checkVisibility()) continue;
    const svg = f.querySelector('svg');
    if (!svg) { out[f.id] = null; continue; }
    const colour = (n, a) => (n.getAttribute(a) || '').toUpperCase();
    const lines = [...svg.querySelectorAll('polyline')]
      .filter((p) => ['#1F5DA6', '#D68214'].includes(colour(p, 'stroke')))
      .map((p) => p.getAttribute('points').trim().split(/\\s+/).length);
    out[f.id] = {
      line: Math.max(0, ...lines),
      bands: svg.querySelectorAll('polygon').length,
      // Standing on the x axis, as every stage's strip and bar does (a
      // legend's keys do not): the lowest rectangle's bottom edge.
      stage_rects: (() => {
        const rects = [...svg.querySelectorAll('rect')]
          .filter((r) => ['#1F5DA6', '#D68214', '#1D7A3A'].includes(colour(r, 'fill')));
        const bottom = (r) => Number(r.getAttribute('y')) + Number(r.getAttribute('height'));
        const axis = Math.max(0, ...rects.map(bottom));
        return rects.filter((r) => Math.abs(bottom(r) - axis) < 1.5).length;
      })(),
    };
  }
  return out;
})()";

fn exact(value: Option<f64>) -> Value {
    value.map_or(Value::Null, |v| json!(v))
}

fn count(value: u64) -> Value {
    json!(value.to_string())
}

/// Opens campaign `view`'s page (the campaign stopped: its numbers no
/// longer move), checks it against `view` and keeps a screenshot of the
/// whole page as `campaign-{name}.png`. Returns what the page showed.
pub async fn page_agrees(browser: &Browser, url: &str, view: &CampaignView, name: &str) -> Value {
    browser
        .goto(&format!("{url}/campaigns/{}?refresh=300", view.id))
        .await
        .unwrap();
    until(
        browser,
        &format!(
            "document.getElementById('status').textContent === '{}' \
             && !document.getElementById('updated').textContent.startsWith('update failed')",
            view.status.as_str()
        ),
        &format!("the {name} campaign's page"),
    )
    .await;
    let shown = eval(browser, SHOWN).await;
    let fields = &shown["fields"];
    let sections = &shown["sections"];
    let build = matches!(view.method, Method::Enumerate | Method::Build);
    let adaptive = view.adaptive.as_ref();
    assert_eq!(
        sections["summary"],
        json!(true),
        "{name}: the header is on screen"
    );
    assert_eq!(fields["status"], json!(view.status.as_str()), "{name}");
    // The verdict first, as the API words it.
    let verdict = eval(browser, "document.getElementById('verdict').textContent").await;
    assert!(!view.verdict.is_empty(), "{name}");
    assert_eq!(
        verdict,
        json!(format!("Verdict: {}", view.verdict)),
        "{name}"
    );
    assert_eq!(fields["tests"], count(view.tests), "{name}");
    assert_eq!(fields["events"], count(view.events), "{name}");
    assert_eq!(fields["invalid"], count(view.invalid), "{name}");
    let number = |field: &str| -> Value {
        fields[field].as_str().map_or(Value::Null, |s| {
            s.parse::<f64>().map_or(json!(s), |v| json!(v))
        })
    };
    if build {
        assert_eq!(
            fields["estimate"],
            Value::Null,
            "{name}: a build estimates nothing"
        );
        assert_eq!(sections["estimate-figures"], json!(false), "{name}");
    } else {
        assert_eq!(number("estimate"), exact(view.estimate), "{name}");
        assert_eq!(
            number("relative-half-width"),
            exact(view.relative_half_width),
            "{name}"
        );
        assert_eq!(sections["estimate-figures"], json!(true), "{name}");
    }
    let outside = view.outside_upper.is_some() || view.guarded_ci_high.is_some();
    assert_eq!(
        (number("outside-upper"), number("guarded-interval")),
        if outside {
            (exact(view.outside_upper), exact(view.guarded_ci_high))
        } else {
            (Value::Null, Value::Null)
        },
        "{name}: the outside bound is shown where there is one"
    );
    // The answer to report, and why, as the API gives it.
    assert_eq!(
        (number("answer"), fields["answer-reason"].clone()),
        match &view.answer {
            Some(a) => (
                json!(a.high),
                json!(format!("{}: {}", a.interval.as_str(), a.reason))
            ),
            None => (Value::Null, Value::Null),
        },
        "{name}: the answer"
    );
    assert_eq!(sections["pair"], json!(view.pair.is_some()), "{name}");
    assert_eq!(sections["adaptive"], json!(adaptive.is_some()), "{name}");
    match adaptive {
        Some(a) => {
            assert_eq!(fields["indices"], count(view.indices), "{name}");
            assert_eq!(fields["library-tests"], count(a.library_tests));
            assert_eq!(fields["search-tests"], count(a.search_tests));
            assert_eq!(fields["estimation-tests"], count(view.tests));
            assert_eq!(fields["stages"], count(a.stages));
            assert_eq!(fields["support"], count(a.support));
        }
        None => assert_eq!(fields["indices"], Value::Null, "{name}"),
    }
    // The figures, once drawn: each draws its data.
    let figures: Vec<&str> = match (build, adaptive.is_some()) {
        (true, _) => vec![],
        // A paired campaign's page also draws the other vehicle's estimate.
        (false, false) if view.pair.is_some() => {
            vec!["estimate-figure", "half-width-figure", "pair-figure"]
        }
        (false, false) => vec!["estimate-figure", "half-width-figure"],
        (false, true) => vec![
            "estimate-figure",
            "half-width-figure",
            "stages-figure",
            "support-figure",
        ],
    };
    let all_drawn = figures
        .iter()
        .map(|f| format!("document.querySelector('#{f} svg')"))
        .chain(["true".to_owned()])
        .collect::<Vec<_>>()
        .join(" && ");
    until(browser, &all_drawn, &format!("{name}: the figures")).await;
    let drawn = eval(browser, DRAWN).await;
    let shown_figures: Vec<&String> = drawn.as_object().unwrap().keys().collect();
    assert_eq!(
        shown_figures.len(),
        figures.len(),
        "{name}: figures on screen {shown_figures:?}"
    );
    for figure in figures {
        let d = &drawn[figure];
        let line = d["line"].as_u64().unwrap();
        match figure {
            "estimate-figure" | "pair-figure" => {
                assert!(line >= 3, "{name}: the estimate is drawn: {d}");
                assert!(d["bands"].as_u64().unwrap() >= 1, "{name}: its band: {d}");
            }
            "half-width-figure" | "support-figure" => {
                assert!(line >= 3, "{name}: {figure} draws its line: {d}")
            }
            _ => {
                let stages = adaptive.unwrap().stages;
                assert!(
                    d["stage_rects"].as_u64().unwrap() >= stages,
                    "{name}: every one of {stages} stages drawn: {d}"
                );
            }
        }
    }
    // The whole page in the screenshot.
    let height = eval(browser, "document.documentElement.scrollHeight").await;
    let height = height.as_u64().unwrap().clamp(600, 2400) as u32;
    browser.set_window_size(1560, height + 120).await.unwrap();
    save(
        &format!("campaign-{name}.png"),
        &browser.screenshot().await.unwrap(),
    );
    browser.set_window_size(1560, 900).await.unwrap();
    shown
}
