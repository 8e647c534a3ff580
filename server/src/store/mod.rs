//! Database access, one module per table family. Every write runs on the
//! single writer connection ([`crate::db::Database::write`]).

pub mod adaptive_stages;
pub mod audits;
pub mod campaign_row;
pub mod campaigns;
pub mod costs;
pub mod credentials;
pub mod deletion;
pub mod discordance;
pub mod enrolments;
pub mod error;
pub mod leases;
pub mod libraries;
pub mod near_misses;
pub mod pairs;
pub mod prefix;
pub mod reports;
pub mod standing;
pub mod states;
pub mod test_pairing_walks;
pub mod totals;
pub mod user_cases;
pub mod work_spans;
