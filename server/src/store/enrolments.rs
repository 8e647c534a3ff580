//! The `enrolments` table: the enrolment credentials an administrator
//! issued, one per principal (the SHA-256 of the secret); and whether a
//! principal is flagged (`flagged_principals`, which a flag of one of its
//! workers sets: `store/audits.rs`).

use crate::db::sql;
use crate::store::error::StoreError;
use rusqlite::{params, Connection};

/// Issues principal `principal` an enrolment with secret hash `hash`;
/// `None` when the principal has one already. The time it was issued.
pub fn issue(conn: &Connection, principal: &str, hash: &str) -> Result<Option<String>, StoreError> {
    let inserted = sql::execute(
        conn,
        "INSERT OR IGNORE INTO enrolments (principal, secret_hash) VALUES (?, ?)",
        params![principal, hash],
    )? == 1;
    if !inserted {
        return Ok(None);
    }
    let (at,): (String,) = sql::one(
        conn,
        "SELECT issued_at FROM enrolments WHERE principal = ?",
        [principal],
    )?;
    Ok(Some(at))
}

/// The principal whose enrolment secret hashes to `hash`, and when it was
/// revoked (if it was).
pub fn by_secret(
    conn: &Connection,
    hash: &str,
) -> Result<Option<(String, Option<String>)>, StoreError> {
    Ok(sql::optional(
        conn,
        "SELECT principal, revoked_at FROM enrolments WHERE secret_hash = ?",
        [hash],
    )?)
}

/// Revokes `principal`'s enrolment: no worker registers with it any more;
/// false when there is none in force.
pub fn revoke(conn: &Connection, principal: &str) -> Result<bool, StoreError> {
    Ok(sql::execute(
        conn,
        "UPDATE enrolments SET revoked_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now') \
         WHERE principal = ? AND revoked_at IS NULL",
        [principal],
    )? == 1)
}

/// Why `principal` is flagged, if it is.
pub fn flag_of(conn: &Connection, principal: &str) -> Result<Option<String>, StoreError> {
    let row: Option<(String,)> = sql::optional(
        conn,
        "SELECT reason FROM flagged_principals WHERE principal = ?",
        [principal],
    )?;
    Ok(row.map(|(reason,)| reason))
}
