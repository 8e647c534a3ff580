//! The `campaign_pairs` table: paired regression campaigns, two campaigns
//! drawing the same tests, one per vehicle, and their pair's fold (its
//! sums, folded by `report/pair_fold.rs`).

use crate::db::sql;
use crate::store::campaigns::{self, CampaignRow};
use crate::store::error::StoreError;
use crate::store::states::{CAMPAIGN_RUNNING, PAIR_CANCELLED};
use const_format::formatcp;
use rusqlite::{params, Connection};
use tslg_api::{CampaignStatus, PairStop};
use tslg_method::paired::{PairedResult, PairedSums};

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
    pub fn sums(&self) -> PairedSums {
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

    pub fn stop(&self) -> Option<PairStop> {
        self.stop
            .as_deref()
            .and_then(|s| serde_json::from_value(serde_json::json!(s)).ok())
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

/// Stores the pair's fold: its sums over `indices`, and its stop and the
/// confidence of its last look once its rule held.
pub fn store_fold(
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
                formatcp!("UPDATE campaign_pairs SET stop = {PAIR_CANCELLED} WHERE campaign_a = ?"),
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
            formatcp!(
                "UPDATE campaigns SET status = {CAMPAIGN_RUNNING}, status_detail = ? WHERE id = ?"
            ),
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
