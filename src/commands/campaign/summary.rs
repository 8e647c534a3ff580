//! `tslg campaign report`'s `summary.md`: a campaign for a reader without
//! the service at hand, in Markdown: its verdict (which interval to report
//! and why), its numbers, its warnings, and the figures written beside it.

use tslg_api::CampaignView;
use tslg_method::warnings::Dialect;

fn sci(value: Option<f64>) -> String {
    value.map_or("–".into(), |v| format!("{v:.4e}"))
}

/// The summary of `view`, linking the figure files `figures` (written in
/// the same folder).
pub fn markdown(view: &CampaignView, figures: &[&str]) -> String {
    let vehicle = crate::inputs::vehicle_name(&view.vut, &view.case);
    let mut out = format!(
        "# Campaign {}: {vehicle} on {} ({})\n\n",
        view.id,
        view.case,
        view.method.as_str()
    );
    if !view.verdict.is_empty() {
        out.push_str(&format!(
            "**Verdict:** {}\n\n",
            Dialect::Cli.translate(&view.verdict)
        ));
    }
    let mut rows: Vec<(String, String)> = vec![
        (
            "status".into(),
            match &view.status_detail {
                Some(detail) => format!("{} ({detail})", view.status.as_str()),
                None => view.status.as_str().to_owned(),
            },
        ),
        // An adaptive campaign's estimate reads its estimation tests only.
        ("tests".into(), crate::commands::remote::counts(view)),
        ("events".into(), view.events.to_string()),
        ("estimate".into(), sci(view.estimate)),
        (
            format!(
                "{:.0}% interval ({})",
                100.0 * view.confidence,
                match view.interval {
                    tslg_api::IntervalKind::Wald => "Wald",
                    tslg_api::IntervalKind::Anytime => "anytime",
                }
            ),
            format!("[{}, {}]", sci(view.ci_low), sci(view.ci_high)),
        ),
        (
            "relative half-width".into(),
            format!(
                "{} (β {})",
                view.relative_half_width
                    .map_or("–".into(), |r| format!("{r:.4}")),
                view.beta
            ),
        ),
    ];
    if let Some(answer) = &view.answer {
        rows.push((
            "answer".into(),
            format!(
                "[{}, {}], the {} interval: {}",
                sci(Some(answer.low)),
                sci(Some(answer.high)),
                answer.interval.as_str(),
                answer.reason
            ),
        ));
    }
    if let Some(upper) = view.outside_upper {
        rows.push((
            "failure mass outside the library (or support) ≤".into(),
            format!(
                "{} ({} exploring tests, {} events there)",
                sci(Some(upper)),
                view.outside_tests,
                view.outside_events
            ),
        ));
    }
    if let Some(exact) = view.exact_probability {
        let inside = view
            .answer
            .as_ref()
            .map(|a| {
                if a.low <= exact && exact <= a.high {
                    " (inside the answer)"
                } else {
                    " (OUTSIDE the answer)"
                }
            })
            .unwrap_or_default();
        rows.push((
            "exact P(A), by enumeration".into(),
            format!("{}{inside}", sci(Some(exact))),
        ));
    }
    out.push_str("| | |\n|---|---|\n");
    for (label, value) in rows {
        out.push_str(&format!("| {label} | {} |\n", value.replace('|', "\\|")));
    }
    if !view.warnings.is_empty() {
        out.push_str("\n## Warnings\n\n");
        for warning in &view.warnings {
            out.push_str(&format!("- {}\n", Dialect::Cli.translate(warning)));
        }
    }
    if !figures.is_empty() {
        out.push_str("\n## Figures\n\n");
        for figure in figures {
            out.push_str(&format!("![{figure}]({figure})\n\n"));
        }
    }
    out
}
