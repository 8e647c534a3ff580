//! A library build as a service asks for it and gets it back: the request
//! (threshold and search, the case's defaults where left out), the built
//! file with its summary, and what a library file holds.

use crate::library::{LibrarySearch, Threshold};

/// A build request; what is `None` takes the case's default.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BuildRequest {
    /// The criticality threshold; the case's default when `None`.
    pub threshold: Option<Threshold>,
    /// The search or solver; the case's default when `None`.
    pub search: Option<LibrarySearch>,
}

/// A built library: its file in the case's format and its summary.
#[derive(Debug, Clone, PartialEq)]
pub struct BuiltLibrary {
    /// The library file's bytes.
    pub file: Vec<u8>,
    /// The file's media type (JSON for grid cases, binary for car-following).
    pub media_type: &'static str,
    /// `N(Φ)`: library cells, or states with `P(S|s) > 0`.
    pub size: usize,
    /// Surrogate simulations the search used.
    pub sm_evaluations: usize,
    /// `μ_S = Σ_x V(x)`: the surrogate's event rate under the exposure (exact for exhaustive search, a lower bound otherwise).
    pub mu_s: f64,
    /// `W`: the criticality mass inside the library.
    pub w: f64,
}

/// What a library file holds, as `tslg library show` prints it.
#[derive(Debug, Clone, PartialEq)]
pub struct LibrarySummary {
    /// The case and preset it was built for.
    pub case: String,
    /// The case's preset.
    pub preset: String,
    /// The surrogate, as its specification.
    pub surrogate: serde_json::Value,
    /// The exposure's name and fingerprint.
    pub exposure: crate::library::ExposureRef,
    /// `N(Φ)`: its cells or states.
    pub size: usize,
    /// `N(X)`: the case's scenarios (grid cells or states).
    pub total: usize,
    /// `μ_S`.
    pub mu_s: f64,
    /// `W = Σ_{x∈Φ} V(x)`.
    pub w: f64,
    /// The threshold γ (grid cases).
    pub gamma: Option<f64>,
    /// How it was searched or learned, in words.
    pub search: String,
    /// Surrogate simulations the search used.
    pub sm_evaluations: usize,
    /// The share of the exhaustive library's criticality a multistart
    /// search found, when measured.
    pub recall: Option<f64>,
}
