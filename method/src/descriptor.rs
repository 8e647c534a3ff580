//! The description of a case ([`CaseDescriptor`]): everything the service
//! and the command line need to know about it, so that nothing outside the
//! case's own folder (`crate::cases`) matches on its name.

use crate::library::{LibrarySearch, Threshold};
use crate::sampling::OutsideSpread;

/// One of a case's simulation presets.
#[derive(Debug, Clone, PartialEq)]
pub struct Preset {
    /// The name requests and commands use.
    pub name: &'static str,
    /// What it sets, in a sentence.
    pub summary: &'static str,
}

/// How a case's tests get their scenarios.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scenarios {
    /// A grid cell and its weight are drawn before the test runs: a lease
    /// can list them, libraries are sets of cells, exact answers come by
    /// enumeration, adaptive campaigns search cells.
    Grid,
    /// Drawn decision by decision while the test runs (car-following): a
    /// lease cannot list them, and exploration happens in every decision.
    Sequential,
}

/// An exposure table format a case accepts in place of its built-in model.
#[derive(Debug, Clone, PartialEq)]
pub struct TableFormat {
    /// What the table holds, e.g. `P(R, Ṙ)`.
    pub holds: &'static str,
    /// Where its layout is documented.
    pub doc: &'static str,
}

/// Pairings of `tslg validate`: each (surrogate, vehicle under test) with an
/// exact answer by enumeration, and the preset of a quick run.
#[derive(Debug, Clone, PartialEq)]
pub struct Validation {
    /// `(surrogate, vehicle)` pairs, the matched ones first.
    pub pairs: Vec<(&'static str, &'static str)>,
    /// The preset `--quick` runs on (a coarser grid), if any.
    pub quick_preset: Option<&'static str>,
}

/// The paper's own figures for a case (Part II, Section IV).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperFigures {
    /// Scenarios in the paper's library, when it gives them.
    pub library_size: Option<u64>,
    /// The paper's library tests to β.
    pub library_tests: f64,
    /// The paper's NDD tests to β.
    pub ndd_tests: f64,
}

/// A case as the paper ran it (`tslg reproduce`), and the vehicles tested
/// with its library.
#[derive(Debug, Clone, PartialEq)]
pub struct Reproduction {
    /// The paper's preset.
    pub preset: &'static str,
    /// The paper's surrogate.
    pub surrogate: &'static str,
    /// The search that gives the paper's library.
    pub search: LibrarySearch,
    /// The paper's ε.
    pub epsilon: f64,
    /// The paper's β.
    pub beta: f64,
    /// `(label, specification)` of the vehicles tested.
    pub vehicles: Vec<(&'static str, serde_json::Value)>,
    /// Whether a `--ndd-table` given to the command applies to this case.
    pub takes_table: bool,
    /// The paper's figures.
    pub paper: PaperFigures,
}

/// Everything the service and the command line know about a case.
#[derive(Debug, Clone, PartialEq)]
pub struct CaseDescriptor {
    /// The name requests and commands use.
    pub name: &'static str,
    /// What the case tests, in a sentence or two (help texts, `GET
    /// /api/v1/cases`).
    pub summary: &'static str,
    /// Its presets; the first is the default.
    pub presets: Vec<Preset>,
    /// Its built-in vehicles.
    pub vehicles: Vec<&'static str>,
    /// The surrogate a library uses when none is named.
    pub default_surrogate: &'static str,
    /// The library search when none is named.
    pub default_search: LibrarySearch,
    /// Starting points of a multistart search that does not say (grid
    /// cases).
    pub multistart_starts: usize,
    /// The library threshold when none is named (grid cases).
    pub default_threshold: Option<Threshold>,
    /// Grid cells or sequential scenarios.
    pub scenarios: Scenarios,
    /// What a library's size counts (`scenarios`, `states`).
    pub scenario_unit: &'static str,
    /// What a library build's progress counts.
    pub build_unit: &'static str,
    /// The exposure tables it accepts besides its built-in model.
    pub tables: Vec<TableFormat>,
    /// How a library campaign spreads ε when the request does not say.
    pub default_outside: OutsideSpread,
    /// The library picture's axes, `[x, y]`.
    pub picture_axes: [&'static str; 2],
    /// A vehicle the demo tests when none is named, one that is not the
    /// surrogate (as a user's never is); `None`: the surrogate.
    pub demo_vut: Option<&'static str>,
    /// What `tslg validate` runs (grid cases with exact answers).
    pub validation: Option<Validation>,
    /// What `tslg reproduce` runs (the paper's cases).
    pub reproduction: Option<Reproduction>,
}

impl CaseDescriptor {
    /// The default preset's name.
    pub fn default_preset(&self) -> &'static str {
        self.presets[0].name
    }

    /// Whether its tests draw grid cells before they run.
    pub fn is_grid(&self) -> bool {
        self.scenarios == Scenarios::Grid
    }

    /// The probability that one test of a campaign explores outside the
    /// library: ε for a library campaign of a grid case, `None` for the
    /// NDD and for sequential cases (which explore in every decision). It
    /// sets the default `n_min` ([`crate::estimator::default_n_min`]).
    pub fn exploring_share(&self, library: bool, epsilon: f64) -> Option<f64> {
        (library && self.is_grid()).then_some(epsilon)
    }

    /// Whether an exposure table may replace its built-in model.
    pub fn takes_tables(&self) -> bool {
        !self.tables.is_empty()
    }
}
