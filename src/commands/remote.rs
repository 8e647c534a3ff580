//! Talking to a running coordinator: connection arguments, the runtime for
//! one command, and how a campaign is shown.

use crate::args::{CaseArgs, ServerArgs};
use tslg_api::CampaignView;
use tslg_api::ExposureRequest;
use tslg_client::Client;
use tslg_method::number::Count;
use tslg_method::warnings::Dialect;

pub fn client(args: &ServerArgs) -> anyhow::Result<Client> {
    anyhow::ensure!(
        args.server.starts_with("http://") || args.server.starts_with("https://"),
        "--server {} must be an http:// or https:// URL",
        args.server
    );
    Client::new(&args.server, args.token.clone())
}

/// Runs one client command on a small runtime.
pub fn block_on<T>(
    future: impl std::future::Future<Output = anyhow::Result<T>>,
) -> anyhow::Result<T> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?
        .block_on(future)
}

/// A vehicle given as a built-in name or as a JSON object.
pub fn vehicle_json(text: &str) -> anyhow::Result<serde_json::Value> {
    if text.trim_start().starts_with('{') {
        Ok(serde_json::from_str(text).map_err(|e| anyhow::anyhow!("invalid vehicle JSON: {e}"))?)
    } else {
        Ok(serde_json::json!({ "model": text }))
    }
}

fn sci(value: Option<f64>) -> String {
    value.map_or("-".into(), |v| format!("{v:.3e}"))
}

/// The tests a campaign's one-line views show: an adaptive campaign counts
/// every test it ran (its library and search tests too, as the demo's table
/// does), not only the estimation tests its `tests` holds; the others their
/// valid tests.
pub fn tests_shown(view: &CampaignView) -> u64 {
    if view.adaptive.is_some() {
        view.indices
    } else {
        view.tests
    }
}

/// The campaign's tests, named: all it used (the progress line's count),
/// and of them the valid ones its estimate reads (an adaptive campaign's
/// estimation tests), its events and its invalid tests.
pub fn counts(view: &CampaignView) -> String {
    let used = Count(view.indices, "test");
    let events = Count(view.events, "event");
    match &view.adaptive {
        Some(_) => format!(
            "{used} run, {} of them estimation tests ({events}, {} invalid)",
            view.tests + view.invalid,
            view.invalid
        ),
        None => format!(
            "{used} used ({} valid, {events}, {} invalid)",
            view.tests, view.invalid
        ),
    }
}

/// One line of progress toward β ([`tests_shown`]).
pub fn progress_line(label: &str, view: &CampaignView) -> String {
    let r = view
        .relative_half_width
        .map_or("∞".into(), |r| format!("{r:.3}"));
    let tests = tests_shown(view);
    format!(
        "{label:<8} #{:<3} {:<9} {:>10} tests {:>6} events  r {r:>6} → β {}",
        view.id,
        view.status.as_str(),
        tests,
        view.events,
        view.beta
    )
}

/// A paired regression campaign's difference, several lines (as `tslg
/// evaluate --paired-with` prints it).
fn describe_pair(pair: &tslg_api::PairView) -> String {
    let interval = |i: Option<tslg_api::PairedInterval>| {
        i.map_or("-".into(), |i| {
            format!("{:.4e}  [{:.4e}, {:.4e}]", i.estimate, i.ci_low, i.ci_high)
        })
    };
    let mut lines = vec![
        format!(
            "\n  paired: a = campaign {}, b = campaign {}; {} over {} tests{}",
            pair.campaign_a,
            pair.campaign_b,
            pair.status.as_str(),
            pair.tests,
            match pair.stop {
                Some(tslg_api::PairStop::Precision) =>
                    " (the difference is within beta of the larger rate)",
                Some(tslg_api::PairStop::Significant) =>
                    " (the difference's interval excludes zero)",
                Some(tslg_api::PairStop::Exhausted) => " (max tests reached)",
                Some(tslg_api::PairStop::Cancelled) => " (cancelled)",
                None => "",
            }
        ),
        format!(
            "    events a {}, b {}, discordant (one failed) {}",
            pair.events_a, pair.events_b, pair.discordant
        ),
        format!("    P(A) of a          {}", interval(pair.rate_a)),
        format!("    P(A) of b          {}", interval(pair.rate_b)),
        format!("    difference a - b   {}", interval(pair.difference)),
    ];
    if let Some(level) = pair.look_confidence {
        lines.push(format!("    (zero excluded at confidence {level:.4})"));
    }
    if let Some(t) = pair.independent_tests {
        lines.push(format!(
            "    two separate campaigns: about {t:.0} tests each for this half-width ({:.1} x)",
            t / pair.tests.max(1) as f64
        ));
    }
    if let Some(d) = pair.exact_difference {
        lines.push(format!(
            "    exact difference   {d:.4e} (by enumeration of the grid)"
        ));
    }
    lines.join("\n")
}

/// The campaign's state, several lines.
pub fn describe(view: &CampaignView) -> String {
    let health = match (view.effective_events, view.largest_weight_share) {
        (Some(ess), Some(share)) => format!(
            "\n  sampling health: {ess:.1} effective events of {}, largest weight {:.1}% of the estimate",
            view.events,
            share * 100.0
        ),
        _ => String::new(),
    };
    // An adaptive campaign's exploring tests are a share of its estimation
    // tests, drawn off its support K (docs/statistics.md, "Adaptive
    // campaigns").
    let (region, share) = match view.adaptive {
        Some(_) => (
            "outside the support K",
            "of its estimation tests".to_owned(),
        ),
        None => (
            "outside the library",
            format!("ε {}, {} split", view.epsilon, view.split.as_str()),
        ),
    };
    let outside = match view.outside_upper {
        Some(upper) => format!(
            "\n  {region}: {} exploring tests ({share}), {}; failure mass \
             there ≤ {upper:.3e} ({:.0}% bound), guarded interval [{}, {}]{}",
            view.outside_tests,
            tslg_method::number::Count(view.outside_events, "event"),
            view.confidence * 100.0,
            sci(view.ci_low),
            sci(view.guarded_ci_high),
            if view.guard_outside { ", guard on" } else { "" }
        ),
        None => String::new(),
    };
    let answer = match &view.answer {
        Some(a) => format!(
            "\n  answer [{}, {}]: {}",
            sci(Some(a.low)),
            sci(Some(a.high)),
            a.reason
        ),
        None => String::new(),
    };
    let exact = match (view.exact_probability, &view.answer) {
        (Some(p), Some(a)) => format!(
            "\n  exact P(A) {p:.3e} (by enumeration of the grid): {} the answer",
            if a.low <= p && p <= a.high {
                "inside"
            } else {
                "OUTSIDE"
            }
        ),
        (Some(p), _) => format!("\n  exact P(A) {p:.3e} (by enumeration of the grid)"),
        _ => String::new(),
    };
    let adaptive = match &view.adaptive {
        Some(a) => format!(
            "\n  adaptive: {} library and {} search tests found where the vehicle fails; the \
             estimate uses only the estimation tests, on {} cells (failures found, library \
             cells untested), {} stages{}\n  assumes: the vehicle's failures outside the \
             library are reachable through failures and near misses from what the tests met",
            a.library_tests,
            a.search_tests,
            a.support,
            a.stages,
            a.running.as_ref().map_or(String::new(), |r| format!(
                "; running a {} stage, tests {}..{}",
                r.kind, r.start, r.end
            ))
        ),
        None => String::new(),
    };
    let pair = view.pair.as_ref().map_or(String::new(), |pair| {
        let mut text = describe_pair(pair);
        // Each campaign of a pair folds its own results as they come, so
        // one can hold more than the pair's decision used.
        if view.indices > pair.tests {
            text.push_str(&format!(
                "\n    (the pair decides on its first {} tests; this campaign's own figures \
                 above count all {} it resolved)",
                pair.tests, view.indices
            ));
        }
        text
    });
    let inert = if view.parameters_inert == Some(true) {
        format!(
            "\n  note: the parameters of {} change no accident of this preset: its exact P(A) \
             equals the defaults', to the last bit",
            crate::inputs::vehicle_name(&view.vut, &view.case)
        )
    } else {
        String::new()
    };
    let warnings: String = view
        .warnings
        .iter()
        .map(|w| format!("\n  warning: {}", Dialect::Cli.translate(w)))
        .collect();
    // A coordinator of an earlier release sends no verdict.
    let verdict = if view.verdict.is_empty() {
        String::new()
    } else {
        format!("\n  verdict: {}", Dialect::Cli.translate(&view.verdict))
    };
    format!(
        "campaign {} ({} {}, vehicle {}): {}{}{verdict}\n  {}\n  \
         estimate {}  {}interval [{}, {}]  relative half-width {} (β {}, confidence {}){answer}{exact}{inert}{health}{outside}{adaptive}{pair}{warnings}",
        view.id,
        view.case,
        view.method.as_str(),
        crate::inputs::vehicle_name(&view.vut, &view.case),
        view.status.as_str(),
        view.status_detail.as_ref().map_or(String::new(), |d| format!(" — {d}")),
        counts(view),
        sci(view.estimate),
        match view.interval {
            tslg_api::IntervalKind::Wald => "",
            tslg_api::IntervalKind::Anytime => "anytime ",
        },
        sci(view.ci_low),
        sci(view.ci_high),
        view.relative_half_width.map_or("-".into(), |r| format!("{r:.3}")),
        view.beta,
        view.confidence
    )
}

/// The exposure of a request: the table named by `--ndd-table`, uploaded
/// with the request, or the case's built-in model.
pub fn exposure_request(case: &CaseArgs) -> anyhow::Result<ExposureRequest> {
    Ok(match &case.ndd_table {
        None => ExposureRequest::Builtin,
        Some(path) => {
            let (name, text) = crate::inputs::read_table(path)?;
            ExposureRequest::Table { name, text }
        }
    })
}

/// Prints a campaign: as JSON, or described in a few lines.
pub fn print_campaign(view: &tslg_api::CampaignView, json: bool) -> anyhow::Result<()> {
    if json {
        outln!("{}", serde_json::to_string_pretty(view)?);
    } else {
        outln!("{}", describe(view));
    }
    Ok(())
}
