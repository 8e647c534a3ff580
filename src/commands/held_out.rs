//! Vehicles under test that are external programs in `tslg validate`
//! (`--vut-exec NAME=COMMAND`): the held-out vehicles no test, default or
//! library was tuned on.
//!
//! A vehicle is deterministic, so a test's outcome and criticality depend on
//! its scenario alone. The program is run once on every grid cell with
//! exposure (in step mode, the case measuring its criticality as it drives
//! it, exactly as a worker runs it), which gives the exact `P(A)` by
//! enumeration; each replicate campaign then looks its tests' outcomes up
//! in that table instead of asking the program again. The campaigns are the
//! ones the service would run with workers offering the program (the
//! service tests check that a program in step mode runs its built-in twin's
//! adaptive campaign to the bit).

use anyhow::Context;
use rayon::prelude::*;
use std::sync::Arc;
use std::time::Duration;
use tslg_method::adaptive::{AdaptiveResult, AdaptiveSettings, TestResult};
use tslg_method::estimator::StoppingRule;
use tslg_method::external::{DriverError, ExternalVehicle, ExternalVut};
use tslg_method::outside::OutsideMass;
use tslg_method::registry::{CampaignTests, PlannedTest, ScenarioCase, TestOutcome};
use tslg_method::sampling::{OutsideSpread, Split};
use tslg_worker::external::{ProgramRun, ProgramSettings, Programs};

/// A program's outcome on every cell of a case's grid.
pub struct ProgramTable {
    /// The program's name (`--vut-exec NAME=…`).
    pub name: String,
    /// Its campaigns' vehicle specification: the program in step mode.
    pub spec: serde_json::Value,
    /// `(event, criticality)` per cell; cells without exposure are never
    /// drawn and hold `(false, 1)`.
    pub outcomes: Arc<Vec<(bool, f64)>>,
    /// The exact `P(A)`: the exposure of its failing cells.
    pub probability: f64,
}

/// Runs `exec` (`NAME=COMMAND`) on every cell of `case` with exposure;
/// `None` when the program does not drive `case` in step mode.
pub fn tabulate(case: &dyn ScenarioCase, exec: &str) -> anyhow::Result<Option<ProgramTable>> {
    let name = exec
        .split_once('=')
        .map(|(n, _)| n.to_owned())
        .context("--vut-exec takes NAME=COMMAND")?;
    let settings = ProgramSettings {
        worker: "tslg-validate".into(),
        timeout: Duration::from_secs(30),
        max_failures: 5,
        cooldown: Duration::from_secs(1),
    };
    let programs = Programs::start(&[exec.to_owned()], &settings).map_err(anyhow::Error::msg)?;
    let requirement = tslg_method::external::requirement(
        &name,
        case.name(),
        tslg_method::external::ExternalMode::Step,
    );
    if !programs.offers().contains(&requirement) {
        programs.stop();
        return Ok(None);
    }
    if programs.noisy_offers().contains(&requirement) {
        programs.stop();
        anyhow::bail!(
            "--vut-exec {name}: the program says its runs of one test may differ \
             (\"deterministic\": false); a held-out program is run once per cell to give its exact \
             P(A), which one run of a noisy program does not (validate noisy vehicles with \
             --noise: docs/statistics.md, \"Noisy vehicles\")"
        );
    }
    let program = Arc::clone(programs.get(&name).expect("started"));
    let spec = serde_json::json!({"external": name, "mode": "step"});
    let tests = case.campaign(None, &spec, 0.0, OutsideSpread::Uniform, Split::Random, 0)?;
    let exposures = case.cell_exposures()?;
    let outcomes = exposures
        .par_iter()
        .enumerate()
        .map(|(cell, &p)| {
            if p <= 0.0 {
                return Ok((false, 1.0));
            }
            match program.run_cell(tests.as_ref(), 0, cell as u64, cell, 1.0) {
                ProgramRun::Done(outcome, criticality) => Ok((
                    outcome.event,
                    if outcome.event {
                        0.0
                    } else {
                        criticality.unwrap_or(1.0)
                    },
                )),
                ProgramRun::Invalid(reason) => {
                    anyhow::bail!("--vut-exec {name}: cell {cell}: {reason}")
                }
                ProgramRun::Skipped => {
                    anyhow::bail!("--vut-exec {name}: the program turned unhealthy")
                }
            }
        })
        .collect::<anyhow::Result<Vec<_>>>();
    programs.stop();
    let outcomes = outcomes?;
    let probability = outcomes
        .iter()
        .zip(&exposures)
        .filter(|((event, _), _)| *event)
        .map(|(_, p)| p)
        .sum();
    Ok(Some(ProgramTable {
        name,
        spec,
        outcomes: Arc::new(outcomes),
        probability,
    }))
}

/// A campaign's tests whose vehicle is a program's table: every draw as
/// the campaign makes it, every outcome from the table.
pub struct TabulatedTests {
    pub inner: Arc<dyn CampaignTests>,
    pub outcomes: Arc<Vec<(bool, f64)>>,
}

impl CampaignTests for TabulatedTests {
    /// Run in this process, like a built-in model.
    fn external(&self) -> Option<&ExternalVut> {
        None
    }

    fn run_with(
        &self,
        index: u64,
        _program: Option<&mut dyn ExternalVehicle>,
    ) -> Result<TestOutcome, DriverError> {
        let planned = self
            .inner
            .planned(index)
            .ok_or_else(|| DriverError("a grid case's tests are planned".into()))?;
        Ok(TestOutcome {
            event: self.outcomes[planned.cell].0,
            weight: planned.weight,
        })
    }

    fn check_event(&self, index: u64, weight: f64) -> Result<(), String> {
        self.inner.check_event(index, weight)
    }

    fn planned(&self, index: u64) -> Option<PlannedTest> {
        self.inner.planned(index)
    }

    fn replay(&self, index: u64) -> Option<TestOutcome> {
        self.run_with(index, None).ok()
    }

    fn explores(&self, index: u64) -> bool {
        self.inner.explores(index)
    }

    fn strata(&self) -> Option<f64> {
        self.inner.strata()
    }

    fn outside_mass(&self) -> Option<&OutsideMass> {
        self.inner.outside_mass()
    }

    fn term_bounds(&self) -> Option<tslg_method::anytime::TermBounds> {
        self.inner.term_bounds()
    }

    fn explore_from(&self) -> Option<u64> {
        self.inner.explore_from()
    }

    fn set_explore_from(&self, from: Option<u64>) -> bool {
        self.inner.set_explore_from(from)
    }

    fn surrogate_misses(&self, index: u64) -> bool {
        self.inner.surrogate_misses(index)
    }
}

/// An adaptive campaign of the tabulated program: the coordinator's plan
/// ([`ScenarioCase::adaptive_tests`]) resolved stage by stage from the
/// table, as it is from workers' reports.
pub fn adaptive_campaign(
    case: &dyn ScenarioCase,
    library: &[u8],
    table: &ProgramTable,
    (epsilon, settings): (f64, AdaptiveSettings),
    rule: &StoppingRule,
    seed: u64,
) -> anyhow::Result<AdaptiveResult> {
    let tests = case.adaptive_tests(library, &table.spec, epsilon, settings, rule, seed)?;
    let stages = tests.adaptive().context("an adaptive campaign's stages")?;
    while let Some((from, to)) = stages.running() {
        let results = (from..to)
            .map(|index| {
                let cell = tests.planned(index).context("a planned test")?.cell;
                let (event, criticality) = table.outcomes[cell];
                Ok(TestResult::Done { event, criticality })
            })
            .collect::<anyhow::Result<Vec<_>>>()?;
        stages.resolve(&results);
    }
    stages
        .progress()
        .finished
        .context("an adaptive campaign ends when its stages do")
}
