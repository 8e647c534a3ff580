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

/// The `NAME.k` tried past the count of those issued, before registration
/// gives up (names a client registered directly, out of turn).
const MAX_TRIES: u32 = 100;

/// The credential of `name`, if one was issued.
pub fn get(conn: &Connection, name: &str) -> Result<Option<CredentialRow>, StoreError> {
    Ok(sql::optional(
        conn,
        "SELECT name, secret_hash, issued_at, revoked_at FROM worker_credentials WHERE name = ?",
        [name],
    )?)
}

/// Issues a credential under `requested`, or under the next `requested.k`
/// (k = 2, 3, …) never issued: a name belongs to one credential for good.
/// `k` starts past the count of `requested.*` issued, so a registration
/// costs a count and an insert or two, however often the name was taken.
/// `None` when [`MAX_TRIES`] names past that are all taken.
pub fn issue(
    conn: &Connection,
    requested: &str,
    secret_hash: &str,
) -> Result<Option<CredentialRow>, StoreError> {
    let insert = |name: &str| -> Result<bool, StoreError> {
        Ok(sql::execute(
            conn,
            "INSERT OR IGNORE INTO worker_credentials (name, secret_hash) VALUES (?1, ?2)",
            params![name, secret_hash],
        )? == 1)
    };
    if insert(requested)? {
        return get(conn, requested);
    }
    // `requested.` up to (not including) `requested/`: '/' follows '.'.
    let (taken,): (i64,) = sql::one(
        conn,
        "SELECT COUNT(*) FROM worker_credentials WHERE name > ?1 || '.' AND name < ?1 || '/'",
        [requested],
    )?;
    for k in (taken as u32 + 2..).take(MAX_TRIES as usize) {
        let name = format!("{requested}.{k}");
        if insert(&name)? {
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
