//! Wire types of the tslg HTTP API (`/api/v1`), shared by the coordinator,
//! the worker and clients. Plain serde types and nothing else; the
//! coordinator validates every field and answers errors as [`Problem`]s.
//!
//! Vehicle and surrogate specifications travel as JSON objects
//! (`{"model": "idm", ...}`, see `docs/models.md`) and are validated by the
//! case they are used with.

mod campaign;
mod campaign_kind;
mod case;
mod events;
mod lease;
mod library;
mod method;
pub mod packed;
mod pair;
mod queue;
mod stages;
mod timeline;
mod worker;

pub use campaign::*;
pub use campaign_kind::*;
pub use case::*;
pub use events::*;
pub use lease::*;
pub use library::*;
pub use method::*;
pub use pair::*;
pub use queue::*;
pub use stages::*;
pub use timeline::*;
pub use worker::*;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// An error, as `application/problem+json` (RFC 9457).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Problem {
    /// A URI naming the kind of problem (`about:blank` for plain HTTP errors).
    #[serde(rename = "type")]
    pub kind: String,
    /// The HTTP reason phrase or a short summary.
    pub title: String,
    /// The HTTP status code.
    pub status: u16,
    /// What exactly is wrong with this request.
    pub detail: String,
}

/// `GET /healthz`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Health {
    /// `ok` when the database answers.
    pub status: String,
    /// The coordinator's version (its crate version).
    pub version: String,
}
