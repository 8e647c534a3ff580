//! Worker identities. A worker registers under the fleet's worker token and
//! gets a secret of its own (256 bits from the operating system); every
//! request that names a worker must present that worker's secret, so the
//! shared token no longer lets one worker act as another: claim leases in
//! its name, report on them, and have it flagged. Names are issued once
//! (`store/credentials.rs`), so a flag, which is keyed by name, attaches to
//! one credential.
//!
//! The coordinator keeps SHA-256(secret), compared in constant time; the
//! credentials it has checked are kept in memory, so a request costs one
//! hash and no read.

use crate::db::Database;
use crate::error::ServiceError;
use crate::store::credentials::{self, CredentialRow};
use crate::store::enrolments;
use sha2::{Digest, Sha256};
use std::collections::HashMap;
use std::sync::Mutex;
use subtle::ConstantTimeEq;
use tslg_api::{WorkerCredential, WORKER_SECRET_HEADER};

/// The longest name a worker may ask for, leaving room for a `.k` suffix
/// within the 128 bytes a worker's name may have.
pub const MAX_REQUESTED_NAME: usize = 120;

/// Credentials kept in memory at most (a cache of the table: past it, it
/// starts again empty).
const MAX_KEPT: usize = 100_000;

/// The credentials checked so far, by name.
#[derive(Default)]
pub struct Credentials {
    known: Mutex<HashMap<String, CredentialRow>>,
    /// `--enrolment required`: a credential issued without an enrolment
    /// (before the switch) is refused too.
    enrolment_required: bool,
}

/// The principal an enrolment secret (its hash, `None`: none given)
/// enrols under: refused (403) when it is not one an administrator issued,
/// was revoked, or its principal is flagged (registering again does not
/// shed a flag), and when none is given where `required`.
fn principal_of_enrolment(
    conn: &rusqlite::Connection,
    hash: Option<&str>,
    required: bool,
) -> Result<Option<String>, ServiceError> {
    let refuse = |why: String| Err(ServiceError::Forbidden(why));
    let Some(hash) = hash else {
        if required {
            return refuse(
                "this coordinator admits enrolled workers only (--enrolment required): ask an \
                 administrator for an enrolment credential (POST /api/v1/enrolments, or `tslg \
                 worker enrol PRINCIPAL`) and start the worker with --enrolment-file or \
                 TSLG_ENROLMENT_SECRET"
                    .into(),
            );
        }
        return Ok(None);
    };
    let Some((principal, revoked)) = enrolments::by_secret(conn, hash)? else {
        return refuse("the enrolment credential given is not one an administrator issued".into());
    };
    if let Some(at) = revoked {
        return refuse(format!(
            "the enrolment of principal `{principal}` was revoked at {at}"
        ));
    }
    if let Some(reason) = enrolments::flag_of(conn, &principal)? {
        return refuse(format!(
            "principal `{principal}` is flagged ({reason}); registering again does not shed a \
             flag: an operator clears it with DELETE /api/v1/workers/NAME/flag"
        ));
    }
    Ok(Some(principal))
}

/// Hex SHA-256 of a secret.
pub fn digest(secret: &str) -> String {
    Sha256::digest(secret.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

impl Credentials {
    /// No credentials checked yet; `enrolment_required` as the
    /// coordinator's `--enrolment required`.
    pub fn new(enrolment_required: bool) -> Self {
        Self {
            known: Mutex::default(),
            enrolment_required,
        }
    }

    /// Issues a credential for a worker asking for `requested` (checked by
    /// the caller): the name itself when it was never issued, else the
    /// first free `requested.k`.
    pub async fn register(
        &self,
        db: &Database,
        requested: &str,
        (enrolment, required): (Option<&str>, bool),
    ) -> Result<WorkerCredential, ServiceError> {
        let enrolment_hash = enrolment.map(digest);
        let secret = format!(
            "{:032x}{:032x}",
            rand::random::<u128>(),
            rand::random::<u128>()
        );
        let hash = digest(&secret);
        let asked = requested.to_owned();
        let row = db
            .write(move |conn| {
                let principal = principal_of_enrolment(conn, enrolment_hash.as_deref(), required)?;
                Ok::<_, ServiceError>(credentials::issue(
                    conn,
                    &asked,
                    &hash,
                    principal.as_deref(),
                )?)
            })
            .await?
            .ok_or_else(|| {
                ServiceError::Conflict(format!(
                    "worker name `{requested}` and the numbered names after it are issued; \
                     ask for another name"
                ))
            })?;
        let issued = WorkerCredential {
            name: row.name.clone(),
            secret,
            issued_at: row.issued_at.clone(),
            principal: row.principal.clone(),
        };
        self.remember(row);
        Ok(issued)
    }

    /// Admits a request naming `worker` when `secret` is its credential's
    /// (403 otherwise: no secret, another worker's, an unknown name or a
    /// revoked credential).
    pub async fn verify(
        &self,
        db: &Database,
        worker: &str,
        secret: Option<&str>,
    ) -> Result<(), ServiceError> {
        // Bound first: a guard in the match's scrutinee would be held over
        // the read below.
        let kept = self.lock().get(worker).cloned();
        let row = match kept {
            Some(row) => Some(row),
            None => {
                let name = worker.to_owned();
                let row = db.read(move |conn| credentials::get(conn, &name)).await?;
                if let Some(row) = &row {
                    self.remember(row.clone());
                }
                row
            }
        };
        let refuse = |why: String| Err(ServiceError::Forbidden(why));
        let Some(row) = row else {
            return refuse(format!(
                "worker `{worker}` is not registered: a worker registers with POST \
                 /api/v1/workers and sends its secret in the `{WORKER_SECRET_HEADER}` header"
            ));
        };
        if let Some(at) = &row.revoked_at {
            return refuse(format!(
                "worker `{worker}`'s credential was revoked at {at}: it gets no work"
            ));
        }
        if self.enrolment_required && row.principal.is_none() {
            return refuse(format!(
                "worker `{worker}` registered without an enrolment, and this coordinator now \
                 admits enrolled workers only (--enrolment required): register again with an \
                 enrolment credential (a new credential file)"
            ));
        }
        if worker.starts_with('@') {
            // Registered before `@` was kept for principals.
            return refuse(format!(
                "worker `{worker}`: names beginning with `@` name principals now; register \
                 under another name"
            ));
        }
        let Some(secret) = secret else {
            return refuse(format!(
                "a request naming worker `{worker}` must carry its secret in the \
                 `{WORKER_SECRET_HEADER}` header"
            ));
        };
        let given = digest(secret);
        if !bool::from(given.as_bytes().ct_eq(row.secret_hash.as_bytes())) {
            return refuse(format!(
                "the `{WORKER_SECRET_HEADER}` given is not worker `{worker}`'s: a worker acts \
                 only in its own name"
            ));
        }
        Ok(())
    }

    /// Revokes `worker`'s credential and expires its active leases (each is
    /// handed out again to another worker); false when it has none or it
    /// was revoked already. Its results stay: revoking is not a flag.
    pub async fn revoke(&self, db: &Database, worker: &str) -> Result<bool, ServiceError> {
        let name = worker.to_owned();
        let (revoked, row) = db
            .write(move |conn| {
                let revoked = credentials::revoke(conn, &name)?;
                if revoked {
                    crate::store::leases::expire_all_of(conn, &name)?;
                }
                Ok::<_, ServiceError>((revoked, credentials::get(conn, &name)?))
            })
            .await?;
        if let Some(row) = row {
            self.remember(row);
        }
        Ok(revoked)
    }

    /// When `worker`'s credential was issued and revoked, and the principal
    /// it enrolled under, as far as this process has seen it.
    pub fn dates(&self, worker: &str) -> (Option<String>, Option<String>, Option<String>) {
        self.lock()
            .get(worker)
            .map(|row| {
                let principal = row.principal.clone();
                (
                    Some(row.issued_at.clone()),
                    row.revoked_at.clone(),
                    principal,
                )
            })
            .unwrap_or_default()
    }

    /// Keeps `row`, unless a revoked row of the same name is kept: a read
    /// that began before a revocation must not bring the credential back.
    fn remember(&self, row: CredentialRow) {
        let mut known = self.lock();
        if known
            .get(&row.name)
            .is_some_and(|kept| kept.revoked_at.is_some() && row.revoked_at.is_none())
        {
            return;
        }
        if known.len() >= MAX_KEPT {
            known.clear();
        }
        known.insert(row.name.clone(), row);
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<String, CredentialRow>> {
        self.known.lock().unwrap_or_else(|p| p.into_inner())
    }
}
