//! The store's few ways of running a statement: rows into `serde` types by
//! column name (a struct's fields) or by position (a tuple), through each
//! connection's cache of prepared statements, errors as [`DbError`].

use super::error::DbError;
use rusqlite::{Connection, Params, Statement};
use serde::de::DeserializeOwned;
use std::cell::RefCell;
use std::collections::HashMap;
use std::rc::Rc;

/// Every row of `sql`.
pub fn all<T: DeserializeOwned>(
    conn: &Connection,
    sql: &str,
    params: impl Params,
) -> Result<Vec<T>, DbError> {
    rows(conn, sql, params, usize::MAX)
}

/// The first row of `sql`, if any.
pub fn optional<T: DeserializeOwned>(
    conn: &Connection,
    sql: &str,
    params: impl Params,
) -> Result<Option<T>, DbError> {
    Ok(rows(conn, sql, params, 1)?.pop())
}

/// The first `most` rows of `sql`.
fn rows<T: DeserializeOwned>(
    conn: &Connection,
    sql: &str,
    params: impl Params,
    most: usize,
) -> Result<Vec<T>, DbError> {
    let mut statement = conn.prepare_cached(sql)?;
    let columns = columns_of(sql, &statement);
    let mut rows = statement.query(params)?;
    let mut out = Vec::new();
    while out.len() < most {
        let Some(row) = rows.next()? else { break };
        out.push(serde_rusqlite::from_row_with_columns(row, &columns)?);
    }
    Ok(out)
}

thread_local! {
    /// The column names of each statement this thread ran, by its SQL: a
    /// campaign's row has 53 columns, whose names would otherwise be
    /// copied into new strings at every read.
    static COLUMNS: RefCell<HashMap<String, Rc<[String]>>> = RefCell::default();
}

/// The column names of `statement`, prepared from `sql`.
fn columns_of(sql: &str, statement: &Statement<'_>) -> Rc<[String]> {
    COLUMNS.with(|known| {
        if let Some(columns) = known.borrow().get(sql) {
            return Rc::clone(columns);
        }
        let columns: Rc<[String]> = serde_rusqlite::columns_from_statement(statement).into();
        known
            .borrow_mut()
            .insert(sql.to_owned(), Rc::clone(&columns));
        columns
    })
}

/// The first row of `sql`, which must have one.
pub fn one<T: DeserializeOwned>(
    conn: &Connection,
    sql: &str,
    params: impl Params,
) -> Result<T, DbError> {
    optional(conn, sql, params)?
        .ok_or_else(|| DbError::new(format!("a statement returned no row: {sql}")))
}

/// Runs `sql`; the rows it changed.
pub fn execute(conn: &Connection, sql: &str, params: impl Params) -> Result<usize, DbError> {
    Ok(conn.prepare_cached(sql)?.execute(params)?)
}

/// Whether the connection answers a statement.
pub fn ping(conn: &Connection) -> Result<(), DbError> {
    conn.query_row("SELECT 1", [], |_| Ok(()))?;
    Ok(())
}

/// A real write for `/healthz`: the probe row's time set to now (its
/// commit is the writer's, as every write's).
pub fn probe_write(conn: &Connection) -> Result<(), DbError> {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs() as i64);
    conn.execute("UPDATE health_probe SET at = ?1 WHERE id = 1", [now])?;
    Ok(())
}
