//! The fold of a paired regression campaign's pair.
//!
//! A pair is two campaigns drawing the same tests (same seed, library and
//! ε), one per vehicle, so test `i` gives `aᵢ = w 1{A_a}` and `bᵢ = w 1{A_b}`
//! from the same draw. Each campaign folds its own estimate as any other,
//! but never stops on its own precision (`CampaignRow::fold_rule`); after
//! either folds, the pair folds `dᵢ = aᵢ − bᵢ` over the tests both have
//! resolved (`min` of their prefixes) with the paired rule of
//! `tslg_method::paired`, checked at every index, and when it holds stops
//! both. The stop therefore depends only on the outcomes, never on which
//! worker reported what first.

use crate::error::ServiceError;
use crate::store::campaigns::{self, CampaignRow};
use crate::store::{leases, pairs, reports};
use rusqlite::Connection;
use tslg_api::CampaignStatus;
use tslg_method::paired::{PairedOutcome, PairedStop, PairedSums};
use tslg_method::prefix::SparseOutcome;

/// The pair's outcomes of `from..to` from each campaign's: a test either
/// could not run is invalid for both; one where either had the event gives
/// both weighted outcomes (0 for the vehicle without it).
fn merge(a: &[(u64, SparseOutcome)], b: &[(u64, SparseOutcome)]) -> Vec<(u64, PairedOutcome)> {
    let mut merged: Vec<(u64, PairedOutcome)> = Vec::with_capacity(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    let weight = |o: SparseOutcome| match o {
        SparseOutcome::Event(w) => Some(w),
        SparseOutcome::Invalid => None,
    };
    while i < a.len() || j < b.len() {
        let ia = a.get(i).map_or(u64::MAX, |o| o.0);
        let ib = b.get(j).map_or(u64::MAX, |o| o.0);
        let index = ia.min(ib);
        let oa = (ia == index).then(|| a[i].1);
        let ob = (ib == index).then(|| b[j].1);
        i += usize::from(oa.is_some());
        j += usize::from(ob.is_some());
        let outcome = match (oa.map(weight), ob.map(weight)) {
            (Some(None), _) | (_, Some(None)) => PairedOutcome::Invalid,
            (wa, wb) => {
                PairedOutcome::Weighted(wa.flatten().unwrap_or(0.0), wb.flatten().unwrap_or(0.0))
            }
        };
        merged.push((index, outcome));
    }
    merged
}

/// After `campaign` folded (in the same transaction): folds its pair over
/// the tests both campaigns have now resolved and, when the paired rule
/// holds, stops both. Returns `campaign`'s new status when the pair
/// stopped it.
fn fold(conn: &Connection, campaign: &CampaignRow) -> Result<Option<CampaignStatus>, ServiceError> {
    let Some(pair) = pairs::of(conn, campaign)? else {
        return Ok(None);
    };
    if pair.stop.is_some() {
        return Ok(None);
    }
    let a = campaigns::get(conn, pair.campaign_a)?;
    let b = campaigns::get(conn, pair.campaign_b)?;
    let to = a.indices.min(b.indices) as u64;
    let (mut sums, mut indices) = (pair.sums(), pair.indices as u64);
    if to < indices {
        // A campaign's results were taken back (a worker caught lying):
        // fold the pair again from the start.
        (sums, indices) = (PairedSums::default(), 0);
    }
    if to == indices {
        return Ok(None);
    }
    let outcomes = merge(
        &reports::outcomes(conn, a.id, indices, to)?,
        &reports::outcomes(conn, b.id, indices, to)?,
    );
    let rule = a.rule();
    let result = sums.advance(&rule, rule.z(), &mut indices, to, &outcomes);
    pairs::store_fold(conn, &pair, &sums, indices, result.as_ref())?;
    let Some(result) = result else {
        return Ok(None);
    };
    let status = match result.stop {
        PairedStop::Exhausted => CampaignStatus::Exhausted,
        PairedStop::Precision | PairedStop::Significant => CampaignStatus::Converged,
    };
    let why = match result.stop {
        PairedStop::Precision => format!(
            "the difference of the rates is known to within β = {} of the larger rate",
            rule.beta
        ),
        PairedStop::Significant => format!(
            "the difference's interval at confidence {:.4} excludes zero",
            result.look_confidence.unwrap_or(rule.confidence)
        ),
        PairedStop::Exhausted => format!(
            "max_tests = {} used up before the difference reached its precision",
            rule.max_tests
        ),
    };
    for (id, partner) in [(a.id, b.id), (b.id, a.id)] {
        let detail = format!("paired with campaign {partner}: {why} after {indices} tests");
        campaigns::set_status(conn, id, status, &detail)?;
        // Its leases stop; its open audits wait (they run only for a
        // running campaign) in case the pair runs again
        // ([`pairs::reopen`]).
        leases::cancel_active(conn, id)?;
    }
    tracing::info!(
        pair = a.id,
        stop = result.stop.as_str(),
        stop_index = indices,
        "paired campaign stopped"
    );
    Ok(Some(status))
}

/// [`fold`] after `campaign`'s own fold, which gave `own`: the campaign's
/// status when either stopped it (the pair's first: a pair that stops at an
/// earlier index decides both), and the other campaign of the pair when
/// the pair stopped it too. Called after every fold, even one that stopped
/// the campaign at `max_tests`: the pair's last fold may come with it.
pub fn fold_after(
    conn: &Connection,
    campaign: &CampaignRow,
    own: Option<CampaignStatus>,
) -> Result<(Option<CampaignStatus>, Option<i64>), ServiceError> {
    Ok(match fold(conn, campaign)? {
        Some(status) => (Some(status), campaign.paired_with),
        None => (own, None),
    })
}
