//! A campaign's verdict in one line: which interval to report and why, or
//! why there is none yet (issue 69). The API's `verdict`, printed first by
//! `tslg campaign status` and on the campaign's page, and the first line
//! of `tslg campaign report`'s summary. It reads only the view: the answer
//! (`answer`, the interval the method says to report), the status and the
//! warnings.

use tslg_api::{CampaignStatus, CampaignView};

/// The verdict on `view`, from its answer, status and warnings.
pub fn verdict(view: &CampaignView) -> String {
    if view.method.builds_library() {
        return "a library build's surrogate runs: no failure rate to report".to_owned();
    }
    let confidence = format!("{:.0}%", 100.0 * view.confidence);
    let read_warnings = match view.warnings.len() {
        0 => String::new(),
        1 => "; read its warning".to_owned(),
        n => format!("; read its {n} warnings"),
    };
    let Some(answer) = &view.answer else {
        return match view.status {
            CampaignStatus::Pending => "waiting for its library: no verdict yet".to_owned(),
            CampaignStatus::Running => "running: no verdict before its first tests".to_owned(),
            other => format!(
                "{}: no verdict (too few tests for an interval){read_warnings}",
                other.as_str()
            ),
        };
    };
    let interval = format!("[{:.3e}, {:.3e}]", answer.low, answer.high);
    let which = format!("the {} interval", answer.interval.as_str());
    match view.status {
        // The reason names the interval it gives and what it assumes.
        CampaignStatus::Converged => format!(
            "report P(A) in {interval} at {confidence} confidence: {}{read_warnings}",
            answer.reason
        ),
        CampaignStatus::Exhausted => format!(
            "its budget ran out before β: {interval} at {confidence} confidence is wider than \
             asked ({}); raise the budget for a verdict within β{read_warnings}",
            answer.reason
        ),
        CampaignStatus::Running | CampaignStatus::Pending => {
            format!("running: {interval} so far ({which}), not yet within β{read_warnings}")
        }
        CampaignStatus::Cancelled => {
            format!("cancelled: {interval} when it stopped ({which}), not a verdict{read_warnings}")
        }
        CampaignStatus::Failed => format!(
            "failed: no verdict{}{read_warnings}",
            view.status_detail
                .as_ref()
                .map_or(String::new(), |d| format!(" ({d})"))
        ),
    }
}
