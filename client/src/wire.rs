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

/// The interval a campaign reads, from the wire.
pub fn interval(kind: tslg_api::IntervalKind) -> tslg_method::estimator::Interval {
    match kind {
        tslg_api::IntervalKind::Wald => tslg_method::estimator::Interval::Wald,
        tslg_api::IntervalKind::Anytime => tslg_method::estimator::Interval::Anytime,
    }
}

/// Whether a campaign runs under the guard: as the request says, else by
/// default when its vehicle is noisy and the guard applies to it (a grid
/// case's library or adaptive campaign, not paired, on the Wald interval):
/// a noisy vehicle's support is never shown complete by a few runs, so its
/// answer is the guarded one ([`tslg_method::noise::guards_by_default`]).
pub fn guard_outside(req: &tslg_api::CreateCampaign, grid_case: bool) -> bool {
    req.guard_outside.unwrap_or_else(|| {
        tslg_method::noise::guards_by_default(
            req.vehicle_noise || tslg_method::noise::spec_is_noisy(&req.vut),
            grid_case
                && req.method.spec().explores
                && req.paired_with.is_none()
                && req.interval == tslg_api::IntervalKind::Wald,
        )
    })
}

/// The interval a campaign reads, for the wire.
pub fn wire_interval(interval: tslg_method::estimator::Interval) -> tslg_api::IntervalKind {
    match interval {
        tslg_method::estimator::Interval::Wald => tslg_api::IntervalKind::Wald,
        tslg_method::estimator::Interval::Anytime => tslg_api::IntervalKind::Anytime,
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

/// An adaptive campaign's settings: the defaults, with the vehicle's noise,
/// the search the request names, and its stage length (which sets the
/// search's width, [`tslg_method::adaptive::AdaptiveSettings::fleet_search_width`]).
pub fn adaptive_settings(
    noisy: bool,
    search: tslg_api::AdaptiveSearch,
    stage_tests: u64,
) -> tslg_method::adaptive::AdaptiveSettings {
    tslg_method::adaptive::AdaptiveSettings {
        noisy,
        lattice: search == tslg_api::AdaptiveSearch::Lattice,
        stage_tests,
        search_width: tslg_method::adaptive::AdaptiveSettings::fleet_search_width(stage_tests),
        ..Default::default()
    }
}

/// The wire form of a library search.
pub fn search_request(search: tslg_method::library::LibrarySearch) -> tslg_api::SearchRequest {
    use tslg_api::SearchRequest;
    use tslg_method::library::{LibrarySearch, PolicySolver, SearchMethod};
    match search {
        LibrarySearch::Cells(SearchMethod::Exhaustive) => SearchRequest::Exhaustive,
        LibrarySearch::Cells(SearchMethod::Multistart { starts, seed }) => {
            SearchRequest::Multistart { starts, seed }
        }
        LibrarySearch::Policy(PolicySolver::DynamicProgramming) => {
            SearchRequest::DynamicProgramming
        }
        LibrarySearch::Policy(PolicySolver::TemporalDifference { alpha, seed }) => {
            SearchRequest::TemporalDifference { alpha, seed }
        }
    }
}

/// A library search from its wire form.
pub fn library_search(search: tslg_api::SearchRequest) -> tslg_method::library::LibrarySearch {
    use tslg_api::SearchRequest;
    use tslg_method::library::{LibrarySearch, PolicySolver, SearchMethod};
    match search {
        SearchRequest::Exhaustive => LibrarySearch::Cells(SearchMethod::Exhaustive),
        SearchRequest::Multistart { starts, seed } => {
            LibrarySearch::Cells(SearchMethod::Multistart { starts, seed })
        }
        SearchRequest::DynamicProgramming => {
            LibrarySearch::Policy(PolicySolver::DynamicProgramming)
        }
        SearchRequest::TemporalDifference { alpha, seed } => {
            LibrarySearch::Policy(PolicySolver::TemporalDifference { alpha, seed })
        }
    }
}

/// The wire form of a library threshold.
pub fn threshold_request(threshold: tslg_method::library::Threshold) -> tslg_api::ThresholdRequest {
    use tslg_api::ThresholdRequest;
    use tslg_method::library::Threshold;
    match threshold {
        Threshold::Relative { m } => ThresholdRequest::Relative { m },
        Threshold::Absolute { gamma } => ThresholdRequest::Absolute { gamma },
    }
}

/// A library threshold from its wire form.
pub fn threshold(threshold: tslg_api::ThresholdRequest) -> tslg_method::library::Threshold {
    use tslg_api::ThresholdRequest;
    use tslg_method::library::Threshold;
    match threshold {
        ThresholdRequest::Relative { m } => Threshold::Relative { m },
        ThresholdRequest::Absolute { gamma } => Threshold::Absolute { gamma },
    }
}

/// The wire form of a case's descriptor.
pub fn case_view(case: &tslg_method::cases::CaseDescriptor) -> tslg_api::CaseView {
    use tslg_api::{CaseView, PresetView, ScenarioKind, TableView};
    CaseView {
        name: case.name.to_owned(),
        summary: case.summary.to_owned(),
        presets: case
            .presets
            .iter()
            .map(|p| PresetView {
                name: p.name.to_owned(),
                summary: p.summary.to_owned(),
            })
            .collect(),
        vehicles: case.vehicles.iter().map(|v| (*v).to_owned()).collect(),
        default_surrogate: case.default_surrogate.to_owned(),
        default_search: search_request(case.default_search),
        scenarios: if case.is_grid() {
            ScenarioKind::Grid
        } else {
            ScenarioKind::Sequential
        },
        scenario_unit: case.scenario_unit.to_owned(),
        tables: case
            .tables
            .iter()
            .map(|t| TableView {
                holds: t.holds.to_owned(),
                doc: t.doc.to_owned(),
            })
            .collect(),
        default_outside: outside(case.default_outside),
        picture_axes: case.picture_axes.map(str::to_owned),
        exact_answers: case.is_grid(),
        adaptive: case.is_grid(),
        user_defined: tslg_method::cases::user::registry::get(case.name).is_some(),
    }
}

/// A user-defined case's definition from its wire form.
pub fn user_case_definition(
    d: &tslg_api::UserCaseDefinition,
) -> tslg_method::cases::user::registry::UserCaseDefinition {
    tslg_method::cases::user::registry::UserCaseDefinition {
        file: d.file.clone(),
        table_name: d.table_name.clone(),
        table: d.table.clone(),
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
