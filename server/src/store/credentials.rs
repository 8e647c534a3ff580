//! The `worker_credentials` table: each worker's name, the SHA-256 of its
//! secret, when it was issued and, once an operator revoked it, when; and
//! the principal it enrolled under, if any (a worker registered with the
//! shared worker token alone is its own principal).

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
    /// The principal it enrolled under (`None`: its own).
    pub principal: Option<String>,
}

/// The `NAME.k` tried past the count of those issued, before registration
/// gives up (names a client registered directly, out of turn).
const MAX_TRIES: u32 = 100;

/// The credential of `name`, if one was issued.
pub fn get(conn: &Connection, name: &str) -> Result<Option<CredentialRow>, StoreError> {
    Ok(sql::optional(
        conn,
        "SELECT name, secret_hash, issued_at, revoked_at, principal FROM worker_credentials \
         WHERE name = ?",
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
    principal: Option<&str>,
) -> Result<Option<CredentialRow>, StoreError> {
    let insert = |name: &str| -> Result<bool, StoreError> {
        Ok(sql::execute(
            conn,
            "INSERT OR IGNORE INTO worker_credentials (name, secret_hash, principal) \
             VALUES (?1, ?2, ?3)",
            params![name, secret_hash, principal],
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

/// SQL for the principal of the worker named by the expression `name`:
/// `@` and the principal it enrolled under, else its own name (names do not
/// begin with `@`, so the two never meet).
pub fn principal_sql(name: &str) -> String {
    format!(
        "COALESCE((SELECT '@' || principal FROM worker_credentials WHERE name = {name}), {name})"
    )
}

/// The principal of worker `name`: `@` and the principal it enrolled
/// under, else its own name (also when it is unknown).
pub fn principal_of(conn: &Connection, name: &str) -> Result<String, StoreError> {
    let (principal,): (String,) =
        sql::one(conn, &format!("SELECT {}", principal_sql("?1")), [name])?;
    Ok(principal)
}

/// The workers of principal `principal` (as [`principal_of`] gives it):
/// those enrolled under it, or the worker itself.
pub fn names_of(conn: &Connection, principal: &str) -> Result<Vec<String>, StoreError> {
    let Some(enrolled) = principal.strip_prefix('@') else {
        return Ok(vec![principal.to_owned()]);
    };
    let rows: Vec<(String,)> = sql::all(
        conn,
        "SELECT name FROM worker_credentials WHERE principal = ? ORDER BY name",
        [enrolled],
    )?;
    Ok(rows.into_iter().map(|(name,)| name).collect())
}
