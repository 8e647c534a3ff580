//! A worker's identity: it registers under the fleet's worker token and
//! gets a secret of its own, which every request naming it presents in the
//! [`WORKER_SECRET_HEADER`] header (docs/api.md, worker identity).

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// The header that carries a worker's secret on every request that names
/// it (lease requests, heartbeats, releases, reports, library uploads).
pub const WORKER_SECRET_HEADER: &str = "tslg-worker-secret";

/// `POST /api/v1/workers`: the name a worker asks for.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct WorkerRegistration {
    /// 1 to 120 printable characters. A name is issued once: when it was
    /// issued before, the worker gets the first free `NAME.k` (k = 2, 3, …).
    pub name: String,
    /// An enrolment secret an administrator issued (`POST
    /// /api/v1/enrolments`): the worker belongs to its principal. Required
    /// when the coordinator runs with `--enrolment required`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub enrolment: Option<String>,
}

/// A worker's credential, as issued (the secret is shown this once).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
pub struct WorkerCredential {
    /// The name issued: the one asked for, or `NAME.k` when it was taken.
    /// Every request of the worker names it.
    pub name: String,
    /// The secret (64 hex digits) to send in the `tslg-worker-secret`
    /// header. The coordinator keeps only its SHA-256.
    pub secret: String,
    /// When the credential was issued (RFC 3339, UTC).
    pub issued_at: String,
    /// The principal it enrolled under, if it gave an enrolment.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub principal: Option<String>,
}

/// `POST /api/v1/enrolments` (admin): an enrolment credential for a
/// principal (a host, an operator, a cluster job).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct EnrolmentRequest {
    /// 1 to 120 characters: letters, digits, `.`, `-` and `_`.
    pub principal: String,
}

/// An enrolment credential, as issued (the secret is shown this once).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
pub struct Enrolment {
    /// The principal, as asked for.
    pub principal: String,
    /// The secret (64 hex digits) a worker of the principal registers with
    /// (`WorkerRegistration::enrolment`). The coordinator keeps only its
    /// SHA-256.
    pub secret: String,
    /// When it was issued (RFC 3339, UTC).
    pub issued_at: String,
}
