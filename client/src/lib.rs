//! What talks to a tslg coordinator: the HTTP client of its API
//! ([`http`], feature `http`, used by the worker and the `tslg` command)
//! and the conversions between the API's wire types and the method's
//! ([`wire`], used by all three, the coordinator included), each written
//! once.

#[cfg(feature = "http")]
pub mod http;
pub mod wire;

#[cfg(feature = "http")]
pub use http::{CallError, Client};
