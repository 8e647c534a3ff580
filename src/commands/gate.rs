//! `--fail-above P`: a campaign as a gate in a continuous-integration
//! pipeline. After the campaign stops, the command exits
//!
//! - 0 when it converged and its upper bound is at most `P`,
//! - [`ABOVE`] (3) when it converged and its upper bound is above `P`,
//! - [`NOT_CONVERGED`] (4) when it stopped without converging (its budget
//!   spent, cancelled, failed): no claim either way,
//! - 1 on any other error (the coordinator unreachable, a bad request).
//!
//! A campaign with an anytime interval (`--interval anytime`, a confidence
//! sequence that holds at every number of tests at once) is judged while it
//! runs: the command exits [`ABOVE`] as soon as the interval's lower end is
//! above `P`, and 0 as soon as its upper bound is below `P`. A Wald
//! interval is only judged at the stop, where its promise holds.
//!
//! The upper bound is the guarded one where the campaign has it (a library
//! campaign of a grid case: `guarded_ci_high`, which also bounds what the
//! library's surrogate may have missed; docs/statistics.md), else the
//! interval's `ci_high`: a gate must not pass a vehicle on an interval that
//! rests on the library covering its failures. For a paired regression
//! campaign it is the upper end of the difference `P(A)_a − P(A)_b`, and
//! the status is the pair's: the gate fails when today's build (a) may be
//! worse than yesterday's (b) by more than `P`.

use tslg_api::{CampaignStatus, CampaignView};

/// The exit status of a converged campaign whose upper bound is above the
/// limit.
pub const ABOVE: u8 = 3;
/// The exit status of a campaign that stopped without converging.
pub const NOT_CONVERGED: u8 = 4;

/// An outcome that ends the command with its own exit status and message
/// (the message on stderr; the campaign's state is printed as usual).
#[derive(Debug)]
pub struct GateFailed {
    pub code: u8,
    pub message: String,
}

impl std::fmt::Display for GateFailed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for GateFailed {}

/// The upper bound the gate compares: the paired difference's for a pair,
/// else the guarded one where it exists.
pub fn upper_bound(view: &CampaignView) -> Option<f64> {
    match &view.pair {
        Some(pair) => pair.difference.map(|d| d.ci_high),
        None => view.guarded_ci_high.or(view.ci_high),
    }
}

/// Whether `view`, a stopped campaign, passes the gate at `limit`: `Ok`
/// with the sentence saying why, or the failure with its exit status.
pub fn judge(view: &CampaignView, limit: f64) -> Result<String, GateFailed> {
    let (which, status) = match &view.pair {
        Some(pair) => ("the difference a - b's upper bound", pair.status),
        None if view.guarded_ci_high.is_some() => ("guarded upper bound", view.status),
        None => ("upper bound", view.status),
    };
    match (status, upper_bound(view)) {
        (CampaignStatus::Converged, Some(upper)) if upper <= limit => Ok(format!(
            "gate passed: campaign {} converged with {which} {upper:.3e} <= {limit}",
            view.id
        )),
        (CampaignStatus::Converged, Some(upper)) => Err(GateFailed {
            code: ABOVE,
            message: format!(
                "gate failed: campaign {} converged with {which} {upper:.3e} > {limit}",
                view.id
            ),
        }),
        (status, _) => Err(GateFailed {
            code: NOT_CONVERGED,
            message: format!(
                "gate undecided: campaign {} stopped {} without converging{}",
                view.id,
                status.as_str(),
                view.status_detail
                    .as_deref()
                    .map(|d| format!(" ({d})"))
                    .unwrap_or_default()
            ),
        }),
    }
}

/// The verdict on a running anytime campaign, once its interval lies
/// wholly on one side of `limit`: its lower end above (failed, [`ABOVE`])
/// or its upper bound below (passed); `None` while it straddles `limit`,
/// and always for a Wald campaign or a pair.
pub fn early(view: &CampaignView, limit: f64) -> Option<Result<String, GateFailed>> {
    if view.interval != tslg_api::IntervalKind::Anytime
        || view.pair.is_some()
        || view.status != CampaignStatus::Running
    {
        return None;
    }
    let (low, upper) = (view.ci_low?, upper_bound(view)?);
    if low > limit {
        return Some(Err(GateFailed {
            code: ABOVE,
            message: format!(
                "gate failed early: campaign {}'s anytime interval lies above {limit} after {}                  tests (lower end {low:.3e})",
                view.id, view.tests
            ),
        }));
    }
    (upper < limit).then(|| {
        Ok(format!(
            "gate passed early: campaign {}'s anytime interval lies below {limit} after {} tests              (upper bound {upper:.3e})",
            view.id, view.tests
        ))
    })
}

/// Checks that `limit` is a probability a gate can compare against.
pub fn check_limit(limit: f64) -> anyhow::Result<()> {
    anyhow::ensure!(
        limit.is_finite() && (0.0..=1.0).contains(&limit),
        "--fail-above must be a probability in [0, 1], got {limit}"
    );
    Ok(())
}
