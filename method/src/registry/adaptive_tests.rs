//! A service adaptive campaign of a grid case ([`crate::adaptive`]) as the
//! coordinator keeps it: the stages planned so far, each test's cell and
//! weight from its stage, and the step that resolves the running stage once
//! its results are in. Workers are told each test's cell in the lease and
//! run it with [`CampaignTests::run_cell`]; they plan nothing.
//!
//! The state is a function of the seed and the resolved stages' results
//! (events and invalid tests as stored, criticality replayed for a built-in
//! vehicle or reported by a program), so a coordinator that restarts
//! rebuilds it by resolving the stored stages again, and the campaign is
//! the one [`crate::adaptive::run_adaptive`] runs in one process.

use super::vut::CampaignVehicle;
use super::{AdaptiveProgress, AdaptiveStages, CampaignTests, PlannedTest, TestOutcome};
use crate::adaptive::{AdaptiveSettings, AdaptiveState, Planner, StageRecord, TestResult};
use crate::case::Case;
use crate::estimator::StoppingRule;
use crate::external::{DriverError, ExternalVehicle, ExternalVut};
use rayon::prelude::*;
use std::sync::{Mutex, MutexGuard, OnceLock};

/// The coordinator's copy of an adaptive campaign.
pub(super) struct AdaptiveCellCampaign<C: Case + 'static> {
    planner: Planner<'static, C>,
    vehicle: CampaignVehicle<C::Vehicle>,
    rule: StoppingRule,
    settings: AdaptiveSettings,
    state: Mutex<AdaptiveState>,
    /// The built-in vehicle's event and criticality per cell, run once.
    runs: OnceLock<Vec<OnceLock<(bool, f64)>>>,
}

impl<C: Case + 'static> AdaptiveCellCampaign<C> {
    pub(super) fn new(
        planner: Planner<'static, C>,
        vehicle: CampaignVehicle<C::Vehicle>,
        settings: AdaptiveSettings,
        rule: StoppingRule,
        seed: u64,
    ) -> Self {
        let state = planner.start(&rule, seed);
        Self {
            planner,
            vehicle,
            rule,
            settings,
            state: Mutex::new(state),
            runs: OnceLock::new(),
        }
    }

    fn state(&self) -> MutexGuard<'_, AdaptiveState> {
        self.state
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// The cell and weight of test `index`, when its stage is planned.
    fn test(&self, index: u64) -> Option<(usize, f64)> {
        let state = self.state();
        let seed = state.seed();
        state.stage_of(index).map(|stage| stage.test(seed, index))
    }

    /// The built-in vehicle's event and criticality in `cell` as test
    /// `index`: each cell run once and remembered, or, for a noisy vehicle,
    /// the test run with its own noise stream (as the worker ran it).
    fn run_builtin(&self, vehicle: &C::Vehicle, index: u64, cell: usize) -> (bool, f64) {
        let case = self.planner.case();
        if case.is_noisy(vehicle) {
            return case.test_run(vehicle, cell, self.state().seed(), index);
        }
        let runs = self
            .runs
            .get_or_init(|| (0..case.grid().len()).map(|_| OnceLock::new()).collect());
        *runs[cell].get_or_init(|| case.event_and_criticality(vehicle, cell))
    }
}

impl<C> CampaignTests for AdaptiveCellCampaign<C>
where
    C: Case + Send + Sync + 'static,
    C::Vehicle: Send + Sync,
{
    fn external(&self) -> Option<&ExternalVut> {
        self.vehicle.external()
    }

    /// The coordinator runs no test by index; workers run the cells their
    /// leases name.
    fn run_with(
        &self,
        index: u64,
        _program: Option<&mut dyn ExternalVehicle>,
    ) -> Result<TestOutcome, DriverError> {
        Err(DriverError(format!(
            "test {index} of an adaptive campaign runs the cell its lease names"
        )))
    }

    fn check_event(&self, index: u64, weight: f64) -> Result<(), String> {
        let Some((_, expected)) = self.test(index) else {
            return Err(format!(
                "test {index} is not in a planned stage of this adaptive campaign"
            ));
        };
        if expected.to_bits() == weight.to_bits() {
            Ok(())
        } else {
            Err(format!(
                "event at test {index} reports weight {weight:e}, but its stage gives \
                 {expected:e}"
            ))
        }
    }

    fn planned(&self, index: u64) -> Option<PlannedTest> {
        let (cell, weight) = self.test(index)?;
        Some(PlannedTest {
            cell,
            scenario: self.planner.case().grid().values(cell),
            weight,
        })
    }

    fn replay(&self, index: u64) -> Option<TestOutcome> {
        let CampaignVehicle::Builtin(vehicle) = &self.vehicle else {
            return None;
        };
        let (cell, weight) = self.test(index)?;
        let (event, _) = self.run_builtin(vehicle, index, cell);
        Some(TestOutcome { event, weight })
    }

    fn adaptive(&self) -> Option<&dyn AdaptiveStages> {
        Some(self)
    }
}

impl<C> AdaptiveStages for AdaptiveCellCampaign<C>
where
    C: Case + Send + Sync + 'static,
    C::Vehicle: Send + Sync,
{
    fn running(&self) -> Option<(u64, u64)> {
        let state = self.state();
        if state.finished().is_some() {
            return None;
        }
        let stage = state.current();
        Some((stage.start, stage.end()))
    }

    fn settings(&self) -> AdaptiveSettings {
        self.settings
    }

    fn replay_stage(&self, from: u64, to: u64) -> Option<Vec<(bool, f64)>> {
        let CampaignVehicle::Builtin(vehicle) = &self.vehicle else {
            return None;
        };
        let cells: Vec<(u64, usize)> = (from..to)
            .map(|i| self.test(i).map(|(cell, _)| (i, cell)))
            .collect::<Option<_>>()?;
        Some(
            cells
                .par_iter()
                .map(|&(index, cell)| self.run_builtin(vehicle, index, cell))
                .collect(),
        )
    }

    fn resolve(&self, results: &[TestResult]) -> StageRecord {
        let mut state = self.state();
        self.planner.resolve(&mut state, &self.rule, results)
    }

    fn stops_within(&self, results: &[TestResult]) -> bool {
        self.planner
            .stops_within(&self.state(), &self.rule, results)
    }

    fn stage_kind(&self, index: u64) -> Option<&'static str> {
        self.state().stage_of(index).map(|stage| stage.kind())
    }

    fn progress(&self) -> AdaptiveProgress {
        let state = self.state();
        let (library_tests, search_tests, stages) = state.spent();
        let running = state.finished().is_none().then(|| {
            let stage = state.current();
            (stage.start, stage.end(), stage.kind())
        });
        AdaptiveProgress {
            fold: *state.fold(),
            running,
            library_tests,
            search_tests,
            stages,
            support: self.planner.support(state.knowledge()).len(),
            explored: state.explored(),
            finished: state.finished().cloned(),
        }
    }
}
