//! The API's wire types ↔ the method's types. The API crate knows nothing
//! of the method and the method nothing of the API; these are the only
//! places where one becomes the other.

use tslg_api::{ExposureRequest, Outside};
use tslg_method::registry::ExposureSource;
use tslg_method::sampling::OutsideSpread;

/// The method's exposure source of a request's exposure.
pub fn exposure_source(exposure: &ExposureRequest) -> ExposureSource {
    match exposure {
        ExposureRequest::Builtin => ExposureSource::Builtin,
        ExposureRequest::Table { name, text } => ExposureSource::Table {
            name: name.clone(),
            text: text.clone(),
        },
    }
}

/// The request form of an exposure source.
pub fn exposure_request(source: ExposureSource) -> ExposureRequest {
    match source {
        ExposureSource::Builtin => ExposureRequest::Builtin,
        ExposureSource::Table { name, text } => ExposureRequest::Table { name, text },
    }
}

/// The exposure a stored row was made with: its table, or the case's
/// built-in model when it has none.
pub fn stored_exposure(name: &str, table: Option<&String>) -> ExposureSource {
    match table {
        None => ExposureSource::Builtin,
        Some(text) => ExposureSource::Table {
            name: name.to_owned(),
            text: text.clone(),
        },
    }
}

/// The method's spread of ε.
pub fn outside_spread(outside: Outside) -> OutsideSpread {
    match outside {
        Outside::Uniform => OutsideSpread::Uniform,
        Outside::Ndd => OutsideSpread::Ndd,
    }
}

/// The method's split of a wire split.
pub fn split(split: tslg_api::Split) -> tslg_method::sampling::Split {
    match split {
        tslg_api::Split::Stratified => tslg_method::sampling::Split::Stratified,
        tslg_api::Split::Random => tslg_method::sampling::Split::Random,
    }
}

/// The wire form of a split.
pub fn wire_split(split: tslg_method::sampling::Split) -> tslg_api::Split {
    match split {
        tslg_method::sampling::Split::Stratified => tslg_api::Split::Stratified,
        tslg_method::sampling::Split::Random => tslg_api::Split::Random,
    }
}

/// The wire form of a spread of ε.
pub fn outside(spread: OutsideSpread) -> Outside {
    match spread {
        OutsideSpread::Uniform => Outside::Uniform,
        OutsideSpread::Ndd => Outside::Ndd,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversions_round_trip() {
        for o in [Outside::Uniform, Outside::Ndd] {
            assert_eq!(outside(outside_spread(o)), o);
        }
        let table = ExposureRequest::Table {
            name: "t.csv".into(),
            text: "1,2,3".into(),
        };
        assert_eq!(exposure_request(exposure_source(&table)), table);
        assert_eq!(
            exposure_request(exposure_source(&ExposureRequest::Builtin)),
            ExposureRequest::Builtin
        );
        assert_eq!(
            stored_exposure("t.csv", Some(&"1,2,3".to_owned())),
            exposure_source(&table)
        );
    }
}
