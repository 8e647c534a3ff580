//! Database access, one module per table family. Every write runs on the
//! single writer connection ([`crate::db::Database::write`]).

pub mod campaigns;
pub mod leases;
pub mod libraries;
pub mod results;

use tslg_method::registry::ExposureSource;

/// The exposure a library or campaign row was made with: its uploaded
/// table, or the case's built-in model when it has none.
pub fn exposure_source(name: &str, table: Option<&String>) -> ExposureSource {
    match table {
        None => ExposureSource::Builtin,
        Some(text) => ExposureSource::Table {
            name: name.to_owned(),
            text: text.clone(),
        },
    }
}
