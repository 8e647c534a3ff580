//! The `campaigns` and `history` tables.

pub use crate::store::campaign_row::{CampaignRow, COLUMNS};

use crate::db::sql;
use crate::store::campaign_row::methods_where;
use crate::store::costs;
use crate::store::error::StoreError;
use crate::store::states::{CAMPAIGN_CANCELLED, CAMPAIGN_FAILED, CAMPAIGN_RUNNING};
use const_format::formatcp;
use rusqlite::{params, Connection};
use tslg_api::{AdaptiveSearch, CampaignStatus, Method, Outside, Split};
use tslg_method::estimator::StoppingRule;

/// A validated campaign to insert.
pub struct NewCampaign {
    pub case_name: String,
    pub preset: String,
    pub method: Method,
    pub library_id: Option<i64>,
    pub exposure_name: String,
    pub exposure_fingerprint: String,
    pub exposure_table: Option<String>,
    pub vut: String,
    pub requires: Option<String>,
    pub epsilon: f64,
    pub outside: Outside,
    pub split: Split,
    pub rule: StoppingRule,
    pub seed: u64,
    pub status: CampaignStatus,
    /// `P(A)` by enumeration, where the case could compute it.
    pub exact_probability: Option<f64>,
    /// Its vehicle's parameters change no accident of the preset
    /// (`tslg_method::registry::parameters_inert`).
    pub parameters_inert: Option<bool>,
    /// Its program's runs may differ: audits compare by statistics.
    pub vehicle_noise: bool,
    /// How an adaptive campaign searches (`grid` for the others).
    pub adaptive_search: AdaptiveSearch,
    /// An adaptive campaign's estimation stages' length (100 for the
    /// others).
    pub stage_tests: u64,
    /// An adaptive campaign's search width
    /// (`tslg_method::adaptive::AdaptiveSettings::search_width`; 0 for the
    /// others).
    pub search_width: u64,
    /// An adaptive campaign's first stage: its tests `start..end` and kind.
    pub first_stage: Option<(u64, u64, &'static str)>,
}

pub fn insert(conn: &Connection, new: &NewCampaign) -> Result<CampaignRow, StoreError> {
    let sql = format!(
        "INSERT INTO campaigns (case_name, preset, method, library_id, exposure_name, \
         exposure_fingerprint, exposure_table, vut, requires, epsilon, outside, beta, confidence, \
         n_min, min_events, max_tests, seed, status, guard_outside, exact_probability, split, \
         stage_start, stage_end, stage_kind, cost_per_test, vehicle_noise, \
         interval, outside_s2, parameters_inert, adaptive_search, stage_tests, search_width) \
         VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, 0, ?, ?, ?, ?) \
         RETURNING {COLUMNS}"
    );
    let first_stage = new.first_stage.as_ref();
    // What its vehicle's tests cost in earlier campaigns: its first leases
    // are sized in seconds of work.
    let cost = costs::get(
        conn,
        &costs::key(
            &new.case_name,
            &new.preset,
            &new.vut,
            new.requires.as_deref(),
        ),
    )?;
    Ok(sql::one(
        conn,
        &sql,
        params![
            new.case_name,
            new.preset,
            new.method.as_str(),
            new.library_id,
            new.exposure_name,
            new.exposure_fingerprint,
            new.exposure_table,
            new.vut,
            new.requires,
            new.epsilon,
            new.outside.as_str(),
            new.rule.beta,
            new.rule.confidence,
            new.rule.n_min as i64,
            new.rule.min_events as i64,
            new.rule.max_tests as i64,
            new.seed as i64,
            new.status.as_str(),
            new.rule.guard_outside,
            new.exact_probability,
            new.split.as_str(),
            first_stage.map(|s| s.0 as i64),
            first_stage.map(|s| s.1 as i64),
            first_stage.map(|s| s.2),
            cost,
            new.vehicle_noise,
            new.rule.interval.name(),
            new.parameters_inert,
            new.adaptive_search.as_str(),
            new.stage_tests as i64,
            new.search_width as i64,
        ],
    )?)
}

pub fn get(conn: &Connection, id: i64) -> Result<CampaignRow, StoreError> {
    thread_local! {
        static SQL: String = format!("SELECT {COLUMNS} FROM campaigns WHERE id = ?");
    }
    SQL.with(|sql| super::campaign_row::first(conn, sql, [id]))?
        .ok_or_else(|| StoreError::NotFound(format!("campaign {id} does not exist")))
}

/// Every campaign, or those in `status`, newest first.
pub fn list(
    conn: &Connection,
    status: Option<CampaignStatus>,
) -> Result<Vec<CampaignRow>, StoreError> {
    Ok(sql::all(
        conn,
        &format!(
            "SELECT {COLUMNS} FROM campaigns WHERE ?1 IS NULL OR status = ?1 ORDER BY id DESC"
        ),
        [status.map(CampaignStatus::as_str)],
    )?)
}

/// Cancels a pending or running campaign and its leases (a write).
pub fn cancel(conn: &Connection, id: i64) -> Result<CampaignRow, StoreError> {
    let row = get(conn, id)?;
    if row.status.is_final() {
        return Err(StoreError::Conflict(format!(
            "campaign {id} has already stopped ({})",
            row.status.as_str()
        )));
    }
    sql::execute(
        conn,
        formatcp!("UPDATE campaigns SET status = {CAMPAIGN_CANCELLED}, status_detail = 'cancelled on request', \
         updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now') WHERE id = ?"),
        [id],
    )?;
    crate::store::leases::cancel_active(conn, id)?;
    get(conn, id)
}

/// A stored history point: `(indices, tests, events, s1, s2,
/// outside_tests, outside_s1, sequence_low, sequence_high)`, as the fold
/// wrote it (the sequence's interval only for an anytime campaign).
pub type HistoryRow = (
    i64,
    i64,
    i64,
    f64,
    f64,
    i64,
    f64,
    Option<f64>,
    Option<f64>,
    Option<f64>,
);

/// The stored history points of campaign `id`, in index order.
pub fn history_rows(conn: &Connection, id: i64) -> Result<Vec<HistoryRow>, StoreError> {
    Ok(sql::all(
        conn,
        "SELECT indices, tests, events, s1, s2, outside_tests, outside_s1, sequence_low, \
         sequence_high, outside_s2 FROM history \
         WHERE campaign_id = ? ORDER BY indices",
        [id],
    )?)
}

/// Sets campaign `id`'s status, saying why.
pub fn set_status(
    conn: &Connection,
    id: i64,
    status: CampaignStatus,
    detail: &str,
) -> Result<(), StoreError> {
    sql::execute(
        conn,
        "UPDATE campaigns SET status = ?, status_detail = ?, \
         updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now') WHERE id = ?",
        params![status.as_str(), detail, id],
    )?;
    Ok(())
}

/// Campaign `id` failed, saying why (its leases are cancelled apart).
pub fn set_failed(conn: &Connection, id: i64, detail: &str) -> Result<(), StoreError> {
    sql::execute(
        conn,
        formatcp!(
            "UPDATE campaigns SET status = {CAMPAIGN_FAILED}, status_detail = ? WHERE id = ?"
        ),
        params![detail, id],
    )?;
    Ok(())
}

/// Campaign `id` runs again from an empty prefix, saying why; its history
/// past index `first` goes.
pub fn run_again(conn: &Connection, id: i64, detail: &str, first: i64) -> Result<(), StoreError> {
    sql::execute(
        conn,
        formatcp!("UPDATE campaigns SET indices = 0, tests = 0, events = 0, invalid = 0, s1 = 0, \
         s2 = 0, largest = 0, outside_tests = 0, outside_events = 0, outside_s1 = 0, \
         outside_mismatches = 0, outside_upper = NULL, status = {CAMPAIGN_RUNNING}, status_detail = ? \
         WHERE id = ?"),
        params![detail, id],
    )?;
    sql::execute(
        conn,
        "DELETE FROM history WHERE campaign_id = ? AND indices > ?",
        [id, first],
    )?;
    Ok(())
}

/// Counts `audits` tests of `campaign` chosen for an audit that no other
/// worker could run.
pub fn count_waived_audits(
    conn: &Connection,
    campaign: i64,
    audits: u64,
) -> Result<(), StoreError> {
    sql::execute(
        conn,
        "UPDATE campaigns SET audits_waived = audits_waived + ? WHERE id = ?",
        [audits as i64, campaign],
    )?;
    Ok(())
}

/// The campaign that builds library `library` on workers (its
/// enumeration, or the whole build one worker runs), the newest, if any.
pub fn building_library(
    conn: &Connection,
    library: i64,
) -> Result<Option<CampaignRow>, StoreError> {
    Ok(sql::optional(
        conn,
        &format!(
            "SELECT {COLUMNS} FROM campaigns WHERE library_id = ? AND method IN {} \
             ORDER BY id DESC LIMIT 1",
            methods_where(|m| m.builds.is_some())
        ),
        [library],
    )?)
}

/// A whole build's campaign `id` done: its one test resolved, with its
/// `status` and why, and the worker's `seconds` charged.
pub fn finish_whole_build(
    conn: &Connection,
    id: i64,
    status: CampaignStatus,
    detail: Option<&str>,
    seconds: f64,
) -> Result<(), StoreError> {
    sql::execute(
        conn,
        "UPDATE campaigns SET status = ?, status_detail = ?, next_index = 1, indices = 1, \
         tests = 1, worker_seconds = worker_seconds + ?, \
         updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now') WHERE id = ?",
        params![status.as_str(), detail, seconds, id],
    )?;
    Ok(())
}
