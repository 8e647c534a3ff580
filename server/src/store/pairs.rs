//! The `campaign_pairs` table: paired regression campaigns.
//!
//! A pair is two campaigns drawing the same tests (same seed, library and
//! ε), one per vehicle, so test `i` gives `aᵢ = w 1{A_a}` and `bᵢ = w 1{A_b}`
//! from the same draw. Each campaign folds its own estimate as any other,
//! but never stops on its own precision ([`CampaignRow::fold_rule`]); after
//! either folds, the pair folds `dᵢ = aᵢ − bᵢ` over the tests both have
//! resolved (`min` of their prefixes) with the paired rule of
//! `tslg_method::paired`, checked at every index, and when it holds stops
//! both. The stop therefore depends only on the outcomes, never on which
//! worker reported what first.

use crate::db::sql;
use crate::store::campaigns::{self, CampaignRow};
use crate::store::error::StoreError;
use crate::store::reports;
use rusqlite::{params, Connection};
use tslg_api::{CampaignStatus, PairStop, PairView, PairedInterval};
use tslg_method::paired::{PairedOutcome, PairedResult, PairedStop, PairedSums};
use tslg_method::prefix::SparseOutcome;

/// A pair as stored.
#[derive(Debug, Clone, serde::Deserialize)]
pub struct PairRow {
    pub campaign_a: i64,
    pub campaign_b: i64,
    pub indices: i64,
    pub tests: i64,
    pub events_a: i64,
    pub events_b: i64,
    pub discordant: i64,
    pub a_s1: f64,
    pub a_s2: f64,
    pub b_s1: f64,
    pub b_s2: f64,
    pub d_s1: f64,
    pub d_s2: f64,
    /// `precision`, `significant`, `exhausted` or `cancelled`; NULL while
    /// running.
    pub stop: Option<String>,
    pub look_confidence: Option<f64>,
}

const COLUMNS: &str = "campaign_a, campaign_b, indices, tests, events_a, events_b, discordant, \
    a_s1, a_s2, b_s1, b_s2, d_s1, d_s2, stop, look_confidence";

impl PairRow {
    /// The fold's sums as stored.
    fn sums(&self) -> PairedSums {
        PairedSums {
            n: self.tests as u64,
            events: (
                self.events_a as u64,
                self.events_b as u64,
                self.discordant as u64,
            ),
            a: (self.a_s1, self.a_s2),
            b: (self.b_s1, self.b_s2),
            d: (self.d_s1, self.d_s2),
        }
    }

    /// The other campaign of the pair.
    pub fn partner(&self, id: i64) -> i64 {
        if id == self.campaign_a {
            self.campaign_b
        } else {
            self.campaign_a
        }
    }

    fn stop(&self) -> Option<PairStop> {
        self.stop
            .as_deref()
            .and_then(|s| serde_json::from_value(serde_json::json!(s)).ok())
    }

    /// The pair as the API shows it; `a` and `b` are its campaigns.
    pub fn view(&self, a: &CampaignRow, b: &CampaignRow) -> PairView {
        let sums = self.sums();
        let rule = a.rule();
        let stop = self.stop();
        let result = sums.stopped(
            &rule,
            PairedStop::parse(self.stop.as_deref().unwrap_or_default())
                .unwrap_or(PairedStop::Exhausted),
            self.look_confidence,
        );
        let interval = |(estimate, ci_low, ci_high): (f64, f64, f64)| {
            (sums.n > 1).then_some(PairedInterval {
                estimate,
                ci_low,
                ci_high,
            })
        };
        PairView {
            campaign_a: self.campaign_a,
            campaign_b: self.campaign_b,
            status: match stop {
                // Before its rule holds the pair stands as its campaigns:
                // waiting for its library, or failed with it.
                None if [a.status, b.status].contains(&CampaignStatus::Failed) => {
                    CampaignStatus::Failed
                }
                None if [a.status, b.status].contains(&CampaignStatus::Cancelled) => {
                    CampaignStatus::Cancelled
                }
                None if a.status == CampaignStatus::Pending => CampaignStatus::Pending,
                None => CampaignStatus::Running,
                Some(PairStop::Precision | PairStop::Significant) => CampaignStatus::Converged,
                Some(PairStop::Exhausted) => CampaignStatus::Exhausted,
                Some(PairStop::Cancelled) => CampaignStatus::Cancelled,
            },
            stop,
            indices: self.indices as u64,
            tests: sums.n,
            events_a: sums.events.0,
            events_b: sums.events.1,
            discordant: sums.events.2,
            rate_a: interval(result.rate_a),
            rate_b: interval(result.rate_b),
            difference: interval(result.difference),
            look_confidence: self.look_confidence,
            independent_tests: result.independent_tests,
            exact_difference: a
                .exact_probability
                .zip(b.exact_probability)
                .map(|(pa, pb)| pa - pb),
        }
    }
}

/// Makes `a` and `b` a pair (a write, in the transaction that inserted
/// them).
pub fn link(conn: &Connection, a: i64, b: i64) -> Result<(), StoreError> {
    sql::execute(
        conn,
        "INSERT INTO campaign_pairs (campaign_a, campaign_b) VALUES (?, ?)",
        [a, b],
    )?;
    for (id, partner) in [(a, b), (b, a)] {
        sql::execute(
            conn,
            "UPDATE campaigns SET paired_with = ? WHERE id = ?",
            [partner, id],
        )?;
    }
    Ok(())
}

/// The pair `campaign` belongs to, if any.
pub fn of(conn: &Connection, campaign: &CampaignRow) -> Result<Option<PairRow>, StoreError> {
    if campaign.paired_with.is_none() {
        return Ok(None);
    }
    Ok(sql::optional(
        conn,
        &format!("SELECT {COLUMNS} FROM campaign_pairs WHERE campaign_a = ?1 OR campaign_b = ?1"),
        [campaign.id],
    )?)
}

/// The pair of `campaign` as the API shows it, if it has one.
pub fn view_of(conn: &Connection, campaign: &CampaignRow) -> Result<Option<PairView>, StoreError> {
    let Some(pair) = of(conn, campaign)? else {
        return Ok(None);
    };
    let partner = campaigns::get(conn, pair.partner(campaign.id))?;
    Ok(Some(if campaign.id == pair.campaign_a {
        pair.view(campaign, &partner)
    } else {
        pair.view(&partner, campaign)
    }))
}

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
fn fold(conn: &Connection, campaign: &CampaignRow) -> Result<Option<CampaignStatus>, StoreError> {
    let Some(pair) = of(conn, campaign)? else {
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
    write(conn, &pair, &sums, indices, result.as_ref())?;
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
        sql::execute(
            conn,
            "UPDATE campaigns SET status = ?, status_detail = ?, \
             updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now') WHERE id = ?",
            params![
                status.as_str(),
                format!(
                    "paired with campaign {partner}: {why} after test index {}",
                    indices - 1
                ),
                id
            ],
        )?;
        // Its leases stop; its open audits wait (they run only for a
        // running campaign) in case the pair runs again ([`reopen`]).
        crate::store::leases::cancel_active(conn, id)?;
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
) -> Result<(Option<CampaignStatus>, Option<i64>), StoreError> {
    Ok(match fold(conn, campaign)? {
        Some(status) => (Some(status), campaign.paired_with),
        None => (own, None),
    })
}

fn write(
    conn: &Connection,
    pair: &PairRow,
    sums: &PairedSums,
    indices: u64,
    result: Option<&PairedResult>,
) -> Result<(), StoreError> {
    sql::execute(
        conn,
        "UPDATE campaign_pairs SET indices = ?, tests = ?, events_a = ?, events_b = ?, \
         discordant = ?, a_s1 = ?, a_s2 = ?, b_s1 = ?, b_s2 = ?, d_s1 = ?, d_s2 = ?, stop = ?, \
         look_confidence = ? WHERE campaign_a = ?",
        params![
            indices as i64,
            sums.n as i64,
            sums.events.0 as i64,
            sums.events.1 as i64,
            sums.events.2 as i64,
            sums.a.0,
            sums.a.1,
            sums.b.0,
            sums.b.1,
            sums.d.0,
            sums.d.1,
            result.map(|r| r.stop.as_str()),
            result.and_then(|r| r.look_confidence),
            pair.campaign_a
        ],
    )?;
    Ok(())
}

/// Cancels campaign `id` and, when it is one of a pair, the other one and
/// the pair (a write).
pub fn cancel(conn: &Connection, id: i64) -> Result<CampaignRow, StoreError> {
    let row = campaigns::cancel(conn, id)?;
    if let Some(pair) = of(conn, &row)? {
        let partner = campaigns::get(conn, pair.partner(id))?;
        if !partner.status.is_final() {
            campaigns::cancel(conn, partner.id)?;
        }
        if pair.stop.is_none() {
            sql::execute(
                conn,
                "UPDATE campaign_pairs SET stop = 'cancelled' WHERE campaign_a = ?",
                [pair.campaign_a],
            )?;
        }
    }
    Ok(row)
}

/// The index the pair of a stopped campaign decided at, when the pair
/// stopped it: results past it no longer count for the pair.
pub fn decided_at(conn: &Connection, campaign: &CampaignRow) -> Result<Option<u64>, StoreError> {
    Ok(of(conn, campaign)?
        .filter(|p| p.stop.is_some())
        .map(|p| p.indices as u64))
}

/// After campaign `id`'s results were taken back and it runs again: its
/// pair folds again from the start, and the other campaign, if the pair
/// had stopped it, runs again too (with the leases the stop cancelled).
pub fn reopen(conn: &Connection, campaign: &CampaignRow) -> Result<(), StoreError> {
    let Some(pair) = of(conn, campaign)? else {
        return Ok(());
    };
    sql::execute(
        conn,
        "UPDATE campaign_pairs SET indices = 0, tests = 0, events_a = 0, events_b = 0, \
         discordant = 0, a_s1 = 0, a_s2 = 0, b_s1 = 0, b_s2 = 0, d_s1 = 0, d_s2 = 0, \
         stop = NULL, look_confidence = NULL WHERE campaign_a = ?",
        [pair.campaign_a],
    )?;
    let partner = campaigns::get(conn, pair.partner(campaign.id))?;
    // Stopped by the pair (a campaign of a pair stops on its own only when
    // cancelled or failed): it runs again with the pair, if only to be
    // stopped again by the pair's next fold.
    if matches!(
        partner.status,
        CampaignStatus::Converged | CampaignStatus::Exhausted
    ) {
        sql::execute(
            conn,
            "UPDATE campaigns SET status = 'running', status_detail = ? WHERE id = ?",
            params![
                format!(
                    "runs again with campaign {}, whose results were taken back",
                    campaign.id
                ),
                partner.id
            ],
        )?;
        crate::store::leases::reactivate_cancelled(conn, partner.id)?;
    }
    Ok(())
}

/// Removes the pair of `campaign` (before its campaigns are deleted).
pub fn unlink(conn: &Connection, campaign: &CampaignRow) -> Result<Option<i64>, StoreError> {
    let Some(pair) = of(conn, campaign)? else {
        return Ok(None);
    };
    sql::execute(
        conn,
        "DELETE FROM campaign_pairs WHERE campaign_a = ?",
        [pair.campaign_a],
    )?;
    Ok(Some(pair.partner(campaign.id)))
}
