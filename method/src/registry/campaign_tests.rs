//! The worker's side of a case: every test of one campaign, reproducible
//! from its index, run (worker) and run again (coordinator) by index.

use super::stages::AdaptiveStages;
use crate::external::{DriverError, ExternalVehicle, ExternalVut};

/// What one test gave.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TestOutcome {
    /// Whether the test had the event `A`.
    pub event: bool,
    /// The importance weight `P/q` of the whole test.
    pub weight: f64,
}

/// A test whose scenario and weight are fixed before it runs (grid cases).
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedTest {
    /// The scenario's grid cell.
    pub cell: usize,
    /// The scenario's parameters.
    pub scenario: Vec<f64>,
    /// The importance weight `P(x)/q(x)`.
    pub weight: f64,
}

/// Every test of one campaign, reproducible from its index (SPEC §7): the
/// coordinator and the worker build the same object from the same plan.
pub trait CampaignTests: Send + Sync {
    /// The external program the campaign's vehicle under test is, if it is
    /// one.
    fn external(&self) -> Option<&ExternalVut>;
    /// Runs test `index` with `program` as the vehicle under test (sent a
    /// `reset` first), or on the campaign's built-in model when `program`
    /// is `None`. An error is the program's fault: the test has no valid
    /// outcome. A built-in vehicle that panics is the caller's to catch.
    fn run_with(
        &self,
        index: u64,
        program: Option<&mut dyn ExternalVehicle>,
    ) -> Result<TestOutcome, DriverError>;
    /// Runs test `index` on the campaign's built-in model.
    ///
    /// # Panics
    /// When the campaign's vehicle is an external program.
    fn run(&self, index: u64) -> TestOutcome {
        self.run_with(index, None).unwrap_or_else(|e| panic!("{e}"))
    }
    /// The outcomes of tests `from..to`, in order, when the campaign's
    /// vehicle is built in and its case runs many scenarios at once
    /// ([`crate::case::Case::events`]): the same outcomes as [`Self::run`]
    /// one by one. `None`: run them one by one.
    fn run_span(&self, from: u64, to: u64) -> Option<Vec<TestOutcome>> {
        let _ = (from, to);
        None
    }
    /// The outcomes of tests `indices` (any order) on the campaign's
    /// built-in vehicle, in batches where the case runs tests that way
    /// (the coordinator's replay of the tests a report adds); `None`:
    /// replay them one by one ([`Self::replay`]).
    fn replay_many(&self, indices: &[u64]) -> Option<Vec<TestOutcome>> {
        let _ = indices;
        None
    }
    /// Checks a reported event against the campaign's own test `index`: a
    /// mismatch means the reporter samples differently (another version,
    /// another library) and its results must not enter the estimate. What
    /// depends on an external program's behaviour cannot be checked here.
    fn check_event(&self, index: u64, weight: f64) -> Result<(), String>;
    /// The scenario and weight of test `index` when they are fixed before the
    /// test runs; `None` for sequential scenarios sampled while they run.
    fn planned(&self, index: u64) -> Option<PlannedTest>;
    /// The coordinator's own outcome of test `index`, to check what a
    /// worker reported: the test run again on the campaign's built-in
    /// model (a grid case runs each cell once and remembers it, since a
    /// built-in vehicle's outcome depends on the cell alone). `None` when
    /// the vehicle is an external program, which only workers can run.
    fn replay(&self, index: u64) -> Option<TestOutcome>;
    /// [`Self::replay`] with [`Self::explores`] of the same test, from one
    /// draw where the case can (a grid case's exploring tests are those
    /// whose cell lies outside the library).
    fn replay_explored(&self, index: u64) -> Option<(TestOutcome, bool)> {
        self.replay(index)
            .map(|outcome| (outcome, self.explores(index)))
    }
    /// [`Self::replay_explored`] of each test of `from..to`, in order, in
    /// batches where the case draws that way; `None` when a test cannot be
    /// replayed here.
    fn replay_explored_span(&self, from: u64, to: u64) -> Option<Vec<(TestOutcome, bool)>> {
        (from..to)
            .map(|index| self.replay_explored(index))
            .collect()
    }
    /// Whether test `index` draws its scenario outside the library.
    fn explores(&self, _index: u64) -> bool {
        false
    }
    /// The exploring share the estimate stratifies on: ε of a library
    /// campaign of a grid case under the stratified split
    /// ([`crate::prefix::PrefixFold::strata`]); `None` otherwise.
    fn strata(&self) -> Option<f64> {
        None
    }
    /// The test from which nearly every test explores, once the campaign
    /// switched (docs/statistics.md, "The allocation"); `None` before and
    /// for campaigns that never switch.
    fn explore_from(&self) -> Option<u64> {
        None
    }
    /// Sets (or clears) the switch, as the coordinator's row or a lease
    /// says; `false` where the campaign cannot switch (and `from` is set).
    fn set_explore_from(&self, from: Option<u64>) -> bool {
        from.is_none()
    }
    /// The largest terms of an anytime campaign's sequences
    /// ([`crate::anytime`]); `None` where this case has no anytime interval.
    fn term_bounds(&self) -> Option<crate::anytime::TermBounds> {
        None
    }
    /// The fill that bounds the failure mass outside the library
    /// ([`crate::outside`]); `None` for the NDD and for cases whose
    /// exploration is per decision (car-following).
    fn outside_mass(&self) -> Option<&crate::outside::OutsideMass> {
        None
    }
    /// Whether the library's surrogate has no event in the scenario of test
    /// `index`: asked of exploring tests where the vehicle had one, it
    /// counts the vehicle failing where the surrogate does not.
    fn surrogate_misses(&self, _index: u64) -> bool {
        false
    }
    /// Runs the vehicle (built-in, or `program`) on scenario `cell` as test
    /// `index`, the cell given by the lease (an adaptive campaign's stages
    /// are planned by the coordinator): the event and how close it came
    /// ([`crate::case::Case::criticality`]; `None` when a program does not
    /// say). Grid cases only.
    fn run_cell(
        &self,
        _index: u64,
        _cell: usize,
        _program: Option<&mut dyn ExternalVehicle>,
    ) -> Result<(bool, Option<f64>), DriverError> {
        Err(DriverError(
            "this case's scenarios are not grid cells a lease can name".into(),
        ))
    }
    /// An adaptive campaign's stages, as the coordinator plans them.
    fn adaptive(&self) -> Option<&dyn AdaptiveStages> {
        None
    }
}
