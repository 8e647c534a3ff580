//! Reading a campaign's row by position.
//!
//! The writer reads a campaign's row twice for every report that takes the
//! next lease (the report's campaign, then the campaign the claim picks):
//! through `serde` by column name, matching each of its 51 columns against
//! the struct's field names, that was a tenth of the writer's time under
//! load (`perf`, docs/benchmarks.md). [`first`] reads the columns of
//! [`COLUMNS`](super::campaigns::COLUMNS) by their position instead; a test checks both readings give
//! the same row.

use super::campaigns::CampaignRow;
use crate::store::error::StoreError;
use rusqlite::types::FromSql;
use rusqlite::{Connection, Params, Row};
use serde::de::{DeserializeOwned, IntoDeserializer};

/// The first row of `sql`, a `SELECT` of [`COLUMNS`](super::campaigns::COLUMNS) (the prefix of its
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

/// A row of `SELECT {COLUMNS}`, by position (the order of [`COLUMNS`](super::campaigns::COLUMNS)).
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
    })
}

/// The number of columns [`from_row`] reads.
#[cfg(test)]
const READ: usize = 51;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::db::{sql, Database, Durability};
    use crate::store::campaigns::COLUMNS;

    /// Every column of [`COLUMNS`](super::campaigns::COLUMNS), in order, as the positional reader
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
                     strata_epsilon, cost_per_test, guard_outside, outside, split, adaptive, \
                     stage_start, stage_end, stage_kind, exact_probability, outside_upper, \
                     status_detail) \
                     VALUES ('cut-in', 'paper-code', 'library', 'builtin', 'fp', \
                     '{\"model\":\"idm\"}', 0.1, 0.05, 0.9, 100, 10, 1000000, 7, 'running', \
                     300, 'py:cut-in:step', 'table', 0.1, 2.5e-7, 1, 'ndd', 'stratified', 1, 0, \
                     4096, 'search', 9.3e-4, 1e-5, 'why')",
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
    }
}
