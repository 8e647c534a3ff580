//! The tests of a grid case's campaign, each a cell drawn from the test's
//! stream, run on the built-in vehicle or a program, and remembered per
//! cell so the coordinator's replays cost a draw and a look-up.

use crate::case::Case;
use crate::external::{DriverError, ExternalVehicle, ExternalVut, TestStart};
use crate::registry::vut::{runner, CampaignVehicle, Runner};
use crate::registry::{CampaignTests, PlannedTest, TestOutcome};
use crate::sampling::TestDistribution;
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::{Arc, OnceLock};

/// A grid campaign: test `i` draws its cell and weight from the stream
/// `(seed, i)`, then the vehicle runs that scenario.
pub(super) struct CellCampaign<C: Case> {
    pub(super) case: Arc<C>,
    pub(super) vehicle: CampaignVehicle<C::Vehicle>,
    /// The library's surrogate, for the mismatch count.
    pub(super) surrogate: Option<C::Vehicle>,
    pub(super) distribution: TestDistribution,
    pub(super) seed: u64,
    /// The world block of each `reset` sent to a program.
    pub(super) world: serde_json::Value,
    /// The built-in vehicle's outcome per cell, for [`CampaignTests::replay`]:
    /// 0 not run yet, 1 no event, 2 event. Allocated on the first replay
    /// (the coordinator's copy), so workers never pay for it.
    pub(super) outcomes: OnceLock<Vec<AtomicU8>>,
}

/// [`CellCampaign::outcomes`]' codes.
const NOT_RUN: u8 = 0;
const NO_EVENT: u8 = 1;
const EVENT: u8 = 2;

impl<C> CellCampaign<C>
where
    C: Case,
{
    /// The built-in `vehicle`'s outcome of test `index`, drawn as `draw`:
    /// each cell simulated once and remembered, or, for a noisy vehicle,
    /// the test run with its own noise stream (bit for bit the worker's).
    fn replay_draw(
        &self,
        vehicle: &C::Vehicle,
        index: u64,
        draw: &crate::sampling::Draw,
    ) -> TestOutcome {
        if self.case.is_noisy(vehicle) {
            return TestOutcome {
                event: self.case.test_run(vehicle, draw.cell, self.seed, index).0,
                weight: draw.weight,
            };
        }
        let outcomes = self.outcomes.get_or_init(|| {
            (0..self.case.grid().len())
                .map(|_| AtomicU8::new(NOT_RUN))
                .collect()
        });
        let known = outcomes[draw.cell].load(Ordering::Relaxed);
        let event = if known == NOT_RUN {
            let event = self.case.is_event(vehicle, draw.cell);
            outcomes[draw.cell].store(if event { EVENT } else { NO_EVENT }, Ordering::Relaxed);
            event
        } else {
            known == EVENT
        };
        TestOutcome {
            event,
            weight: draw.weight,
        }
    }
}

impl<C> CampaignTests for CellCampaign<C>
where
    C: Case + Send + 'static,
    C::Vehicle: Send + Sync,
{
    fn external(&self) -> Option<&ExternalVut> {
        self.vehicle.external()
    }

    fn run_with(
        &self,
        index: u64,
        program: Option<&mut dyn ExternalVehicle>,
    ) -> Result<TestOutcome, DriverError> {
        let draw = self.distribution.draw(self.seed, index);
        let start = TestStart {
            case: self.case.name(),
            mode: Default::default(),
            index,
            noise_seed: crate::noise::noise_seed(self.seed, index),
            world: &self.world,
        };
        let event = match runner(&self.vehicle, program, start)? {
            Runner::Builtin(vehicle) if self.case.is_noisy(vehicle) => {
                self.case.test_run(vehicle, draw.cell, self.seed, index).0
            }
            Runner::Builtin(vehicle) => self.case.is_event(vehicle, draw.cell),
            Runner::Program(program, mode) => self.case.external_event(program, mode, draw.cell)?,
        };
        Ok(TestOutcome {
            event,
            weight: draw.weight,
        })
    }

    fn run_span(&self, from: u64, to: u64) -> Option<Vec<TestOutcome>> {
        let CampaignVehicle::Builtin(vehicle) = &self.vehicle else {
            return None;
        };
        let draws = self.distribution.draws(self.seed, from, to);
        let cells: Vec<usize> = draws.iter().map(|d| d.cell).collect();
        let mut events = vec![false; cells.len()];
        if self.case.is_noisy(vehicle) {
            for ((event, &cell), index) in events.iter_mut().zip(&cells).zip(from..to) {
                *event = self.case.test_run(vehicle, cell, self.seed, index).0;
            }
        } else {
            self.case.events(vehicle, &cells, &mut events);
        }
        Some(
            draws
                .iter()
                .zip(events)
                .map(|(draw, event)| TestOutcome {
                    event,
                    weight: draw.weight,
                })
                .collect(),
        )
    }

    fn check_event(&self, index: u64, weight: f64) -> Result<(), String> {
        let expected = self.distribution.draw(self.seed, index).weight;
        if expected.to_bits() == weight.to_bits() {
            Ok(())
        } else {
            Err(format!(
                "event at test {index} reports weight {weight:e}, but the campaign's sampler \
                 gives {expected:e}"
            ))
        }
    }

    fn replay(&self, index: u64) -> Option<TestOutcome> {
        self.replay_explored(index).map(|(outcome, _)| outcome)
    }

    fn replay_explored(&self, index: u64) -> Option<(TestOutcome, bool)> {
        let CampaignVehicle::Builtin(vehicle) = &self.vehicle else {
            return None;
        };
        let draw = self.distribution.draw(self.seed, index);
        let outcome = self.replay_draw(vehicle, index, &draw);
        Some((outcome, self.distribution.explored(&draw)))
    }

    fn replay_explored_span(&self, from: u64, to: u64) -> Option<Vec<(TestOutcome, bool)>> {
        let CampaignVehicle::Builtin(vehicle) = &self.vehicle else {
            return None;
        };
        let mut outcomes = Vec::with_capacity(to.saturating_sub(from) as usize);
        self.distribution
            .draw_each(self.seed, from..to, |index, draw| {
                let outcome = self.replay_draw(vehicle, index, &draw);
                outcomes.push((outcome, self.distribution.explored(&draw)));
            });
        Some(outcomes)
    }

    fn replay_many(&self, indices: &[u64]) -> Option<Vec<TestOutcome>> {
        let CampaignVehicle::Builtin(vehicle) = &self.vehicle else {
            return None;
        };
        let mut outcomes = Vec::with_capacity(indices.len());
        self.distribution
            .draw_each(self.seed, indices.iter().copied(), |index, draw| {
                outcomes.push(self.replay_draw(vehicle, index, &draw));
            });
        Some(outcomes)
    }

    fn planned(&self, index: u64) -> Option<PlannedTest> {
        let draw = self.distribution.draw(self.seed, index);
        Some(PlannedTest {
            cell: draw.cell,
            scenario: self.case.grid().values(draw.cell),
            weight: draw.weight,
        })
    }

    fn explores(&self, index: u64) -> bool {
        self.distribution.explores(self.seed, index)
    }

    fn strata(&self) -> Option<f64> {
        self.distribution.strata()
    }

    fn outside_mass(&self) -> Option<&crate::outside::OutsideMass> {
        self.distribution.outside_mass()
    }

    fn term_bounds(&self) -> Option<crate::anytime::TermBounds> {
        self.distribution.term_bounds()
    }

    fn explore_from(&self) -> Option<u64> {
        self.distribution.explore_from()
    }

    fn set_explore_from(&self, from: Option<u64>) -> bool {
        self.distribution.set_explore_from(from)
    }

    fn run_cell(
        &self,
        index: u64,
        cell: usize,
        program: Option<&mut dyn ExternalVehicle>,
    ) -> Result<(bool, Option<f64>), DriverError> {
        if cell >= self.case.grid().len() {
            return Err(DriverError(format!(
                "test {index} names cell {cell}; the grid has {} cells",
                self.case.grid().len()
            )));
        }
        let start = TestStart {
            case: self.case.name(),
            mode: Default::default(),
            index,
            noise_seed: crate::noise::noise_seed(self.seed, index),
            world: &self.world,
        };
        match runner(&self.vehicle, program, start)? {
            Runner::Builtin(vehicle) => {
                let (event, criticality) = self.case.test_run(vehicle, cell, self.seed, index);
                Ok((event, Some(criticality)))
            }
            Runner::Program(program, mode) => self
                .case
                .external_event_and_criticality(program, mode, cell),
        }
    }

    fn surrogate_misses(&self, index: u64) -> bool {
        self.surrogate.as_ref().is_some_and(|surrogate| {
            !self
                .case
                .is_event(surrogate, self.distribution.draw(self.seed, index).cell)
        })
    }
}
