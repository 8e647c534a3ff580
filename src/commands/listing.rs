//! `tslg campaign list` and `tslg library list`: a coordinator's campaigns
//! and libraries, a line each; and how one library is shown.

use crate::args::ServerArgs;
use crate::commands::remote::{block_on, client};
use crate::inputs::vehicle_name;
use tslg_api::{CampaignStatus, CampaignView, LibraryStatus, LibraryView};

fn sci(value: Option<f64>) -> String {
    value.map_or("-".into(), |v| format!("{v:.3e}"))
}

/// One campaign's line of the list (its tests as the progress line counts
/// them, [`crate::commands::remote::tests_shown`]).
fn campaign_line(view: &CampaignView) -> String {
    let interval = match (view.ci_low, view.ci_high) {
        (Some(low), Some(high)) => format!("[{low:.3e}, {high:.3e}]"),
        _ => "-".into(),
    };
    format!(
        "{:>5}  {:<9}  {:<13} {:<9} {:<14} {:>11} {:>7}  {:<10} {:<24} {:>6}  {}",
        view.id,
        view.status.as_str(),
        view.case,
        view.method.as_str(),
        vehicle_name(&view.vut, &view.case),
        crate::commands::remote::tests_shown(view),
        view.events,
        sci(view.estimate),
        interval,
        view.relative_half_width
            .map_or("-".into(), |r| format!("{r:.3}")),
        view.beta
    )
}

pub fn campaigns(
    server: &ServerArgs,
    status: Option<CampaignStatus>,
    json: bool,
) -> anyhow::Result<()> {
    let client = client(server)?;
    let list = block_on(async { Ok(client.campaigns_in(status).await?) })?;
    let header = format!(
        "{:>5}  {:<9}  {:<13} {:<9} {:<14} {:>11} {:>7}  {:<10} {:<24} {:>6}  β",
        "id", "status", "case", "method", "vehicle", "tests", "events", "estimate", "interval", "r"
    );
    let lines = list.campaigns.iter().map(campaign_line).collect();
    let empty = format!(
        "no campaigns{}",
        in_state(status.map(CampaignStatus::as_str))
    );
    print_list(
        json.then(|| serde_json::to_string_pretty(&list))
            .transpose()?,
        &header,
        lines,
        &empty,
    );
    Ok(())
}

/// A list as JSON when asked for, else its header and lines (a note on
/// stderr when it is empty).
fn print_list(json: Option<String>, header: &str, lines: Vec<String>, empty: &str) {
    if let Some(json) = json {
        outln!("{json}");
        return;
    }
    outln!("{header}");
    for line in &lines {
        outln!("{line}");
    }
    if lines.is_empty() {
        eprintln!("{empty}");
    }
}

fn in_state(status: Option<&str>) -> String {
    status.map_or(String::new(), |s| format!(" {s}"))
}

/// One library's line of the list.
fn library_line(view: &LibraryView) -> String {
    let size = view
        .size
        .map_or("-".into(), |s| format!("{s} of {}", view.total_scenarios));
    format!(
        "{:>5}  {:<8}  {:<13} {:<11} {:<12} {:<10} {:>18}  {}",
        view.id,
        view.status.as_str(),
        view.case,
        view.preset,
        vehicle_name(&view.surrogate, &view.case),
        view.exposure,
        size,
        sci(view.mu_s)
    )
}

pub fn libraries(
    server: &ServerArgs,
    status: Option<LibraryStatus>,
    json: bool,
) -> anyhow::Result<()> {
    let client = client(server)?;
    let list = block_on(async { Ok(client.libraries(status).await?) })?;
    let header = format!(
        "{:>5}  {:<8}  {:<13} {:<11} {:<12} {:<10} {:>18}  μ_S",
        "id", "status", "case", "preset", "surrogate", "exposure", "cells"
    );
    let lines = list.iter().map(library_line).collect();
    let empty = format!(
        "no libraries{}",
        in_state(status.map(LibraryStatus::as_str))
    );
    print_list(
        json.then(|| serde_json::to_string_pretty(&list))
            .transpose()?,
        &header,
        lines,
        &empty,
    );
    Ok(())
}

/// A library on the coordinator, several lines (as `tslg library build`
/// shows a file).
pub fn describe_library(view: &LibraryView) -> String {
    let mut lines = vec![
        format!("library {:<10} {}", view.id, view.status.as_str()),
        format!("case               {} ({})", view.case, view.preset),
        format!(
            "surrogate          {}",
            vehicle_name(&view.surrogate, &view.case)
        ),
        format!(
            "exposure           {} (fingerprint {})",
            view.exposure, view.exposure_fingerprint
        ),
    ];
    if let Some(size) = view.size {
        lines.push(format!(
            "library size       {size} of {} scenarios ({:.2}%)",
            view.total_scenarios,
            100.0 * size as f64 / view.total_scenarios.max(1) as f64
        ));
    }
    if let Some(mu_s) = view.mu_s {
        lines.push(format!("mu_S               {mu_s:.6e}"));
        if let Some(w) = view.w {
            lines.push(format!(
                "W                  {w:.6e} ({:.2}% of mu_S)",
                100.0 * w / mu_s
            ));
        }
    }
    if let Some(n) = view.sm_evaluations {
        lines.push(format!("SM evaluations     {n}"));
    }
    if let Some(seconds) = view.build_seconds {
        lines.push(format!("build time         {seconds:.3} s"));
    }
    if let Some(detail) = &view.status_detail {
        lines.push(format!("now                {detail}"));
    }
    if let Some(error) = &view.error {
        lines.push(format!("error              {error}"));
    }
    lines.join("\n")
}
