//! A campaign method's one home: its name on the wire and in the database,
//! what its answer rests on, how it uses a library, how far its leases
//! reach and what its view counts. Everything outside that depends on the
//! method asks its [`MethodSpec`] here instead of naming variants, so a new
//! method is a variant and its spec in this file, its sampler in
//! `tslg-method`, and the few files docs/architecture.md ("Adding a
//! campaign method") lists.
//!
//! The database stores the name ([`Method::as_str`]) in one column,
//! `campaigns.method` (migrations/…37_method_column.sql), read back by its
//! serde name, which is that name (a test holds them equal): a new method
//! needs no migration. The command line's
//! `--method` offers [`Method::requestable`], so it needs no edit either.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// How tests are drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// From the library with ε-greedy exploration, importance-weighted.
    Library,
    /// From the naturalistic distribution itself (the baseline), weight 1.
    Ndd,
    /// In stages that learn where this vehicle fails: the library's tests,
    /// a search around the failures and near misses they meet, then
    /// estimation on the failures found (grid cases; docs/statistics.md,
    /// "Adaptive campaigns").
    Adaptive,
    /// A library build's surrogate runs, which the coordinator leases to
    /// workers as tests: test `i` runs the surrogate on the `i`-th cell
    /// with exposure (`build_of` names the library). Created by the
    /// coordinator for a build whose surrogate is a program, not by
    /// clients.
    Enumerate,
    /// A library build that one worker runs whole (a multistart search, a
    /// car-following policy): its one test is the build, and the worker
    /// uploads the library to `POST /api/v1/leases/{id}/library`
    /// (`build_search` and `build_threshold` in the plan say how to build
    /// it). Created by the coordinator, not by clients.
    Build,
}

/// How far a campaign's leases may reach past the tests already resolved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LeaseReach {
    /// To the tests its stopping rule predicts it still needs (the rest
    /// would be run only to be thrown away).
    Predicted,
    /// To the end of the running stage: the next is planned from its
    /// results.
    Stage,
    /// To its last test: a build runs every test it has.
    All,
}

/// What a library-build method does on workers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BuildWork {
    /// Test `i` runs the surrogate on the `i`-th cell with exposure.
    Cells,
    /// One worker runs the whole build as the campaign's one test.
    Whole,
}

/// Everything a method decides, in one place.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MethodSpec {
    /// Its name on the wire, in the database and on the command line.
    pub name: &'static str,
    /// How it draws its tests, in a line (the command line's help).
    pub summary: &'static str,
    /// What its interval rests on, in one line (docs/statistics.md, "What
    /// each answer assumes").
    pub rests_on: &'static str,
    /// Whether a client may ask for it (the others are a library build's,
    /// created by the coordinator).
    pub requestable: bool,
    /// Whether it draws from a library (a campaign waits for its build).
    pub uses_library: bool,
    /// Whether ε of its tests explore outside the library, so a guard has
    /// an outside to bound.
    pub explores: bool,
    /// Whether its default `n_min` waits for ten exploring tests
    /// (`tslg_method::estimator::default_n_min`): a library campaign's
    /// exploring tests are what can show its vehicle failing outside the
    /// library; an adaptive campaign's search does that before it estimates.
    pub waits_for_explorers: bool,
    /// Whether it reads a confidence sequence (interval `anytime`) when
    /// asked: its tests' weights have a known largest value to bet against.
    pub anytime: bool,
    /// Whether the coordinator plans its tests in stages from the results
    /// of the stage before (leases list their tests; only the estimation
    /// stages' tests enter the estimate).
    pub in_stages: bool,
    /// Whether two vehicles can run it on the same scenarios (a paired
    /// campaign): its tests do not depend on the vehicle's results.
    pub pairs: bool,
    /// A library build's work, for the methods that are one (no estimate).
    pub builds: Option<BuildWork>,
    /// How far its leases reach.
    pub lease_reach: LeaseReach,
    /// What its estimate's tests are called on a page or a plot.
    pub tests_axis: &'static str,
}

/// What every library build's method shares: no estimate, so nothing to
/// explore, stage, pair or read as a sequence, and every test run.
const LIBRARY_BUILD: MethodSpec = MethodSpec {
    name: "",
    summary: "",
    rests_on: "",
    requestable: false,
    uses_library: false,
    explores: false,
    waits_for_explorers: false,
    anytime: false,
    in_stages: false,
    pairs: false,
    builds: None,
    lease_reach: LeaseReach::All,
    tests_axis: "tests",
};

impl Method {
    /// Every method, in the order they were added.
    pub const ALL: [Method; 5] = [
        Method::Library,
        Method::Ndd,
        Method::Adaptive,
        Method::Enumerate,
        Method::Build,
    ];

    /// What the method decides (the table above, one row per method).
    pub const fn spec(self) -> MethodSpec {
        match self {
            Method::Library => MethodSpec {
                name: "library",
                summary: "from the library with ε-greedy exploration, importance-weighted",
                rests_on: "the library holds the vehicle's failures: the surrogate fails where \
                           it does",
                requestable: true,
                uses_library: true,
                explores: true,
                waits_for_explorers: true,
                anytime: true,
                in_stages: false,
                pairs: true,
                builds: None,
                lease_reach: LeaseReach::Predicted,
                tests_axis: "tests",
            },
            Method::Ndd => MethodSpec {
                name: "ndd",
                summary: "from the naturalistic distribution itself (the baseline), weight 1",
                rests_on: "nothing beyond the exposure model: every scenario sampled as it occurs",
                requestable: true,
                uses_library: false,
                explores: false,
                waits_for_explorers: false,
                anytime: true,
                in_stages: false,
                pairs: true,
                builds: None,
                lease_reach: LeaseReach::Predicted,
                tests_axis: "tests",
            },
            Method::Adaptive => MethodSpec {
                name: "adaptive",
                summary: "in stages that learn where this vehicle fails: the library's tests, a \
                          search around the failures and near misses they meet, estimation on \
                          the failures found (grid cases)",
                rests_on: "the vehicle's failures outside the library are reachable through \
                           failures and near misses from what its tests met",
                requestable: true,
                uses_library: true,
                explores: true,
                waits_for_explorers: false,
                anytime: false,
                in_stages: true,
                pairs: false,
                builds: None,
                lease_reach: LeaseReach::Stage,
                tests_axis: "estimation tests",
            },
            Method::Enumerate => MethodSpec {
                name: "enumerate",
                summary: "a library build's surrogate on every cell with exposure, in cell order",
                rests_on: "no estimate: a library build's surrogate runs, every scenario once",
                builds: Some(BuildWork::Cells),
                ..LIBRARY_BUILD
            },
            Method::Build => MethodSpec {
                name: "build",
                summary: "a library build one worker runs whole",
                rests_on: "no estimate: a library built whole on one worker",
                builds: Some(BuildWork::Whole),
                ..LIBRARY_BUILD
            },
        }
    }

    /// The method's name on the wire and in the database (`library`, `ndd`).
    pub const fn as_str(self) -> &'static str {
        self.spec().name
    }

    /// The method named `name`, if one is.
    pub fn parse(name: &str) -> Option<Self> {
        Method::ALL.into_iter().find(|m| m.as_str() == name)
    }

    /// The methods a client may ask for (`library`, `ndd`, `adaptive`).
    pub fn requestable() -> impl Iterator<Item = Method> {
        Method::ALL.into_iter().filter(|m| m.spec().requestable)
    }

    /// Whether the campaign draws from a library (`library`, `adaptive`).
    pub const fn uses_library(self) -> bool {
        self.spec().uses_library
    }

    /// Whether the coordinator plans its tests in stages (`adaptive`).
    pub const fn in_stages(self) -> bool {
        self.spec().in_stages
    }

    /// Whether it is a library build's work rather than an estimate.
    pub const fn builds_library(self) -> bool {
        self.spec().builds.is_some()
    }

    /// Whether its tests are independent draws of one proposal, fixed by
    /// the seed before any result (not planned in stages from results, not
    /// a build's cells in order): what pairing tests across workers and
    /// two vehicles sharing scenarios rest on.
    pub const fn draws_independently(self) -> bool {
        !self.spec().in_stages && self.spec().builds.is_none()
    }

    /// Whether the coordinator finds which of its tests explored by
    /// drawing them again when it folds (an exploring method whose leases
    /// do not list their tests), which bounds its leases' length.
    pub const fn folds_by_redrawing(self) -> bool {
        self.spec().explores && !self.spec().in_stages
    }

    /// Whether one worker runs it whole, as its one test (`build`).
    pub fn runs_whole(self) -> bool {
        self.spec().builds == Some(BuildWork::Whole)
    }

    /// Whether its test `i` is a surrogate's run on the `i`-th cell with
    /// exposure (`enumerate`).
    pub fn enumerates_cells(self) -> bool {
        self.spec().builds == Some(BuildWork::Cells)
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_method_s_name_is_its_wire_name_and_parses_back() {
        for method in Method::ALL {
            let wire = serde_json::to_value(method).unwrap();
            assert_eq!(wire, serde_json::json!(method.as_str()));
            assert_eq!(Method::parse(method.as_str()), Some(method));
        }
        assert_eq!(Method::parse("lattice"), None);
        let names: std::collections::HashSet<_> = Method::ALL.iter().map(|m| m.as_str()).collect();
        assert_eq!(names.len(), Method::ALL.len(), "two methods share a name");
    }

    #[test]
    fn a_method_s_rules_agree_with_each_other() {
        for method in Method::ALL {
            let spec = method.spec();
            // A build has no estimate: nothing to pair, explore or stage,
            // and no client asks for one.
            if spec.builds.is_some() {
                assert!(!spec.requestable && !spec.pairs && !spec.explores && !spec.in_stages);
                assert_eq!(spec.lease_reach, LeaseReach::All, "{method}");
            }
            // Exploring is exploring outside a library.
            assert!(!spec.explores || spec.uses_library, "{method}");
            assert!(!spec.waits_for_explorers || spec.explores, "{method}");
            // A sequence bets against the weights of tests drawn in
            // advance, not of stages planned from results.
            assert!(
                !(spec.anytime && (spec.in_stages || spec.builds.is_some())),
                "{method}"
            );
            // A staged method's leases stop at its stage, and its results
            // steer its tests, so two vehicles cannot share them.
            assert_eq!(
                spec.in_stages,
                spec.lease_reach == LeaseReach::Stage,
                "{method}"
            );
            assert!(!(spec.in_stages && spec.pairs), "{method}");
        }
        let requestable: Vec<_> = Method::requestable().map(Method::as_str).collect();
        assert_eq!(requestable, ["library", "ndd", "adaptive"]);
    }
}
