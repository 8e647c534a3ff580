//! Handing out work: which lease a worker's request gets (an expired one,
//! an audit's run, or a new range of the campaign whose turn comes first:
//! [`claim`]), how many tests it holds ([`size`]), and who may keep,
//! report on or give back a lease ([`fence`]); a request checked
//! ([`request`]) and granted as the lease the worker gets ([`grant`]). The
//! rows are in `store/leases.rs`.

pub mod claim;
pub mod fence;
pub mod grant;
pub mod request;
pub mod size;
