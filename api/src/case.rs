//! The cases a coordinator runs (`GET /api/v1/cases`): each case's
//! descriptor as the wire carries it.

use crate::{Outside, SearchRequest};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// One of a case's simulation presets.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct PresetView {
    /// The name requests use.
    pub name: String,
    /// What it sets.
    pub summary: String,
}

/// An exposure table format a case accepts in place of its built-in model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct TableView {
    /// What the table holds.
    pub holds: String,
    /// Where its layout is documented.
    pub doc: String,
}

/// How a case's tests get their scenarios.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "kebab-case")]
pub enum ScenarioKind {
    /// A grid cell and its weight are drawn before the test runs.
    Grid,
    /// Drawn decision by decision while the test runs.
    Sequential,
}

/// Everything a client needs to know about a case.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct CaseView {
    /// The name requests use (`case`).
    pub name: String,
    /// What it tests.
    pub summary: String,
    /// Its presets; the first is the default.
    pub presets: Vec<PresetView>,
    /// Its built-in vehicles (`{"model": NAME}`).
    pub vehicles: Vec<String>,
    /// The surrogate of a library request that names none.
    pub default_surrogate: String,
    /// The search of a library request that names none.
    pub default_search: SearchRequest,
    /// Grid cells or sequential scenarios.
    pub scenarios: ScenarioKind,
    /// What a library's size counts.
    pub scenario_unit: String,
    /// Exposure tables it accepts besides its built-in model (none: only
    /// its built-in model).
    pub tables: Vec<TableView>,
    /// How a library campaign spreads ε when the request does not say.
    pub default_outside: Outside,
    /// The library picture's axes, `[x, y]`.
    pub picture_axes: [String; 2],
    /// Whether campaigns get the exact P(A) by enumeration (grid cases of
    /// at most [`crate::EXACT_MAX_SCENARIOS`] scenarios).
    pub exact_answers: bool,
    /// Whether the service runs its adaptive campaigns.
    pub adaptive: bool,
    /// Whether a user defined it (`POST /api/v1/cases`).
    #[serde(default)]
    pub user_defined: bool,
}

/// A user-defined grid case (`POST /api/v1/cases`): its case file and its
/// exposure table, as text (docs/bring-your-own.md).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CreateCase {
    /// The case file (TOML).
    pub file: String,
    /// The exposure table the file names (CSV: one column per dimension,
    /// then `probability`).
    pub table: String,
    /// The table's name; the file's `exposure` when left out.
    #[serde(default)]
    pub table_name: Option<String>,
}

/// A user-defined case's definition as a campaign's plan carries it to the
/// workers, which register it before they open the case.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
pub struct UserCaseDefinition {
    /// The case file (TOML).
    pub file: String,
    /// The exposure table's name.
    pub table_name: String,
    /// The exposure table (CSV).
    pub table: String,
}
