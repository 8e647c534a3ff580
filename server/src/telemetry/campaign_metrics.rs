//! Per-campaign series on `/metrics`: each running campaign's tests, events,
//! estimate, relative half-width (with its target β) and rate, labelled by
//! campaign id, case and method, so a dashboard can follow one campaign and
//! alert on one that stalls.
//!
//! Cardinality is bounded: only running campaigns have series (a campaign's
//! series disappear when it stops; its final numbers stay in the API), and
//! at most [`MAX_CAMPAIGN_SERIES`] of them, the newest; how many running
//! campaigns were left out is itself a gauge. The totals over all campaigns
//! stay in `metrics.rs`.

use prometheus::{GaugeVec, IntGauge, Opts, Registry};
use tslg_api::CampaignView;

/// The most campaigns with series of their own in one scrape.
pub const MAX_CAMPAIGN_SERIES: usize = 50;

const LABELS: [&str; 3] = ["campaign", "case", "method"];

fn gauge_vec(registry: &Registry, name: &str, help: &str) -> GaugeVec {
    let gauge = GaugeVec::new(Opts::new(name, help), &LABELS).expect("valid gauge");
    registry
        .register(Box::new(gauge.clone()))
        .expect("registered once");
    gauge
}

/// Registers the series of `running` (running campaigns, newest first) in
/// `registry`; `all` counts every running campaign, including those beyond
/// the cap that `running` may leave out.
pub fn register(registry: &Registry, running: &[CampaignView], all: usize) {
    let tests = gauge_vec(
        registry,
        "tslg_campaign_tests",
        "Valid tests in a running campaign's resolved prefix.",
    );
    let events = gauge_vec(
        registry,
        "tslg_campaign_events",
        "Tests with the event in a running campaign's resolved prefix.",
    );
    let estimate = gauge_vec(
        registry,
        "tslg_campaign_estimate",
        "A running campaign's estimate of P(A) (absent before its first test).",
    );
    let relative = gauge_vec(
        registry,
        "tslg_campaign_relative_half_width",
        "A running campaign's relative half-width (absent while undefined); it stops at β.",
    );
    let beta = gauge_vec(
        registry,
        "tslg_campaign_beta",
        "The relative half-width a running campaign stops at.",
    );
    let rate = gauge_vec(
        registry,
        "tslg_campaign_tests_per_second",
        "Tests a second a running campaign receives (absent until measured).",
    );
    for view in running.iter().take(MAX_CAMPAIGN_SERIES) {
        let id = view.id.to_string();
        let labels = [id.as_str(), view.case.as_str(), view.method.as_str()];
        tests.with_label_values(&labels).set(view.tests as f64);
        events.with_label_values(&labels).set(view.events as f64);
        beta.with_label_values(&labels).set(view.beta);
        let optional = [
            (&estimate, view.estimate),
            (&relative, view.relative_half_width),
            (&rate, view.tests_per_second),
        ];
        for (gauge, value) in optional {
            if let Some(value) = value.filter(|v| v.is_finite()) {
                gauge.with_label_values(&labels).set(value);
            }
        }
    }
    let omitted = IntGauge::new(
        "tslg_campaign_series_omitted",
        "Running campaigns without series of their own (beyond the newest 50).",
    )
    .expect("valid gauge");
    omitted.set(all.max(running.len()).saturating_sub(MAX_CAMPAIGN_SERIES) as i64);
    registry
        .register(Box::new(omitted))
        .expect("registered once");
}

#[cfg(test)]
mod tests {
    use super::*;
    use prometheus::Encoder;

    fn running(id: i64) -> CampaignView {
        let mut view: CampaignView = serde_json::from_value(serde_json::json!({
            "id": id, "case": "cut-in", "method": "ndd", "library_id": null,
            "vut": {"model": "idm"}, "epsilon": 0.1, "outside": "uniform", "split": "stratified", "beta": 0.1,
            "confidence": 0.9, "n_min": 30, "min_events": 5, "max_tests": 1000, "seed": 1,
            "status": "running", "tests": 10 * id, "events": id, "invalid": 0,
            "indices": 10 * id, "leased": 0, "worker_seconds": 0.0,
            "created_at": "", "updated_at": ""
        }))
        .expect("a campaign view");
        view.estimate = Some(0.1);
        view
    }

    fn exposition(views: &[CampaignView]) -> String {
        let registry = Registry::new();
        register(&registry, views, views.len());
        let mut body = Vec::new();
        prometheus::TextEncoder::new()
            .encode(&registry.gather(), &mut body)
            .unwrap();
        String::from_utf8(body).unwrap()
    }

    #[test]
    fn each_running_campaign_has_its_series_up_to_the_cap() {
        let text = exposition(&[running(7)]);
        assert!(text.contains(r#"tslg_campaign_tests{campaign="7",case="cut-in",method="ndd"} 70"#));
        assert!(
            text.contains(r#"tslg_campaign_estimate{campaign="7",case="cut-in",method="ndd"} 0.1"#)
        );
        // Undefined numbers are absent, not NaN or 0.
        assert!(
            !text.contains("tslg_campaign_relative_half_width{"),
            "{text}"
        );
        assert!(text.contains("tslg_campaign_series_omitted 0"));
        let many: Vec<CampaignView> = (1..=60).rev().map(running).collect();
        let text = exposition(&many);
        let series = text
            .lines()
            .filter(|l| l.starts_with("tslg_campaign_tests{"))
            .count();
        assert_eq!(series, MAX_CAMPAIGN_SERIES);
        // The newest kept: 60 down to 11.
        assert!(text.contains(r#"tslg_campaign_tests{campaign="11","#));
        assert!(!text.contains(r#"tslg_campaign_tests{campaign="10","#));
        assert!(text.contains("tslg_campaign_series_omitted 10"));
    }
}
