//! The figures parse as SVG (XML) and hold the series they claim, at the
//! positions their data give.

use roxmltree::Document;
use tslg_api::{AdaptiveStage, CampaignStatus, CampaignView, HistoryPoint, Method, Outside};
use tslg_figures::{
    estimate_svg, heatmaps_svg, history_csv, relative_half_width_svg, stages_svg, support_svg,
    Heatmap, HeatmapAxis,
};

fn view() -> CampaignView {
    CampaignView {
        id: 7,
        case: "cut-in".into(),
        method: Method::Library,
        method_facts: Method::Library.into(),
        library_id: Some(1),
        vut: serde_json::json!({"model": "idm"}),
        vut_label: "idm".into(),
        parameters_inert: None,
        epsilon: 0.1,
        outside: Outside::Uniform,
        split: Default::default(),
        beta: 0.2,
        confidence: 0.9,
        n_min: 30,
        min_events: 5,
        max_tests: 1_000_000,
        seed: 1,
        status: CampaignStatus::Running,
        status_detail: None,
        tests: 4000,
        events: 80,
        invalid: 0,
        indices: 4000,
        leased: 4100,
        worker_seconds: 1.0,
        estimate: Some(1e-4),
        half_width: Some(3e-5),
        relative_half_width: Some(0.3),
        ci_low: Some(7e-5),
        ci_high: Some(1.3e-4),
        predicted_tests: Some(9000),
        effective_events: None,
        largest_weight_share: None,
        guard_outside: false,
        interval: Default::default(),
        explore_from: None,
        outside_tests: 0,
        outside_events: 0,
        mismatched_events: 0,
        outside_share: None,
        outside_upper: None,
        guarded_ci_high: None,
        answer: None,
        verdict: String::new(),
        exact_probability: None,
        adaptive: None,
        warnings: Vec::new(),
        tests_per_second: Some(1000.0),
        seconds_left: Some(5.0),
        audits: None,
        pair: None,
        created_at: String::new(),
        updated_at: String::new(),
        vehicle_noise: false,
    }
}

/// A history whose relative half-width falls as 1/√n from 2 at n = 10.
fn history() -> Vec<HistoryPoint> {
    let mut points = vec![HistoryPoint {
        tests: 0,
        indices: 0,
        events: 0,
        estimate: 0.0,
        half_width: 0.0,
        relative_half_width: None,
        ci_low: 0.0,
        ci_high: 0.0,
    }];
    for k in 1..=40u64 {
        let n = (10.0 * 1.2f64.powi(k as i32)).round() as u64;
        let r = 2.0 * (10.0 / n as f64).sqrt();
        points.push(point(n, k, 1e-4 * (1.0 + 0.3 / k as f64), r));
    }
    points
}

/// A point of `n` tests and `events` events with the estimate and its
/// relative half-width `r`.
fn point(n: u64, events: u64, estimate: f64, r: f64) -> HistoryPoint {
    HistoryPoint {
        tests: n,
        indices: n,
        events,
        estimate,
        half_width: r * estimate,
        relative_half_width: Some(r),
        ci_low: estimate * (1.0 - r),
        ci_high: estimate * (1.0 + r),
    }
}

fn texts(doc: &Document) -> Vec<String> {
    doc.descendants()
        .filter(|n| n.has_tag_name("text"))
        .filter_map(|n| n.text().map(|t| t.trim().to_owned()))
        .collect()
}

/// The point lists of the polylines drawn in `colour`.
fn lines(doc: &Document, colour: &str) -> Vec<Vec<(f64, f64)>> {
    doc.descendants()
        .filter(|n| n.has_tag_name("polyline") && n.attribute("stroke") == Some(colour))
        .map(|n| {
            n.attribute("points")
                .unwrap()
                .split_whitespace()
                .map(|xy| {
                    let (x, y) = xy.split_once(',').unwrap();
                    (x.parse().unwrap(), y.parse().unwrap())
                })
                .collect()
        })
        .collect()
}

#[test]
fn the_estimate_figure_holds_the_line_and_the_band_of_every_plotted_point() {
    let svg = estimate_svg(&view(), &history()).unwrap();
    let doc = Document::parse(&svg).expect("valid XML");
    assert_eq!(doc.root_element().tag_name().name(), "svg");
    let texts = texts(&doc);
    // The title names the campaign's vehicle.
    assert!(
        texts
            .iter()
            .any(|t| t.starts_with("Campaign 7, idm: estimate of P(A)")),
        "{texts:?}"
    );
    for label in ["estimate", "90% interval", "tests", "P(A)"] {
        assert!(
            texts.iter().any(|t| t == label),
            "no `{label}` in {texts:?}"
        );
    }
    // The line: one vertex per point with n > 0 (40), left to right.
    let line = lines(&doc, "#1F5DA6")
        .into_iter()
        .max_by_key(|l| l.len())
        .unwrap();
    assert_eq!(line.len(), 40);
    assert!(line.windows(2).all(|w| w[0].0 <= w[1].0));
    // The band: upper and lower edge of the 40 points, and it contains the line.
    let band = doc
        .descendants()
        .find(|n| n.has_tag_name("polygon") && n.attribute("fill") == Some("#A0C4E8"))
        .expect("the interval band");
    assert_eq!(
        band.attribute("points").unwrap().split_whitespace().count(),
        80
    );
}

#[test]
fn the_exact_value_is_a_dashed_line_at_its_height_when_known() {
    let unknown = estimate_svg(&view(), &history()).unwrap();
    let doc = Document::parse(&unknown).unwrap();
    assert!(lines(&doc, "#C82828").is_empty());
    assert!(!texts(&doc).iter().any(|t| t.starts_with("exact")));
    // P(A) = 1.2e-4, above the final estimate 1.0075e-4.
    let known = CampaignView {
        exact_probability: Some(1.2e-4),
        ..view()
    };
    let svg = estimate_svg(&known, &history()).unwrap();
    let doc = Document::parse(&svg).unwrap();
    assert!(
        texts(&doc).iter().any(|t| t == "exact P(A) = 1.20e-4"),
        "{:?}",
        texts(&doc)
    );
    let dashes = lines(&doc, "#C82828");
    let height = dashes[0][0].1;
    let at_height = dashes
        .iter()
        .filter(|s| s.iter().all(|p| p.1 == height))
        .count();
    assert!(
        at_height > 10 && at_height == dashes.len() - 1,
        "{dashes:?}"
    );
    // Pixel heights are linear in P(A) from 0 at the bottom: two points of
    // the estimate line give the scale.
    let line = lines(&doc, "#1F5DA6")
        .into_iter()
        .max_by_key(|l| l.len())
        .unwrap();
    let points = history();
    let (a, b) = (&points[1], points.last().unwrap());
    let (ya, yb) = (line[0].1, line[39].1);
    let per_unit = (yb - ya) / (a.estimate - b.estimate);
    let expected = yb - (1.2e-4 - b.estimate) * per_unit;
    assert!((height - expected).abs() <= 1.5, "{height} vs {expected}");
}

#[test]
fn the_half_width_figure_falls_on_a_log_axis_and_draws_beta() {
    let svg = relative_half_width_svg(&view(), &history()).unwrap();
    let doc = Document::parse(&svg).expect("valid XML");
    let texts = texts(&doc);
    assert!(texts.iter().any(|t| t == "β = 0.2"), "{texts:?}");
    assert!(texts.iter().any(|t| t == "relative half-width"));
    let line = lines(&doc, "#1F5DA6")
        .into_iter()
        .max_by_key(|l| l.len())
        .unwrap();
    assert_eq!(line.len(), 40);
    // r ∝ n^(-1/2) on log–log axes is a straight line of slope −1/2 in
    // data units: equal steps in ln n give equal pixel steps in both axes.
    let (first, last) = (line[0], line[39]);
    let (mid_x, mid_y) = line[20];
    let along = (mid_x - first.0) / (last.0 - first.0);
    let expected_y = first.1 + along * (last.1 - first.1);
    assert!((mid_y - expected_y).abs() <= 2.0, "{mid_y} vs {expected_y}");
    assert!(last.1 > first.1, "r falls: y grows downwards in SVG");
    // β is a dashed horizontal line: red segments at one height (the one
    // other red segment is the legend's sample).
    let beta = lines(&doc, "#C82828");
    let level = |segment: &Vec<(f64, f64)>| segment.iter().all(|p| p.1 == segment[0].1);
    assert!(beta.iter().all(level));
    let height = beta[0][0].1;
    let dashes = beta.iter().filter(|s| s[0].1 == height).count();
    assert!(
        dashes > 10 && dashes == beta.len() - 1,
        "{dashes} of {}",
        beta.len()
    );
}

#[test]
fn the_csv_has_every_point_with_its_numbers() {
    let csv = history_csv(&history());
    let rows: Vec<&str> = csv.lines().collect();
    assert_eq!(rows.len(), 42);
    assert!(rows[0].starts_with("tests,indices,events,estimate"));
    let last: Vec<&str> = rows[41].split(',').collect();
    let point = history().pop().unwrap();
    assert_eq!(last[0].parse::<u64>().unwrap(), point.tests);
    assert_eq!(last[3].parse::<f64>().unwrap(), point.estimate);
    assert_eq!(
        last[5].parse::<f64>().unwrap(),
        point.relative_half_width.unwrap()
    );
    assert_eq!(rows[1], "0,0,0,0,0,,0,0");
}

#[test]
fn a_heatmap_draws_one_cell_per_positive_value_and_rejects_a_wrong_shape() {
    let axis = |label: &str, n: usize| HeatmapAxis {
        label: label.into(),
        centres: (0..n).map(|k| k as f64 * 2.0).collect(),
    };
    let values: Vec<f64> = (0..12)
        .map(|k| if k % 3 == 0 { 0.0 } else { 10f64.powi(-k) })
        .collect();
    let map = Heatmap {
        title: "P(x)".into(),
        x: axis("range", 4),
        y: axis("range rate", 3),
        values,
    };
    let svg = heatmaps_svg("Library 1", &[map.clone(), map.clone()]).unwrap();
    let doc = Document::parse(&svg).expect("valid XML");
    let cells = doc
        .descendants()
        .filter(|n| n.has_tag_name("rect") && n.attribute("fill") != Some("#FFFFFF"))
        .count();
    assert_eq!(
        cells,
        2 * (8 + tslg_figures::COLOUR_STEPS),
        "8 positive cells and a colour bar per map"
    );
    // The bar's ticks run from the smallest positive value to the largest.
    let texts = texts(&doc);
    for end in ["1.00e-11", "0.1"] {
        assert!(texts.iter().any(|t| t == end), "{end} in {texts:?}");
    }
    let wrong = Heatmap {
        values: vec![1.0; 5],
        ..map
    };
    assert!(heatmaps_svg("x", &[wrong])
        .unwrap_err()
        .to_string()
        .contains("5 values for a 4 × 3 grid"));
}

/// Draws both campaign figures on another thread; `None` when they take
/// longer than `limit` (a hang: the figure code once walked a log axis from
/// 0 forever for a campaign stored with β = 10⁻³¹⁰).
fn drawn_within(
    view: CampaignView,
    points: Vec<HistoryPoint>,
    limit: std::time::Duration,
) -> Option<(String, String)> {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let estimate = estimate_svg(&view, &points).unwrap();
        let width = relative_half_width_svg(&view, &points).unwrap();
        let _ = tx.send((estimate, width));
    });
    rx.recv_timeout(limit).ok()
}

#[test]
fn degenerate_numbers_never_hang_a_figure() {
    let point = |tests: u64, r: f64, estimate: f64| HistoryPoint {
        tests,
        indices: tests,
        events: 3,
        estimate,
        half_width: r * estimate,
        relative_half_width: Some(r),
        ci_low: estimate * (1.0 - r),
        ci_high: estimate * (1.0 + r),
    };
    let cases: Vec<(f64, Vec<HistoryPoint>)> = vec![
        // β subnormal, ordinary history: the axis once reached 0.
        (1e-310, history()),
        (1e-310, vec![point(100, 0.5, 1e-3)]),
        // Stored numbers of every kind of wrong.
        (
            0.2,
            vec![
                point(10, f64::NAN, f64::NAN),
                point(20, f64::INFINITY, f64::INFINITY),
            ],
        ),
        (
            0.2,
            vec![point(10, 1e-320, 1e-320), point(u64::MAX, 1e300, f64::MAX)],
        ),
        (f64::MIN_POSITIVE, vec![point(1, 0.0, 0.0)]),
        (0.2, vec![]),
    ];
    for (beta, points) in cases {
        let mut v = view();
        v.beta = beta;
        let drawn = drawn_within(v, points.clone(), std::time::Duration::from_secs(20));
        let (estimate, width) =
            drawn.unwrap_or_else(|| panic!("hung on β = {beta:e} with {} points", points.len()));
        Document::parse(&estimate).expect("the estimate figure is XML");
        Document::parse(&width).expect("the half-width figure is XML");
    }
}

/// The guarded interval's upper end is drawn when the campaign has one: at
/// its height when it fits, at the top and marked "above" when it would
/// flatten the estimate (it can be hundreds of times the estimate).
#[test]
fn the_guarded_upper_end_is_drawn_at_its_height_or_marked_above() {
    let plain = estimate_svg(&view(), &history()).unwrap();
    let doc = Document::parse(&plain).unwrap();
    assert!(lines(&doc, "#A15C00").is_empty());
    let near = CampaignView {
        guarded_ci_high: Some(2.0e-4),
        ..view()
    };
    let svg = estimate_svg(&near, &history()).unwrap();
    let doc = Document::parse(&svg).unwrap();
    assert!(
        texts(&doc)
            .iter()
            .any(|t| t == "guarded upper end = 2.00e-4"),
        "{:?}",
        texts(&doc)
    );
    let dots = lines(&doc, "#A15C00");
    assert!(dots.len() > 10, "{dots:?}");
    let far = CampaignView {
        guarded_ci_high: Some(0.5),
        ..view()
    };
    let svg = estimate_svg(&far, &history()).unwrap();
    let doc = Document::parse(&svg).unwrap();
    assert!(
        texts(&doc)
            .iter()
            .any(|t| t == "guarded upper end = 0.5 (above)"),
        "{:?}",
        texts(&doc)
    );
    // The estimate is not flattened: its line spans most of the height it
    // spans without the guard.
    let span = |svg: &str| {
        let doc = Document::parse(svg).unwrap();
        let line = lines(&doc, "#1F5DA6")
            .into_iter()
            .max_by_key(|l| l.len())
            .unwrap();
        let ys: Vec<f64> = line.iter().map(|p| p.1).collect();
        ys.iter().cloned().fold(f64::MIN, f64::max) - ys.iter().cloned().fold(f64::MAX, f64::min)
    };
    assert!(
        span(&svg) > 0.9 * span(&plain),
        "{} vs {}",
        span(&svg),
        span(&plain)
    );
}

/// The numbers written along the y axis: texts left of the plot area that
/// parse as numbers (the x ticks sit below it, the titles are words).
fn y_ticks(doc: &Document) -> Vec<String> {
    doc.descendants()
        .filter(|n| n.has_tag_name("text"))
        .filter(|n| {
            n.attribute("x")
                .and_then(|x| x.parse::<f64>().ok())
                .is_some_and(|x| x < 90.0)
        })
        .filter_map(|n| n.text().map(|t| t.trim().to_owned()))
        .filter(|t| t.parse::<f64>().is_ok())
        .collect()
}

#[test]
fn a_half_width_within_a_decade_still_has_ticks_to_read_it_by() {
    // A typical β = 0.05 campaign: the half-width falls from 0.3 to 0.05.
    let mut v = view();
    v.beta = 0.05;
    let points: Vec<HistoryPoint> = history()
        .into_iter()
        .map(|mut p| {
            p.relative_half_width = p.relative_half_width.map(|r| 0.05 + r * 0.1);
            p
        })
        .collect();
    let svg = relative_half_width_svg(&v, &points).unwrap();
    let doc = Document::parse(&svg).unwrap();
    let ticks = y_ticks(&doc);
    // The axis reaches a third of its span above the curve, for the
    // legend: 0.5 is the next tick of 1, 2 and 5.
    assert_eq!(ticks, ["0.050", "0.100", "0.200", "0.500"]);
}

/// The legend's box (its translucent white background) as `(x0, y0, x1, y1)`.
fn legend_box(doc: &Document) -> (f64, f64, f64, f64) {
    let rect = doc
        .descendants()
        .find(|n| n.has_tag_name("rect") && n.attribute("opacity") == Some("0.85"))
        .expect("a legend");
    let at = |name: &str| rect.attribute(name).unwrap().parse::<f64>().unwrap();
    let (x, y) = (at("x"), at("y"));
    (x, y, x + at("width"), y + at("height"))
}

/// Every vertex of the band and of the estimate or half-width line.
fn data_vertices(doc: &Document) -> Vec<(f64, f64)> {
    // The legend's own keys are lines of two points.
    let mut vertices: Vec<(f64, f64)> = lines(doc, "#1F5DA6")
        .into_iter()
        .filter(|l| l.len() > 2)
        .flatten()
        .collect();
    for band in doc
        .descendants()
        .filter(|n| n.has_tag_name("polygon") && n.attribute("fill") == Some("#A0C4E8"))
    {
        vertices.extend(
            band.attribute("points")
                .unwrap()
                .split_whitespace()
                .map(|xy| {
                    let (x, y) = xy.split_once(',').unwrap();
                    (x.parse::<f64>().unwrap(), y.parse::<f64>().unwrap())
                }),
        );
    }
    vertices
}

/// The legend covers none of the data: a legend fixed in the upper right
/// covered the interval band of a campaign whose estimate settles high
/// (issue 50), and the relative half-width's curve early on.
#[test]
fn the_legend_covers_no_data() {
    // Three histories: an estimate that settles high on the right (the
    // dashboard's NDD campaign), one that falls from a high start (a
    // library campaign's heavy early events), and the falling 1/√n one.
    let rising: Vec<HistoryPoint> = (1..=60u64)
        .map(|k| {
            let n = (10.0 * 1.15f64.powi(k as i32)).round() as u64;
            let estimate = 5e-3 * (1.0 - (-(k as f64) / 15.0).exp());
            point(n, k, estimate, 2.0 * (10.0 / n as f64).sqrt())
        })
        .collect();
    let falling: Vec<HistoryPoint> = rising
        .iter()
        .map(|p| {
            let estimate = 5e-3 * (1.0 + 20.0 / p.events as f64);
            point(p.tests, p.events, estimate, p.relative_half_width.unwrap())
        })
        .collect();
    let exact = CampaignView {
        exact_probability: Some(5e-3),
        ..view()
    };
    for (name, points) in [
        ("rising", rising),
        ("falling", falling),
        ("1/√n", history()),
    ] {
        for (figure, svg) in [
            ("estimate", estimate_svg(&exact, &points).unwrap()),
            (
                "half-width",
                relative_half_width_svg(&exact, &points).unwrap(),
            ),
        ] {
            let doc = Document::parse(&svg).unwrap();
            let (x0, y0, x1, y1) = legend_box(&doc);
            let vertices = data_vertices(&doc);
            assert!(vertices.len() > 20, "{name} {figure}");
            let covered: Vec<_> = vertices
                .iter()
                .filter(|&&(x, y)| x0 < x && x < x1 && y0 < y && y < y1)
                .collect();
            assert!(
                covered.is_empty(),
                "{name} {figure}: {covered:?} in {:?}",
                (x0, y0, x1, y1)
            );
        }
    }
}

fn stage(
    kind: &str,
    (start, end): (u64, u64),
    events: u64,
    new: u64,
    support: u64,
) -> AdaptiveStage {
    AdaptiveStage {
        kind: kind.into(),
        start,
        end,
        events,
        new_failures: new,
        invalid: 0,
        support,
        restarts_estimate: false,
    }
}

/// The x of a rectangle's left edge and its height, for each of `fill`.
fn rects(doc: &Document, fill: &str) -> Vec<(f64, f64, f64)> {
    doc.descendants()
        .filter(|n| n.has_tag_name("rect") && n.attribute("fill") == Some(fill))
        .map(|n| {
            let at = |a: &str| n.attribute(a).unwrap().parse::<f64>().unwrap();
            (at("x"), at("width"), at("height"))
        })
        .collect()
}

#[test]
fn an_adaptive_campaign_s_stages_are_drawn_over_their_tests_as_high_as_their_events() {
    let stages = [
        stage("library", (0, 100), 4, 4, 300),
        stage("search", (100, 704), 40, 40, 340),
        stage("estimate", (704, 734), 0, 0, 340),
    ];
    let svg = stages_svg(&view(), &stages).unwrap();
    let doc = Document::parse(&svg).unwrap();
    assert!(texts(&doc)
        .iter()
        .any(|t| t.contains("100 library, 604 search, 30 estimation tests")));
    // Each stage's strip and bar in its colour: the search's bar 10 times
    // the library's, its width 6.04 times; the estimation stage met nothing
    // and still has its strip.
    let library = rects(&doc, "#1F5DA6");
    let search = rects(&doc, "#D68214");
    let estimate = rects(&doc, "#1D7A3A");
    // The strip, then the legend's key (bars of no height are not drawn).
    assert_eq!(estimate.len(), 2, "{estimate:?}");
    let tallest = |r: &[(f64, f64, f64)]| r.iter().map(|x| x.2).fold(0.0, f64::max);
    let widest = |r: &[(f64, f64, f64)]| r.iter().map(|x| x.1).fold(0.0, f64::max);
    assert!(
        (tallest(&search) / tallest(&library) - 10.0).abs() < 0.5,
        "{library:?} {search:?}"
    );
    assert!((widest(&search) / widest(&library) - 6.04).abs() < 0.1);
    assert!(library[0].0 < search[0].0 && search[0].0 < estimate[0].0);
    let support = support_svg(&view(), &stages).unwrap();
    let doc = Document::parse(&support).unwrap();
    assert!(texts(&doc)
        .iter()
        .any(|t| t.contains("support after each stage (340 cells)")));
    // The support's steps: 300 after the library stage, held to 704, then 340.
    let line = &lines(&doc, "#1F5DA6")[0];
    assert_eq!(line.len(), 5, "{line:?}");
    assert_eq!(line[0].1, line[1].1);
    assert!(line[2].1 < line[1].1, "340 above 300 (y grows downwards)");
    assert_eq!(lines(&doc, "#D68214")[0].len(), 5, "the failures found");
}
