//! Vehicles under test that are external programs in `tslg validate`
//! (`--vut-exec NAME=COMMAND`): the held-out vehicles no test, default or
//! library was tuned on.
//!
//! A deterministic program's outcome and criticality depend on its
//! scenario alone: it is run once on every grid cell with exposure, which
//! gives the exact `P(A)` by enumeration, and each replicate campaign looks
//! its tests' outcomes up in that table instead of asking the program
//! again.
//!
//! A noisy program (`"deterministic": false` in its hello) is run `m` times
//! on every cell (`--program-runs`), and a test of a replicate campaign
//! takes one of its cell's `m` runs, chosen uniformly by the test's own
//! noise stream ([`tslg_method::noise::noise_seed`]). The replicates then
//! test a noisy vehicle exactly: the one whose runs of scenario `x` are
//! draws from the program's `m` runs there, with `P(A|x)` the share `p̂(x)`
//! of them that had the event. Its `P(A) = Σ P(x) p̂(x)` is what the
//! campaigns estimate, with no Monte Carlo error of its own, and it differs
//! from the program's by at most a few standard errors
//! `√(Σ P(x)² p̂(1 − p̂)/(m − 1))`.
//!
//! The campaigns are the ones the service would run with workers offering
//! the program (the service tests check that a program in step mode runs
//! its built-in twin's adaptive campaign to the bit). A program is driven in
//! step mode where it offers it (the case measures its criticality as it
//! drives it, exactly as a worker does), else in episode mode (a
//! criticality only where the program sends one).

use anyhow::Context;
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tslg_method::adaptive::{AdaptiveResult, AdaptiveSettings, TestResult};
use tslg_method::estimator::StoppingRule;
use tslg_method::external::{DriverError, ExternalMode, ExternalVehicle, ExternalVut};
use tslg_method::outside::OutsideMass;
use tslg_method::registry::{CampaignSampler, ScenarioCase};
use tslg_method::registry::{CampaignTests, PlannedTest, TestOutcome};
use tslg_method::sampling::{OutsideSpread, Split};
use tslg_worker::external::{ProgramRun, ProgramSettings, Programs};

/// Runs of every cell of a noisy program when `--program-runs` is not
/// given: `p̂(x)` to about ±0.05 where it is ½, and `P(A)` to a fraction
/// of a per cent on cut-in.
pub const DEFAULT_PROGRAM_RUNS: usize = 100;

/// A program's outcomes on every cell of a case's grid.
pub struct ProgramTable {
    /// The program's name (`--vut-exec NAME=…`).
    pub name: String,
    /// Its campaigns' vehicle specification: the program in the mode it
    /// was run in.
    pub spec: serde_json::Value,
    /// Runs of every cell: 1 for a deterministic program.
    pub runs: usize,
    /// `(event, criticality)` of run `j` of cell `c` at `c · runs + j`;
    /// cells without exposure are never drawn and hold `(false, 1)`.
    pub outcomes: Arc<Vec<(bool, f64)>>,
    /// `Σ P(x) p̂(x)`: the exact `P(A)` of the tabulated vehicle (of a
    /// deterministic program, its exact `P(A)`).
    pub probability: f64,
    /// The standard error of `probability` as the program's own `P(A)`:
    /// `√(Σ P(x)² p̂(1 − p̂)/(m − 1))`; 0 for a deterministic program.
    pub standard_error: f64,
}

impl ProgramTable {
    /// Whether the program's runs of one scenario differ.
    pub fn noisy(&self) -> bool {
        self.runs > 1
    }

    /// The per-test variance of the best importance sampling of one run a
    /// test, were every cell's `p̂(x)` known: `q ∝ P(x) √p̂(x)` minimises
    /// `Σ P(x)² p̂(x)/q(x) − P(A)²`, to `(Σ P(x) √p̂(x))² − P(A)²`. No
    /// sampler of single runs does better, library or search, so
    /// `z² V/(β P(A))²` is the fewest tests any campaign of this program
    /// can expect: where its failures are spread thin over much exposure
    /// it is close to the NDD's `z² (1 − P(A))/(β² P(A))`. From `m` runs a
    /// cell it is biased low (`E √p̂ ≤ √p`; a cell failing in fewer than
    /// one run in `m` often shows `p̂ = 0`), so the true floor is higher.
    /// `exposures` are the case's cell exposures.
    pub fn best_sampling_variance(&self, exposures: &[f64]) -> f64 {
        let root: f64 = self
            .cell_rates(exposures)
            .iter()
            .map(|&(p, rate)| p * rate.sqrt())
            .sum();
        (root * root - self.probability * self.probability).max(0.0)
    }

    /// `(P(x), p̂(x))` of every cell: its exposure and the share of its runs
    /// with the event.
    pub fn cell_rates(&self, exposures: &[f64]) -> Vec<(f64, f64)> {
        exposures
            .iter()
            .enumerate()
            .map(|(cell, &p)| {
                let runs = &self.outcomes[cell * self.runs..(cell + 1) * self.runs];
                let events = runs.iter().filter(|(event, _)| *event).count();
                (p, events as f64 / self.runs as f64)
            })
            .collect()
    }

    /// The outcome of test `index` of the campaign seeded `seed`, whose
    /// scenario is `cell`: one of the cell's runs, chosen uniformly by the
    /// test's noise stream (the multiply-high of its first word), so that
    /// every test draws its outcome afresh and the same test always draws
    /// the same.
    pub fn outcome(&self, seed: u64, index: u64, cell: usize) -> (bool, f64) {
        let run = if self.runs == 1 {
            0
        } else {
            let word = tslg_method::noise::noise_seed(seed, index);
            ((u128::from(word) * self.runs as u128) >> 64) as usize
        };
        self.outcomes[cell * self.runs + run]
    }
}

/// Runs `exec` (`NAME=COMMAND`) on every cell of `case` with exposure, once
/// for a deterministic program and `runs` times for a noisy one; `None`
/// when the program does not drive `case`.
pub fn tabulate(
    case: &dyn ScenarioCase,
    exec: &str,
    runs: usize,
) -> anyhow::Result<Option<ProgramTable>> {
    anyhow::ensure!(
        runs >= 2,
        "--program-runs {runs}: a noisy program's P(A|x) needs at least 2 runs a cell"
    );
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
    let offered = |mode| {
        let requirement = tslg_method::external::requirement(&name, case.name(), mode);
        programs
            .offers()
            .contains(&requirement)
            .then(|| programs.noisy_offers().contains(&requirement))
    };
    let (mode, noisy) = match (offered(ExternalMode::Step), offered(ExternalMode::Episode)) {
        (Some(noisy), _) => (ExternalMode::Step, noisy),
        (None, Some(noisy)) => (ExternalMode::Episode, noisy),
        (None, None) => {
            programs.stop();
            return Ok(None);
        }
    };
    let runs = if noisy { runs } else { 1 };
    let program = Arc::clone(programs.get(&name).expect("started"));
    let spec = serde_json::json!({"external": name, "mode": mode.as_str()});
    let tests = case.campaign(None, &spec, 0.0, OutsideSpread::Uniform, Split::Random, 0)?;
    let exposures = case.cell_exposures()?;
    let exposed = exposures.iter().filter(|&&p| p > 0.0).count();
    let done = AtomicUsize::new(0);
    let started = Instant::now();
    let outcomes = exposures
        .par_iter()
        .enumerate()
        .map(|(cell, &p)| {
            if p <= 0.0 {
                return Ok(vec![(false, 1.0); runs]);
            }
            let cell_runs = (0..runs)
                .map(|j| {
                    let index = (cell * runs + j) as u64;
                    match program.run_cell(tests.as_ref(), 0, index, cell, 1.0) {
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
                .collect::<anyhow::Result<Vec<_>>>()?;
            let now = done.fetch_add(1, Ordering::Relaxed) + 1;
            if noisy && now.is_multiple_of((exposed / 10).max(1)) {
                eprintln!(
                    "{}: program `{name}`, {runs} runs a cell: {now} of {exposed} cells ({:.0} s)",
                    case.name(),
                    started.elapsed().as_secs_f64()
                );
            }
            Ok(cell_runs)
        })
        .collect::<anyhow::Result<Vec<_>>>();
    programs.stop();
    let outcomes: Vec<(bool, f64)> = outcomes?.into_iter().flatten().collect();
    let (mut probability, mut variance) = (0.0, 0.0);
    for (cell, &p) in exposures.iter().enumerate() {
        let events = outcomes[cell * runs..(cell + 1) * runs]
            .iter()
            .filter(|(event, _)| *event)
            .count();
        let share = events as f64 / runs as f64;
        probability += p * share;
        if runs > 1 {
            variance += p * p * share * (1.0 - share) / (runs - 1) as f64;
        }
    }
    Ok(Some(ProgramTable {
        name,
        spec,
        runs,
        outcomes: Arc::new(outcomes),
        probability,
        standard_error: variance.sqrt(),
    }))
}

/// A campaign's tests whose vehicle is a program's table: every draw as
/// the campaign makes it, every outcome from the table.
pub struct TabulatedTests {
    pub inner: Arc<dyn CampaignTests>,
    pub table: Arc<ProgramTable>,
    /// The campaign's seed: a noisy program's runs are chosen by the test's
    /// noise stream under it.
    pub seed: u64,
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
            event: self.table.outcome(self.seed, index, planned.cell).0,
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
    case: &dyn CampaignSampler,
    library: &[u8],
    table: &ProgramTable,
    (epsilon, settings): (f64, AdaptiveSettings),
    rule: &StoppingRule,
    seed: u64,
) -> anyhow::Result<AdaptiveResult> {
    // A noisy program's campaign is one with `vehicle_noise`, as the
    // service runs it.
    let settings = AdaptiveSettings {
        noisy: settings.noisy || table.noisy(),
        ..settings
    };
    let tests = case.adaptive_tests(library, &table.spec, epsilon, settings, rule, seed)?;
    let stages = tests.adaptive().context("an adaptive campaign's stages")?;
    while let Some((from, to)) = stages.running() {
        let results = (from..to)
            .map(|index| {
                let cell = tests.planned(index).context("a planned test")?.cell;
                let (event, criticality) = table.outcome(seed, index, cell);
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A table of three cells with `runs` runs each, the first `failing[c]`
    /// of cell `c` failing.
    fn table(failing: [usize; 3], runs: usize, exposures: &[f64]) -> ProgramTable {
        let outcomes: Vec<(bool, f64)> = failing
            .iter()
            .flat_map(|&k| (0..runs).map(move |j| (j < k, 1.0)))
            .collect();
        let probability = exposures
            .iter()
            .zip(failing)
            .map(|(p, k)| p * k as f64 / runs as f64)
            .sum();
        ProgramTable {
            name: "t".into(),
            spec: serde_json::Value::Null,
            runs,
            outcomes: Arc::new(outcomes),
            probability,
            standard_error: 0.0,
        }
    }

    #[test]
    fn the_best_sampling_variance_is_the_square_root_rule_on_the_cells_rates() {
        // Rates 1/4, 1, 0 on exposures 0.5, 0.1, 0.4: μ = 0.225,
        // Σ P √p = 0.5·0.5 + 0.1·1 = 0.35, V = 0.35² − 0.225² = 0.071875.
        let exposures = [0.5, 0.1, 0.4];
        let t = table([1, 4, 0], 4, &exposures);
        assert!((t.probability - 0.225).abs() < 1e-15);
        assert!((t.best_sampling_variance(&exposures) - 0.071875).abs() < 1e-12);
        // Below the NDD's per-test variance μ(1 − μ) = 0.174375, as it must be.
        assert!(t.best_sampling_variance(&exposures) < 0.225 * 0.775);
        // A vehicle whose cells fail always or never: no variance at all
        // (sampling only the failing cells, each test's weighted outcome is μ).
        let sure = table([4, 0, 4], 4, &exposures);
        assert!(sure.best_sampling_variance(&exposures).abs() < 1e-15);
        // Every cell at the same rate p: nothing to gain over the NDD,
        // V = (√p)² − p² = p(1 − p).
        let flat = table([2, 2, 2], 4, &exposures);
        assert!((flat.best_sampling_variance(&exposures) - 0.25).abs() < 1e-12);
    }

    #[test]
    fn every_test_draws_one_of_its_cells_runs_the_same_each_time() {
        let t = table([1, 4, 0], 4, &[0.5, 0.1, 0.4]);
        // Cell 0 fails in one run of four: over many tests about a quarter
        // of its draws fail, and test i draws the same run every time.
        let draws: Vec<bool> = (0..4000).map(|i| t.outcome(7, i, 0).0).collect();
        let share = draws.iter().filter(|&&e| e).count() as f64 / 4000.0;
        assert!((share - 0.25).abs() < 0.03, "{share}");
        assert!((0..4000).all(|i| t.outcome(7, i, 0).0 == draws[i as usize]));
        assert!((0..100).all(|i| t.outcome(7, i, 1).0 && !t.outcome(7, i, 2).0));
    }
}
