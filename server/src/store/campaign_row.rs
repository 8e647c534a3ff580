//! A campaign's row: its columns, what they mean to the method (the
//! stopping rule, the persisted prefix fold, the exposure), and reading it
//! by position.
//!
//! The writer reads a campaign's row twice for every report that takes the
//! next lease (the report's campaign, then the campaign the claim picks):
//! through `serde` by column name, matching each of its 51 columns against
//! the struct's field names, that was a tenth of the writer's time under
//! load (`perf`, docs/benchmarks.md). [`first`] reads the columns of
//! [`COLUMNS`] by their position instead; a test checks both readings give
//! the same row.

use crate::store::error::StoreError;
use rusqlite::types::FromSql;
use rusqlite::{Connection, Params, Row};
use serde::de::{DeserializeOwned, IntoDeserializer};
use tslg_api::{AdaptiveSearch, CampaignStatus, ExposureRequest, Method, Outside, Split};
use tslg_method::estimator::{ImportanceEstimator, Interval, StoppingRule};
use tslg_method::outside::OutsideTally;
use tslg_method::prefix::PrefixFold;
use tslg_method::registry::ExposureSource;

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
    /// `S₂,out`; NULL on campaigns created before it was tracked
    /// (migrations/…27_outside_s2.sql), which keep the pooled variance.
    pub outside_s2: Option<f64>,
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
    /// See `store::campaigns::NewCampaign::parameters_inert`.
    pub parameters_inert: Option<bool>,
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
    /// Its program is not bit-reproducible: audits compare by statistics
    /// (`report/noisy.rs`).
    pub vehicle_noise: bool,
    /// The interval the rule reads (`wald`, `anytime`).
    pub interval: String,
    /// An anytime campaign's confidence sequence as of its last fold.
    pub sequence_low: Option<f64>,
    pub sequence_high: Option<f64>,
    /// The test from which nearly every test explores, once the campaign
    /// switched (`tslg_method::sampling::allocated_explores`).
    pub explore_from: Option<i64>,
    /// How an adaptive campaign searches (`grid`, `lattice`).
    pub adaptive_search: AdaptiveSearch,
    /// An adaptive campaign's estimation stages' length.
    pub stage_tests: i64,
    /// An adaptive campaign's search width (0: one ring a search stage).
    pub search_width: i64,
    pub created_at: String,
    pub updated_at: String,
}

/// The columns a campaign is read with, in [`from_row`]'s order. The
/// method is its name (`tslg_api::Method::as_str`, one column since
/// migrations/…37_method_column.sql).
pub const COLUMNS: &str = "id, case_name, preset, method, library_id, exposure_name, \
    exposure_fingerprint, exposure_table, vut, requires, epsilon, outside, split, strata_epsilon, \
    beta, confidence, n_min, min_events, max_tests, seed, status, status_detail, next_index, indices, tests, events, invalid, s1, s2, \
    largest, guard_outside, outside_tests, outside_events, outside_s1, outside_upper, \
    outside_mismatches, \
    cost_per_test, worker_seconds, audits_waived, reported_s1, exact_probability, \
    stage_start, stage_end, stage_kind, library_tests, search_tests, stages, support, paired_with, created_at, \
    updated_at, vehicle_noise, interval, sequence_low, sequence_high, explore_from, outside_s2, parameters_inert, \
    adaptive_search, stage_tests, search_width";

/// The names of the methods `keep` keeps, as an SQL list (`('enumerate',
/// 'build')`) for `method IN …`: queries ask the method's spec instead of
/// naming methods. Never empty (`('')` matches no campaign).
pub fn methods_where(keep: impl Fn(tslg_api::MethodSpec) -> bool) -> String {
    let names: Vec<String> = Method::ALL
        .into_iter()
        .filter(|m| keep(m.spec()))
        .map(|m| format!("'{}'", m.as_str()))
        .collect();
    if names.is_empty() {
        "('')".into()
    } else {
        format!("({})", names.join(", "))
    }
}

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
            interval: self.interval(),
        }
    }

    /// The interval its rule reads; a name this build does not know reads
    /// as `wald` (none is written but by [`crate::store::campaigns::insert`]).
    pub fn interval(&self) -> Interval {
        self.interval.parse().unwrap_or_default()
    }

    /// The switch, as the campaign's tests take it.
    pub fn explore_from(&self) -> Option<u64> {
        self.explore_from.map(|from| from as u64)
    }

    /// An anytime campaign's confidence sequence `[low, high]` as of its
    /// last fold; `None` for a Wald campaign and before its first fold.
    pub fn sequence(&self) -> Option<(f64, f64)> {
        (self.interval() == Interval::Anytime)
            .then(|| self.sequence_low.zip(self.sequence_high))
            .flatten()
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
                s2: self.outside_s2.unwrap_or(0.0),
                mismatches: self.outside_mismatches as u64,
            },
            strata: self.strata_epsilon,
            within_strata: self.strata_epsilon.is_some() && self.tracks_within_strata(),
        }
    }

    /// Whether a stratified fold of this campaign reads the within-strata
    /// variance ([`PrefixFold::within_strata`]): a guarded Wald campaign
    /// that tracked `S₂,out` from its start.
    pub fn tracks_within_strata(&self) -> bool {
        self.guard_outside && self.interval() == Interval::Wald && self.outside_s2.is_some()
    }

    pub fn exposure_source(&self) -> ExposureSource {
        tslg_client::wire::stored_exposure(&self.exposure_name, self.exposure_table.as_ref())
    }

    pub fn exposure_request(&self) -> ExposureRequest {
        tslg_client::wire::exposure_request(self.exposure_source())
    }
}

/// The first row of `sql`, a `SELECT` of [`COLUMNS`] (the prefix of its
/// column list), if any.
pub fn first(
    conn: &Connection,
    sql: &str,
    params: impl Params,
) -> Result<Option<CampaignRow>, StoreError> {
    let mut statement = conn.prepare_cached(sql)?;
    let mut rows = statement.query(params)?;
    match rows.next()? {
        Some(row) => Ok(Some(from_row(row)?)),
        None => Ok(None),
    }
}

/// Column `i` of `row`, a text naming a value of `T` (a kebab-case enum).
fn named<T: DeserializeOwned>(row: &Row<'_>, i: usize) -> rusqlite::Result<T> {
    let text: String = row.get(i)?;
    let value: Result<T, serde::de::value::Error> =
        T::deserialize(text.as_str().into_deserializer());
    value.map_err(|e| {
        rusqlite::Error::FromSqlConversionFailure(
            i,
            rusqlite::types::Type::Text,
            format!("`{text}`: {e}").into(),
        )
    })
}

/// Column `i` of `row`.
fn at<T: FromSql>(row: &Row<'_>, i: usize) -> rusqlite::Result<T> {
    row.get(i)
}

/// A row of `SELECT {COLUMNS}`, by position (the order of [`COLUMNS`]).
fn from_row(row: &Row<'_>) -> rusqlite::Result<CampaignRow> {
    Ok(CampaignRow {
        id: at(row, 0)?,
        case_name: at(row, 1)?,
        preset: at(row, 2)?,
        method: named(row, 3)?,
        library_id: at(row, 4)?,
        exposure_name: at(row, 5)?,
        exposure_fingerprint: at(row, 6)?,
        exposure_table: at(row, 7)?,
        vut: at(row, 8)?,
        requires: at(row, 9)?,
        epsilon: at(row, 10)?,
        outside: named(row, 11)?,
        split: named(row, 12)?,
        strata_epsilon: at(row, 13)?,
        beta: at(row, 14)?,
        confidence: at(row, 15)?,
        n_min: at(row, 16)?,
        min_events: at(row, 17)?,
        max_tests: at(row, 18)?,
        seed: at(row, 19)?,
        status: named(row, 20)?,
        status_detail: at(row, 21)?,
        next_index: at(row, 22)?,
        indices: at(row, 23)?,
        tests: at(row, 24)?,
        events: at(row, 25)?,
        invalid: at(row, 26)?,
        s1: at(row, 27)?,
        s2: at(row, 28)?,
        largest: at(row, 29)?,
        guard_outside: at(row, 30)?,
        outside_tests: at(row, 31)?,
        outside_events: at(row, 32)?,
        outside_s1: at(row, 33)?,
        outside_upper: at(row, 34)?,
        outside_mismatches: at(row, 35)?,
        cost_per_test: at(row, 36)?,
        worker_seconds: at(row, 37)?,
        audits_waived: at(row, 38)?,
        reported_s1: at(row, 39)?,
        exact_probability: at(row, 40)?,
        stage_start: at(row, 41)?,
        stage_end: at(row, 42)?,
        stage_kind: at(row, 43)?,
        library_tests: at(row, 44)?,
        search_tests: at(row, 45)?,
        stages: at(row, 46)?,
        support: at(row, 47)?,
        paired_with: at(row, 48)?,
        created_at: at(row, 49)?,
        updated_at: at(row, 50)?,
        vehicle_noise: at(row, 51)?,
        interval: at(row, 52)?,
        sequence_low: at(row, 53)?,
        sequence_high: at(row, 54)?,
        explore_from: at(row, 55)?,
        outside_s2: at(row, 56)?,
        parameters_inert: at(row, 57)?,
        adaptive_search: named(row, 58)?,
        stage_tests: at(row, 59)?,
        search_width: at(row, 60)?,
    })
}

/// The number of columns [`from_row`] reads.
#[cfg(test)]
const READ: usize = 61;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::db::{sql, Database, Durability};

    /// Every column of [`COLUMNS`], in order, as the positional reader
    /// takes them: a column added to the list without the reader (or in
    /// another place) fails here.
    #[tokio::test]
    async fn the_positional_reader_reads_what_serde_reads_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let url = format!("sqlite://{}", dir.path().join("db.sqlite").display());
        let db = Database::open(&url, Durability::Full).await.unwrap();
        let (by_name, by_position, count) = db
            .write(|conn| -> Result<_, StoreError> {
                conn.execute_batch(
                    "INSERT INTO campaigns (case_name, preset, method, exposure_name, \
                     exposure_fingerprint, vut, epsilon, beta, confidence, n_min, min_events, \
                     max_tests, seed, status, next_index, requires, exposure_table, \
                     strata_epsilon, cost_per_test, guard_outside, outside, split, \
                     stage_start, stage_end, stage_kind, exact_probability, outside_upper, \
                     status_detail, adaptive_search) \
                     VALUES ('cut-in', 'paper-code', 'adaptive', 'builtin', 'fp', \
                     '{\"model\":\"idm\"}', 0.1, 0.05, 0.9, 100, 10, 1000000, 7, 'running', \
                     300, 'py:cut-in:step', 'table', 0.1, 2.5e-7, 1, 'ndd', 'stratified', 0, \
                     4096, 'search', 9.3e-4, 1e-5, 'why', 'lattice')",
                )?;
                let text = format!("SELECT {COLUMNS} FROM campaigns");
                let by_name: CampaignRow = sql::one(conn, &text, [])?;
                let by_position = first(conn, &text, [])?.expect("a row");
                let count = conn.prepare(&text)?.column_count();
                Ok((by_name, by_position, count))
            })
            .await
            .unwrap();
        assert_eq!(format!("{by_position:?}"), format!("{by_name:?}"));
        assert_eq!(count, READ);
        assert_eq!(by_position.method, tslg_api::Method::Adaptive);
        assert_eq!(by_position.split, tslg_api::Split::Stratified);
        assert_eq!(
            by_position.adaptive_search,
            tslg_api::AdaptiveSearch::Lattice
        );
    }

    /// A database of the release before, whose adaptive campaigns were
    /// stored as 'library' with `adaptive = 1` and whose builds as 'ndd'
    /// with `enumerate` 1 or 2, reads every campaign as the method it is
    /// once the one-column migration ran, and then takes a method's name
    /// the old CHECK refused.
    #[test]
    fn the_method_column_migration_keeps_every_campaign_s_method() {
        let dir = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../migrations"));
        let mut files: Vec<_> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|x| x == "sql"))
            .collect();
        files.sort();
        let (before, after): (Vec<_>, Vec<_>) = files
            .iter()
            .partition(|p| p.file_name().unwrap().to_string_lossy().as_ref() < "20261207000037");
        assert!(after[0].ends_with("20261207000037_method_column.sql"));
        let conn = Connection::open_in_memory().unwrap();
        conn.execute_batch("PRAGMA foreign_keys = ON").unwrap();
        for file in &before {
            conn.execute_batch(&std::fs::read_to_string(file).unwrap())
                .unwrap();
        }
        let stored = [
            ("library", 0, 0, Method::Library),
            ("ndd", 0, 0, Method::Ndd),
            ("library", 1, 0, Method::Adaptive),
            ("ndd", 0, 1, Method::Enumerate),
            ("ndd", 0, 2, Method::Build),
        ];
        for (method, adaptive, enumerate, _) in stored {
            conn.execute(
                "INSERT INTO campaigns (case_name, preset, method, exposure_name, \
                 exposure_fingerprint, vut, epsilon, beta, confidence, n_min, min_events, \
                 max_tests, seed, status, adaptive, enumerate) VALUES ('cut-in', 'paper-code', \
                 ?, 'builtin', 'fp', '{}', 0.1, 0.2, 0.9, 100, 10, 1000, 7, 'running', ?, ?)",
                rusqlite::params![method, adaptive, enumerate],
            )
            .unwrap();
        }
        for file in &after {
            conn.execute_batch(&std::fs::read_to_string(file).unwrap())
                .unwrap();
        }
        let text = format!("SELECT {COLUMNS} FROM campaigns ORDER BY id");
        let rows: Vec<CampaignRow> = conn
            .prepare(&text)
            .unwrap()
            .query_map([], from_row)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        let read: Vec<Method> = rows.iter().map(|r| r.method).collect();
        assert_eq!(read, stored.map(|s| s.3));
        // The builds are found by the spec's list, as the store asks.
        let builds: i64 = conn
            .query_row(
                &format!(
                    "SELECT COUNT(*) FROM campaigns WHERE method IN {}",
                    methods_where(|m| m.builds.is_some())
                ),
                [],
                |r| r.get(0),
            )
            .unwrap();
        assert_eq!(builds, 2);
        assert_eq!(methods_where(|_| false), "('')");
        // No CHECK holds the names any more: a new method needs no
        // migration (the service refuses a name it does not know on read).
        conn.execute("UPDATE campaigns SET method = 'adaptive' WHERE id = 1", [])
            .unwrap();
        conn.execute("UPDATE campaigns SET method = 'lattice' WHERE id = 2", [])
            .unwrap();
        let unknown = conn.query_row(
            &format!("SELECT {COLUMNS} FROM campaigns WHERE id = 2"),
            [],
            from_row,
        );
        assert!(unknown.is_err(), "an unknown method must not read as one");
    }
}
