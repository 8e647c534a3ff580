//! The `campaigns` and `history` tables.

use crate::db::sql;
use crate::lease_size::predicted_unleased;
use crate::store::audits::AuditState;
use crate::store::error::StoreError;
use rusqlite::{params, Connection};
use tslg_api::{
    AdaptiveView, AuditCounts, CampaignStatus, CampaignView, ExposureRequest, HistoryPoint, Method,
    Outside, RunningStage, Split,
};
use tslg_method::campaign::CampaignResult;
use tslg_method::estimator::{Decision, ImportanceEstimator, StoppingRule};
use tslg_method::outside::OutsideTally;
use tslg_method::prefix::PrefixFold;
use tslg_method::registry::ExposureSource;
use tslg_method::warnings::{warnings, Dialect, WarningContext};

#[derive(Debug, Clone, serde::Deserialize)]
pub struct CampaignRow {
    pub id: i64,
    pub case_name: String,
    pub preset: String,
    pub method: Method,
    pub library_id: Option<i64>,
    pub exposure_name: String,
    pub exposure_fingerprint: String,
    pub exposure_table: Option<String>,
    pub vut: String,
    /// `NAME:case:mode` of an external vehicle under test.
    pub requires: Option<String>,
    pub epsilon: f64,
    pub outside: Outside,
    /// How the tests are split between the library and the outside.
    pub split: Split,
    /// The exploring share the estimate stratifies on (NULL: the plain mean).
    pub strata_epsilon: Option<f64>,
    pub beta: f64,
    pub confidence: f64,
    pub n_min: i64,
    pub min_events: i64,
    pub max_tests: i64,
    pub seed: i64,
    pub status: CampaignStatus,
    pub status_detail: Option<String>,
    pub next_index: i64,
    pub indices: i64,
    pub tests: i64,
    pub events: i64,
    pub invalid: i64,
    pub s1: f64,
    pub s2: f64,
    /// The largest weighted term of the prefix, `max wᵢ yᵢ`.
    pub largest: f64,
    pub guard_outside: bool,
    /// The prefix's exploring tests, their events and those events' `S₁`.
    pub outside_tests: i64,
    pub outside_events: i64,
    pub outside_s1: f64,
    pub outside_mismatches: i64,
    /// `U` for the prefix; NULL until the exploring tests are counted, and
    /// for campaigns without a library outside (NDD, car-following).
    pub outside_upper: Option<f64>,
    pub cost_per_test: Option<f64>,
    pub worker_seconds: f64,
    /// Tests chosen for an audit that no other worker could run.
    pub audits_waived: i64,
    /// The weights of every event recorded, folded or not.
    pub reported_s1: f64,
    /// `P(A)` by enumeration of the grid, where it was computed.
    pub exact_probability: Option<f64>,
    /// An adaptive campaign's running stage `[stage_start, stage_end)` and
    /// kind; NULL for other methods and once it stopped.
    pub stage_start: Option<i64>,
    pub stage_end: Option<i64>,
    pub stage_kind: Option<String>,
    pub library_tests: i64,
    pub search_tests: i64,
    pub stages: i64,
    pub support: i64,
    /// The other campaign of a paired regression campaign
    /// ([`crate::store::pairs`]).
    pub paired_with: Option<i64>,
    pub created_at: String,
    pub updated_at: String,
}

/// An adaptive campaign is stored as method 'library' with `adaptive = 1`
/// (migrations/…14_adaptive.sql) and read as `adaptive`; a library build's
/// enumeration as 'ndd' with `enumerate = 1` (…17_enumerate.sql), a
/// build one worker runs whole as 'ndd' with `enumerate = 2`.
pub const COLUMNS: &str = "id, case_name, preset, \
    CASE WHEN adaptive = 1 THEN 'adaptive' WHEN enumerate = 1 THEN 'enumerate' \
    WHEN enumerate = 2 THEN 'build' ELSE method END \
    AS method, library_id, exposure_name, \
    exposure_fingerprint, exposure_table, vut, requires, epsilon, outside, split, strata_epsilon, \
    beta, confidence, n_min, min_events, max_tests, seed, status, status_detail, next_index, indices, tests, events, invalid, s1, s2, \
    largest, guard_outside, outside_tests, outside_events, outside_s1, outside_upper, \
    outside_mismatches, \
    cost_per_test, worker_seconds, audits_waived, reported_s1, exact_probability, \
    stage_start, stage_end, stage_kind, library_tests, search_tests, stages, support, paired_with, created_at, \
    updated_at";

/// How the warnings' advice to rerun with the guard reads for a campaign of
/// a pair.
const PAIRED_RERUN: &str =
    "Rerun each vehicle as a campaign of its own (a pair takes no guard) with ";

impl CampaignRow {
    pub fn seed(&self) -> u64 {
        self.seed as u64
    }

    pub fn rule(&self) -> StoppingRule {
        StoppingRule {
            beta: self.beta,
            confidence: self.confidence,
            n_min: self.n_min as u64,
            min_events: self.min_events as u64,
            max_tests: self.max_tests as u64,
            guard_outside: self.guard_outside,
        }
    }

    /// The rule the campaign's own fold applies: its rule, except that a
    /// campaign of a pair never stops on its own precision (`min_events`
    /// is never reached): the pair's rule on the difference stops it
    /// ([`crate::store::pairs::fold`]), or `max_tests`.
    pub fn fold_rule(&self) -> StoppingRule {
        let rule = self.rule();
        match self.paired_with {
            Some(_) => StoppingRule {
                min_events: u64::MAX,
                ..rule
            },
            None => rule,
        }
    }

    /// The prefix estimator as persisted.
    pub fn fold(&self) -> PrefixFold {
        PrefixFold {
            estimator: ImportanceEstimator::from_sums(
                self.tests as u64,
                self.events as u64,
                self.s1,
                self.s2,
            )
            .with_largest(self.largest),
            indices: self.indices as u64,
            invalid: self.invalid as u64,
            outside: OutsideTally {
                tests: self.outside_tests as u64,
                events: self.outside_events as u64,
                s1: self.outside_s1,
                mismatches: self.outside_mismatches as u64,
            },
            strata: self.strata_epsilon,
        }
    }

    pub fn exposure_source(&self) -> ExposureSource {
        tslg_client::wire::stored_exposure(&self.exposure_name, self.exposure_table.as_ref())
    }

    pub fn exposure_request(&self) -> ExposureRequest {
        tslg_client::wire::exposure_request(self.exposure_source())
    }

    /// `n (rₙ/β)²` valid tests, at least `n_min`, once the prefix has
    /// `min_events` events (and at least 2); see [`crate::lease_size`].
    fn predicted_tests(&self, rule: &StoppingRule, point: &HistoryPoint) -> Option<u64> {
        let r = point.relative_half_width?;
        let needed =
            predicted_unleased(point.tests, point.events, rule.min_events, r, rule.beta, 0)?;
        Some(needed.max(rule.n_min).max(point.tests))
    }

    pub fn view(&self) -> CampaignView {
        let rule = self.rule();
        let fold = self.fold();
        let point = point(&fold, rule.z());
        let has_events = self.events > 0;
        let started = self.indices > 0;
        let summary = CampaignResult::with_outside_upper(
            Decision::Continue,
            &fold,
            rule.z(),
            self.outside_upper,
        );
        CampaignView {
            id: self.id,
            case: self.case_name.clone(),
            method: self.method,
            library_id: self.library_id,
            vut: serde_json::from_str(&self.vut).unwrap_or_default(),
            epsilon: self.epsilon,
            outside: self.outside,
            split: self.split,
            beta: self.beta,
            confidence: self.confidence,
            n_min: rule.n_min,
            min_events: rule.min_events,
            max_tests: rule.max_tests,
            seed: self.seed(),
            status: self.status,
            status_detail: self.status_detail.clone(),
            tests: self.tests as u64,
            events: self.events as u64,
            invalid: self.invalid as u64,
            indices: self.indices as u64,
            leased: self.next_index as u64,
            worker_seconds: self.worker_seconds,
            estimate: started.then_some(point.estimate),
            half_width: (self.tests > 1).then_some(point.half_width),
            relative_half_width: point.relative_half_width,
            ci_low: (self.tests > 1).then_some(point.ci_low),
            ci_high: (self.tests > 1).then_some(point.ci_high),
            // A campaign of a pair stops with its pair, not at its own β.
            predicted_tests: self.predicted_tests(&self.fold_rule(), &point),
            effective_events: has_events.then(|| fold.estimator.effective_events()),
            largest_weight_share: fold.estimator.largest_share(),
            guard_outside: self.guard_outside,
            outside_tests: summary.outside_tests,
            outside_events: summary.outside_events,
            mismatched_events: summary.mismatched_events,
            outside_share: summary.outside_share,
            outside_upper: summary.outside_upper,
            guarded_ci_high: summary.guarded_ci_high.filter(|_| self.tests > 1),
            exact_probability: self.exact_probability,
            adaptive: (self.method == Method::Adaptive).then(|| AdaptiveView {
                library_tests: self.library_tests as u64,
                search_tests: self.search_tests as u64,
                stages: self.stages as u64,
                running: match (self.stage_start, self.stage_end, &self.stage_kind) {
                    (Some(start), Some(end), Some(kind)) if !self.status.is_final() => {
                        Some(RunningStage {
                            kind: kind.clone(),
                            start: start as u64,
                            end: end as u64,
                        })
                    }
                    _ => None,
                },
                support: self.support as u64,
            }),
            warnings: if self.tests > 1 {
                let found = warnings(
                    &summary,
                    WarningContext {
                        beta: self.beta,
                        guard_outside: self.guard_outside,
                        dialect: Dialect::Api,
                        unexplored: self.method == Method::Library && self.epsilon == 0.0,
                    },
                );
                match self.paired_with {
                    // The guard is the remedy the warnings give, and a
                    // pair takes none.
                    Some(_) => found
                        .into_iter()
                        .map(|w| w.replace("Rerun with ", PAIRED_RERUN))
                        .collect(),
                    None => found,
                }
            } else {
                Vec::new()
            },
            tests_per_second: None,
            seconds_left: None,
            audits: None,
            pair: None,
            created_at: self.created_at.clone(),
            updated_at: self.updated_at.clone(),
        }
    }
}

/// A campaign's audit counts from `(state, count)` rows, with what they
/// mean for its user in words.
pub fn audit_counts(row: &CampaignRow, states: &[(AuditState, i64)]) -> (AuditCounts, Vec<String>) {
    let count = |state: AuditState| {
        states
            .iter()
            .filter(|(s, _)| *s == state)
            .map(|(_, n)| *n as u64)
            .sum::<u64>()
    };
    let counts = AuditCounts {
        open: count(AuditState::Replica) + count(AuditState::Tiebreak),
        agreed: count(AuditState::Agreed),
        settled: count(AuditState::Settled),
        undecided: count(AuditState::Undecided),
        void: count(AuditState::Void),
        waived: row.audits_waived as u64,
    };
    let program = row
        .requires
        .as_deref()
        .and_then(|r| r.split(':').next())
        .unwrap_or("the program");
    let mut warnings = Vec::new();
    if counts.waived > 0 {
        warnings.push(format!(
            "{} tests chosen for an audit were not run again: no other worker offering \
             `{program}` was live; run two or more workers offering it to have them checked",
            counts.waived
        ));
    }
    if counts.open > 0 && !row.status.is_final() {
        warnings.push(format!(
            "{} tests wait to be run again by another worker offering `{program}`; the estimate \
             stops at the first of them until they are",
            counts.open
        ));
    }
    if counts.undecided > 0 {
        warnings.push(format!(
            "{} audited tests got three different outcomes from three workers: is `{program}` \
             deterministic for a given test?",
            counts.undecided
        ));
    }
    (counts, warnings)
}

/// The estimate, interval and relative half-width of a prefix.
pub fn point(fold: &PrefixFold, z: f64) -> HistoryPoint {
    let e = &fold.estimator;
    let (ci_low, ci_high) = fold.interval(z);
    let r = fold.relative_half_width(z);
    HistoryPoint {
        tests: e.tests(),
        indices: fold.indices,
        events: e.events(),
        estimate: fold.estimate(),
        half_width: if e.tests() > 0 {
            fold.half_width(z)
        } else {
            0.0
        },
        relative_half_width: r.is_finite().then_some(r),
        ci_low: if e.tests() > 0 { ci_low } else { 0.0 },
        ci_high: if e.tests() > 0 { ci_high } else { 0.0 },
    }
}

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
    /// An adaptive campaign's first stage: its tests `start..end` and kind.
    pub first_stage: Option<(u64, u64, &'static str)>,
}

pub fn insert(conn: &Connection, new: &NewCampaign) -> Result<CampaignRow, StoreError> {
    let sql = format!(
        "INSERT INTO campaigns (case_name, preset, method, library_id, exposure_name, \
         exposure_fingerprint, exposure_table, vut, requires, epsilon, outside, beta, confidence, \
         n_min, min_events, max_tests, seed, status, guard_outside, exact_probability, split, \
         adaptive, stage_start, stage_end, stage_kind, enumerate) \
         VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?) \
         RETURNING {COLUMNS}"
    );
    let adaptive = new.method == Method::Adaptive;
    let enumerate = match new.method {
        Method::Enumerate => 1,
        Method::Build => 2,
        _ => 0,
    };
    let stored_method = match new.method {
        Method::Adaptive => Method::Library,
        Method::Enumerate | Method::Build => Method::Ndd,
        other => other,
    };
    let first_stage = new.first_stage.as_ref();
    Ok(sql::one(
        conn,
        &sql,
        params![
            new.case_name,
            new.preset,
            stored_method.as_str(),
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
            adaptive,
            first_stage.map(|s| s.0 as i64),
            first_stage.map(|s| s.1 as i64),
            first_stage.map(|s| s.2),
            enumerate,
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
        "UPDATE campaigns SET status = 'cancelled', status_detail = 'cancelled on request', \
         updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now') WHERE id = ?",
        [id],
    )?;
    crate::store::leases::cancel_active(conn, id)?;
    get(conn, id)
}

/// The persisted history of a campaign's prefix estimate (thinned as
/// [`crate::history`] says), ending at the campaign's current prefix: at
/// most `max` points, logarithmically spaced in tests.
pub fn history(
    conn: &Connection,
    row: &CampaignRow,
    max: usize,
) -> Result<Vec<HistoryPoint>, StoreError> {
    let rows: Vec<(i64, i64, i64, f64, f64, i64, f64)> = sql::all(
        conn,
        "SELECT indices, tests, events, s1, s2, outside_tests, outside_s1 FROM history \
         WHERE campaign_id = ? ORDER BY indices",
        [row.id],
    )?;
    let z = row.rule().z();
    let mut points: Vec<HistoryPoint> = rows
        .into_iter()
        .map(
            |(indices, tests, events, s1, s2, outside_tests, outside_s1)| {
                let fold = PrefixFold {
                    estimator: ImportanceEstimator::from_sums(tests as u64, events as u64, s1, s2),
                    indices: indices as u64,
                    invalid: (indices - tests) as u64,
                    outside: OutsideTally {
                        tests: outside_tests as u64,
                        s1: outside_s1,
                        ..OutsideTally::default()
                    },
                    strata: row.strata_epsilon,
                };
                point(&fold, z)
            },
        )
        .collect();
    let current = row.fold();
    if current.indices > points.last().map_or(0, |p| p.indices) {
        points.push(point(&current, z));
    }
    Ok(crate::history::log_downsample(points, max))
}
