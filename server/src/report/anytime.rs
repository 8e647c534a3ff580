//! An anytime campaign's fold on the coordinator ([`tslg_method::anytime`]):
//! its confidence sequences live in memory between reports, and are folded
//! again from the stored outcomes when they are not there (after a restart,
//! or for a fold outside the report path).
//!
//! The sequences are a function of the outcomes in index order alone, so
//! the copy folded again equals the one that was kept, to the bit, and the
//! stop does not depend on which was used.

use crate::error::ServiceError;
use crate::store::campaigns::CampaignRow;
use crate::store::reports;
use rusqlite::Connection;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use tslg_method::anytime::{AnytimeFold, TermBounds};
use tslg_method::estimator::{Decision, StoppingRule};
use tslg_method::outside::OutsideMass;
use tslg_method::prefix::{Exploration, PrefixFold, SparseOutcome};
use tslg_method::registry::CampaignTests;

/// The anytime folds kept between reports, by campaign. Each is taken out
/// while a fold runs (the writer runs one at a time) and put back after.
#[derive(Default)]
pub struct AnytimeFolds {
    folds: Mutex<HashMap<i64, AnytimeFold>>,
}

impl AnytimeFolds {
    /// Campaign `campaign`'s fold if it stands at `indices`.
    fn take(&self, campaign: i64, indices: u64) -> Option<AnytimeFold> {
        let mut folds = self.lock();
        match folds.remove(&campaign) {
            Some(fold) if fold.fold.indices == indices => Some(fold),
            _ => None,
        }
    }

    fn keep(&self, campaign: i64, fold: AnytimeFold) {
        self.lock().insert(campaign, fold);
    }

    /// Drops the fold of a campaign that stopped.
    pub fn forget(&self, campaign: i64) {
        self.lock().remove(&campaign);
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<i64, AnytimeFold>> {
        self.folds
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

/// What [`fold`] reads: the span to fold and the campaign's tests.
pub struct AnytimeSpan<'a> {
    pub frontier: u64,
    pub outcomes: &'a [(u64, SparseOutcome)],
    pub explored: &'a [u64],
    pub mass: Option<&'a OutsideMass>,
    pub misses: &'a (dyn Fn(u64) -> bool + Sync),
    pub last_stored: Option<u64>,
    /// The exploring tests of `from..to`, drawn again (for a fold folded
    /// again from the stored outcomes).
    pub draw_explored: &'a DrawExplored,
}

/// Draws the exploring tests of `from..to` of a campaign's tests.
pub type DrawExplored = dyn Fn(&Arc<dyn CampaignTests>, u64, u64) -> Vec<u64>;

/// What one anytime fold gave: the history points worth storing, with the
/// sequence's interval at each, and the decision if the rule stopped.
pub struct AnytimeFolded {
    pub course: Vec<(PrefixFold, Option<(f64, f64)>)>,
    pub decision: Option<Decision>,
    pub anytime: AnytimeFold,
}

/// Folds `span` onto campaign `campaign`'s anytime fold (kept in `kept`,
/// or folded again from what is stored), and keeps it for the next report
/// unless it stopped. `tests` are a library campaign's (`None` for the
/// NDD, whose terms are its outcomes, in `[0, 1]`).
pub fn fold(
    conn: &Connection,
    campaign: &CampaignRow,
    rule: &StoppingRule,
    tests: Option<&Arc<dyn CampaignTests>>,
    kept: Option<&AnytimeFolds>,
    span: AnytimeSpan<'_>,
) -> Result<AnytimeFolded, ServiceError> {
    let from = campaign.indices as u64;
    let mut anytime = match kept.and_then(|k| k.take(campaign.id, from)) {
        Some(fold) => fold,
        None => again(conn, campaign, rule, tests, &span)?,
    };
    let exploration = span.mass.map(|mass| Exploration {
        explored: span.explored,
        mass,
        surrogate_misses: span.misses,
    });
    let mut last_stored = span.last_stored;
    let mut course = Vec::new();
    let decision = anytime
        .advance_observed(
            rule,
            span.frontier,
            span.outcomes,
            exploration,
            &mut |state, bounds| {
                if crate::campaign::history::worth_storing(last_stored, state.indices) {
                    last_stored = Some(state.indices);
                    course.push((*state, Some((bounds.low, bounds.high))));
                }
            },
        )
        .map_err(|e| {
            anyhow::anyhow!("stored outcomes of campaign {} rejected: {e}", campaign.id)
        })?;
    let bounds = anytime.bounds();
    if decision.is_some()
        || crate::campaign::history::worth_storing(last_stored, anytime.fold.indices)
    {
        course.push((anytime.fold, Some((bounds.low, bounds.high))));
    }
    if let (Some(kept), None) = (kept, decision) {
        kept.keep(campaign.id, anytime.clone());
    }
    Ok(AnytimeFolded {
        course,
        decision,
        anytime,
    })
}

/// The fold of campaign `campaign`'s stored prefix `0..indices`, folded
/// again from its stored outcomes.
fn again(
    conn: &Connection,
    campaign: &CampaignRow,
    rule: &StoppingRule,
    tests: Option<&Arc<dyn CampaignTests>>,
    span: &AnytimeSpan<'_>,
) -> Result<AnytimeFold, ServiceError> {
    let (mass, misses) = (span.mass, span.misses);
    let indices = campaign.indices as u64;
    let bounds = match tests {
        Some(tests) => tests.term_bounds().ok_or_else(|| {
            anyhow::anyhow!("campaign {}'s tests have no anytime interval", campaign.id)
        })?,
        None => TermBounds::Single(1.0),
    };
    let strata = tests.and_then(|t| t.strata());
    let mut fold = AnytimeFold::new(rule, strata, bounds);
    let outcomes = reports::outcomes(conn, campaign.id, 0, indices)?;
    let explored = match (tests, mass) {
        (Some(tests), Some(_)) => (span.draw_explored)(tests, 0, indices),
        _ => Vec::new(),
    };
    let exploration = mass.map(|mass| Exploration {
        explored: &explored,
        mass,
        surrogate_misses: misses,
    });
    let decision = fold
        .advance(rule, indices, &outcomes, exploration)
        .map_err(|e| {
            anyhow::anyhow!("stored outcomes of campaign {} rejected: {e}", campaign.id)
        })?;
    if decision.is_some() || fold.fold.indices != indices {
        return Err(anyhow::anyhow!(
            "campaign {}'s stored prefix 0..{indices} folds again to a stop at {}",
            campaign.id,
            fold.fold.indices
        )
        .into());
    }
    Ok(fold)
}
