//! The `worker_credentials` table: each worker's name, the SHA-256 of its
//! secret, when it was issued and, once an operator revoked it, when.

use crate::db::sql;
use crate::store::error::StoreError;
use rusqlite::{params, Connection};
use serde::Deserialize;

/// A stored credential.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct CredentialRow {
    pub name: String,
    /// Hex SHA-256 of the secret.
    pub secret_hash: String,
    pub issued_at: String,
    pub revoked_at: Option<String>,
}

/// The most `NAME.k` a name is tried with before registration gives up.
const MAX_SUFFIX: u32 = 10_000;

/// The credential of `name`, if one was issued.
pub fn get(conn: &Connection, name: &str) -> Result<Option<CredentialRow>, StoreError> {
    Ok(sql::optional(
        conn,
        "SELECT name, secret_hash, issued_at, revoked_at FROM worker_credentials WHERE name = ?",
        [name],
    )?)
}

/// Issues a credential under `requested`, or under the first `requested.k`
/// (k = 2, 3, …) never issued: a name belongs to one credential for good.
/// `None` when every suffix up to [`MAX_SUFFIX`] is taken.
pub fn issue(
    conn: &Connection,
    requested: &str,
    secret_hash: &str,
) -> Result<Option<CredentialRow>, StoreError> {
    let candidates = std::iter::once(requested.to_owned())
        .chain((2..=MAX_SUFFIX).map(|k| format!("{requested}.{k}")));
    for name in candidates {
        let inserted = sql::execute(
            conn,
            "INSERT OR IGNORE INTO worker_credentials (name, secret_hash) VALUES (?1, ?2)",
            params![name, secret_hash],
        )?;
        if inserted == 1 {
            return get(conn, &name);
        }
    }
    Ok(None)
}

/// Marks `name`'s credential revoked; false when there is none or it was
/// revoked already.
pub fn revoke(conn: &Connection, name: &str) -> Result<bool, StoreError> {
    Ok(sql::execute(
        conn,
        "UPDATE worker_credentials SET revoked_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now') \
         WHERE name = ? AND revoked_at IS NULL",
        [name],
    )? == 1)
}
