//! Handing out work: which lease a worker's request gets (an expired one,
//! an audit's run, or a new range of the campaign whose turn comes first:
//! [`claim`]), how many tests it holds ([`size`]), and who may keep,
//! report on or give back a lease ([`fence`]), what giving an audit's run
//! back costs a worker ([`dodging`]); a request checked
//! ([`request`]) and granted as the lease the worker gets ([`grant`]). The
//! rows are in `store/leases.rs`.

pub mod claim;
pub mod dodging;
pub mod fence;
pub mod grant;
pub mod request;
pub mod size;
