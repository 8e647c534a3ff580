//! `tslg validate`: replicate campaigns in this process, per case, pairing of
//! surrogate and vehicle, and stopping rule, against the exact `P(A)` by
//! enumeration. It reports how often the plain interval and the guarded
//! interval `[ci_low, guarded_ci_high]` contain `P(A)` (nominal: the
//! confidence), the distribution of tests to stop and the bias of the
//! estimate at the stop, and flags coverage well below nominal: below
//! `c − 2.33 √(c(1 − c)/R)`, where a correct interval falls one time in a
//! hundred.
//!
//! With `--curve-to N` it measures instead the coverage of the plain
//! interval at *every* number of tests `n = 2 … N`: each replicate folds
//! its tests one by one and checks its interval at each `n`, so a default
//! `n_min` is chosen on the whole curve rather than on a few values (the
//! ε-greedy split makes the curve a lattice; docs/statistics.md).

use crate::commands::held_out::{self, ProgramTable, TabulatedTests};
use crate::commands::validate_method::ValidateMethod;
use rayon::prelude::*;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Arc;
use tslg_method::campaign::{answer, run_campaign_tests_watched, AnswerContext, CampaignResult};
use tslg_method::cases::open_case;
use tslg_method::estimator::{default_n_min, Decision, Interval, StoppingRule};
use tslg_method::library::SearchMethod;
use tslg_method::prefix::PrefixFold;
use tslg_method::registry::{
    BuildRequest, CampaignTests, CaseError, ExposureSource, LibrarySearch, ScenarioCase,
};
use tslg_method::sampling::{default_outside, OutsideSpread, Split};
use tslg_method::warnings::{warnings, Dialect, WarningContext};

#[derive(Debug, clap::Args)]
pub struct ValidateArgs {
    /// The cases to validate (default: every case with an exact answer:
    /// cut-in, highway-exit).
    #[arg(long, value_delimiter = ',')]
    pub cases: Option<Vec<String>>,
    /// Replicate campaigns (seeds 0..R) per configuration (default 200, 50
    /// with --quick).
    #[arg(long)]
    pub replicates: Option<u64>,
    /// Target relative half-width β.
    #[arg(long, default_value_t = 0.2, allow_negative_numbers = true)]
    pub beta: f64,
    /// Confidence of the interval.
    #[arg(long, default_value_t = 0.9, allow_negative_numbers = true)]
    pub confidence: f64,
    /// The values of n_min to compare (comma-separated); default: a
    /// campaign's default, max(30, ⌈10/ε⌉) for these library campaigns.
    #[arg(long, value_delimiter = ',')]
    pub n_min: Vec<u64>,
    /// The values of min_events to compare (comma-separated).
    #[arg(long, value_delimiter = ',', default_values_t = [tslg_method::estimator::DEFAULT_MIN_EVENTS])]
    pub min_events: Vec<u64>,
    /// ε of the plain library campaigns (spread as the case does by default).
    #[arg(long, default_value_t = 0.1, allow_negative_numbers = true)]
    pub epsilon: f64,
    /// The splits of the tests between the library and the outside to
    /// compare (comma-separated): stratified, random.
    #[arg(long, value_delimiter = ',', value_enum, default_values_t = [crate::args::SplitArg::Stratified])]
    pub splits: Vec<crate::args::SplitArg>,
    /// Also run each pairing with the outside guard (outside spread ndd,
    /// ε as --epsilon); the same as adding `guarded` to --methods.
    #[arg(long)]
    pub guard: bool,
    /// The methods to compare (comma-separated): plain (the library
    /// campaign), guarded (with the outside guard, outside spread ndd),
    /// adaptive (docs/adaptive-design.md), adaptive-guarded (adaptive,
    /// exploring until the bound on what its support leaves out is within
    /// β), adaptive-lattice (searching a fine grid's coarser lattice;
    /// docs/adaptive-design.md, "Fine grids"), adaptive-lattice-guarded
    /// (the lattice search under the guard). Writes methods.csv.
    #[arg(long, value_delimiter = ',', value_parser = ValidateMethod::parser(), default_values_t = [ValidateMethod::PLAIN])]
    pub methods: Vec<ValidateMethod>,
    /// The intervals to compare (comma-separated): wald (valid at the
    /// stop), anytime (a confidence sequence, valid at every n). Each row
    /// also reports `coverage every n`: the share of replicates whose
    /// interval held the exact P(A) at every settlement from n_min to the
    /// stop. Adaptive campaigns and the random split have no anytime
    /// interval and are skipped.
    #[arg(long, value_delimiter = ',', default_values_t = [Interval::Wald])]
    pub interval: Vec<Interval>,
    /// Tests of each adaptive campaign's estimation stages, as a service
    /// campaign's `stage_tests` on a fleet (a multiple of 20, 20 to
    /// 100000; above 100 the search is widened to stage_tests / 5 cells
    /// a stage, docs/statistics.md, "Stage length").
    #[arg(long, default_value_t = 100)]
    pub stage_tests: u64,
    /// A quick run: 50 replicates (unless given) and highway-exit's coarse preset.
    #[arg(long)]
    pub quick: bool,
    /// Budget of each campaign.
    #[arg(long, default_value_t = 2_000_000)]
    pub max_tests: u64,
    /// Write validation.md and validation.csv (curve.csv with
    /// --curve-to) to this directory.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Replace the files in `--out` if they exist (without it the command
    /// refuses before it runs).
    #[arg(long)]
    pub force: bool,
    /// An exposure table in the layout of the authors' cut-in table (cut-in
    /// only); default: each case's built-in exposure.
    #[arg(long)]
    pub ndd_table: Option<PathBuf>,
    /// Measure the plain interval's coverage at every number of tests from
    /// 2 to N (no stopping rule) instead of at the stop.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(2..=1_000_000))]
    pub curve_to: Option<u64>,
    /// A held-out vehicle under test: an external program (as
    /// `tslg-worker --vut-exec`), tested with the library of the case's
    /// default surrogate on each case it drives, in step mode where it
    /// offers it, else in episode mode. A deterministic program is run once
    /// on every cell with exposure, which gives its exact P(A); a noisy one
    /// (`"deterministic": false`) --program-runs times, and each test takes
    /// one of its cell's runs; repeatable.
    #[arg(long, value_name = "NAME=COMMAND")]
    pub vut_exec: Vec<String>,
    /// Runs of every cell of a noisy --vut-exec program: the tests draw
    /// from them, and the exact P(A) is theirs.
    #[arg(long, default_value_t = held_out::DEFAULT_PROGRAM_RUNS)]
    pub program_runs: usize,
    /// Noisy pairings (cut-in): for each noise given (comma-separated), the
    /// first surrogate's library (the IDM's) tested on each surrogate model
    /// (IDM, FVDM) with that noise, against a Monte Carlo P(A)
    /// (docs/statistics.md, "Noisy vehicles"). A number is σ of additive
    /// noise (m/s²); `KIND:σ` another kind: `multiplicative:0.3`,
    /// `perception:0.1`, `reaction:1.5` (docs/models.md).
    #[arg(long, value_delimiter = ',', value_name = "NOISE")]
    pub noise: Vec<String>,
    /// More built-in vehicles under test (JSON specifications, noisy or
    /// not, e.g. '{"model": "acc-aeb", "actuator_lag": 0.3, "noise": 1}'),
    /// tested with the library of the case's first surrogate; repeatable.
    #[arg(long, value_name = "SPEC")]
    pub vut: Vec<String>,
}

/// One configuration: a case, a library's surrogate, a vehicle and a rule.
struct Setup {
    method: ValidateMethod,
    case: Arc<dyn ScenarioCase>,
    case_name: String,
    surrogate: &'static str,
    /// The vehicle's name as shown (with its noise, if any).
    vut: String,
    /// The built-in model's specification (`None` for a program).
    spec: Option<serde_json::Value>,
    /// An external program's outcomes on every cell (`--vut-exec`); `None`
    /// for a built-in model.
    table: Option<Arc<ProgramTable>>,
    library: Vec<u8>,
    epsilon: f64,
    outside: OutsideSpread,
    split: Split,
    rule: StoppingRule,
    truth: f64,
    /// The vehicle's runs of one scenario may differ.
    noisy: bool,
    /// An adaptive campaign's estimation stage length (`--stage-tests`).
    stage_tests: u64,
}

/// What a campaign's answer depends on ([`tslg_method::campaign::answer`]).
fn answer_context(method: ValidateMethod, rule: &StoppingRule, noisy: bool) -> AnswerContext {
    AnswerContext {
        guard_outside: rule.guard_outside,
        noisy,
        adaptive: method.adaptive(),
    }
}

impl Setup {
    /// The vehicle's specification.
    fn vut_spec(&self) -> serde_json::Value {
        match (&self.table, &self.spec) {
            (Some(table), _) => table.spec.clone(),
            (None, Some(spec)) => spec.clone(),
            (None, None) => serde_json::json!({ "model": self.vut }),
        }
    }

    /// The library campaign's tests seeded `seed` (a program's outcomes
    /// from its table).
    fn tests(&self, seed: u64) -> Result<Arc<dyn CampaignTests>, CaseError> {
        let tests = self.case.campaign(
            Some(&self.library),
            &self.vut_spec(),
            self.epsilon,
            self.outside,
            self.split,
            seed,
        )?;
        Ok(match &self.table {
            Some(table) => Arc::new(TabulatedTests {
                inner: tests,
                table: Arc::clone(table),
                seed,
            }),
            None => tests,
        })
    }

    /// The campaign seeded `seed`, and whether its interval held the exact
    /// P(A) at every settlement from n_min to the stop (`None` for an
    /// adaptive campaign, which is not watched).
    fn campaign(&self, seed: u64) -> anyhow::Result<(CampaignResult, Option<bool>)> {
        if !self.method.adaptive() {
            let tests = self.tests(seed)?;
            // The interval the method answers with, as `Row::answer_coverage`.
            let mut held = true;
            let (truth, n_min) = (self.truth, self.rule.n_min);
            let context = answer_context(self.method, &self.rule, self.noisy);
            let mut watch = |result: &CampaignResult| {
                if result.tests >= n_min {
                    held &= answer(result, context).covers(truth);
                }
            };
            let result = run_campaign_tests_watched(
                tests.as_ref(),
                &self.rule,
                &|_| false,
                Some(&mut watch),
            );
            return Ok((result, Some(held)));
        }
        let run = match &self.table {
            Some(table) => {
                held_out::adaptive_campaign(
                    self.case.as_ref(),
                    &self.library,
                    table,
                    (self.epsilon, self.method.settings(self.stage_tests)),
                    &self.rule,
                    seed,
                )?
                .result
            }
            None => {
                self.case
                    .adaptive_campaign(
                        &self.library,
                        &self.vut_spec(),
                        self.epsilon,
                        self.method.settings(self.stage_tests),
                        &self.rule,
                        seed,
                    )?
                    .result
            }
        };
        Ok((run, None))
    }
}

/// What the replicates of one setup did.
pub struct Row {
    method: ValidateMethod,
    exposure: String,
    case: String,
    surrogate: &'static str,
    vut: String,
    epsilon: f64,
    outside: OutsideSpread,
    split: Split,
    rule: StoppingRule,
    truth: f64,
    runs: Vec<CampaignResult>,
    /// The vehicle's runs of one scenario may differ.
    noisy: bool,
    /// Per run: whether its interval held the exact P(A) at every
    /// settlement from n_min to the stop (`None`: not watched, adaptive).
    held: Vec<Option<bool>>,
}

impl Row {
    /// The share of runs whose interval held at every settlement from
    /// n_min to the stop; `None` where the runs were not watched.
    fn coverage_every_n(&self) -> Option<f64> {
        let held: Option<Vec<bool>> = self.held.iter().copied().collect();
        held.map(|h| h.iter().filter(|&&x| x).count() as f64 / h.len().max(1) as f64)
    }

    fn coverage(&self, covers: impl Fn(&CampaignResult) -> bool) -> f64 {
        self.runs.iter().filter(|r| covers(r)).count() as f64 / self.runs.len() as f64
    }

    /// The coverage of the interval the method answers with: the guarded
    /// interval `[ci_low, guarded_ci_high]` for a guarded campaign and for
    /// a noisy vehicle's, the plain one otherwise.
    fn answer_coverage(&self) -> f64 {
        let context = answer_context(self.method, &self.rule, self.noisy);
        self.coverage(|r| answer(r, context).covers(self.truth))
    }

    /// The coverage of `[ci_low, guarded_ci_high]` where the campaigns
    /// report it (library and adaptive campaigns of grid cases).
    fn guarded_coverage(&self) -> Option<f64> {
        self.runs
            .iter()
            .all(|r| r.guarded_ci_high.is_some())
            .then(|| self.coverage(|r| r.guarded_covers(self.truth)))
    }

    /// The share of campaigns that warned (a surrogate mismatch, an outside
    /// bound wider than accepted: `tslg_method::warnings`).
    fn warned(&self) -> f64 {
        let context = WarningContext {
            beta: self.rule.beta,
            guard_outside: self.rule.guard_outside,
            dialect: Dialect::Cli,
            unexplored: self.epsilon == 0.0 && !self.method.adaptive(),
            uniform_spread: self.outside == OutsideSpread::Uniform,
            adaptive: self.method.adaptive(),
            noisy: self.noisy,
        };
        self.coverage(|r| !warnings(r, context).is_empty())
    }

    /// The coverage a correct interval stays above but one time in a hundred.
    fn floor(&self) -> f64 {
        let c = self.rule.confidence;
        c - 2.33 * (c * (1.0 - c) / self.runs.len() as f64).sqrt()
    }

    /// `(mean μ̂ / P(A) − 1, its standard error)`.
    fn bias(&self) -> (f64, f64) {
        let n = self.runs.len() as f64;
        let mean = self.runs.iter().map(|r| r.estimate).sum::<f64>() / n;
        let var = self
            .runs
            .iter()
            .map(|r| (r.estimate - mean).powi(2))
            .sum::<f64>()
            / (n - 1.0).max(1.0);
        (mean / self.truth - 1.0, (var / n).sqrt() / self.truth)
    }

    /// A quantile of the tests each campaign ran (for an adaptive one,
    /// its library, search and estimation tests).
    fn tests_quantile(&self, q: f64) -> u64 {
        let mut tests: Vec<u64> = self.runs.iter().map(|r| r.indices).collect();
        tests.sort_unstable();
        tests[((tests.len() - 1) as f64 * q).round() as usize]
    }

    fn flag(&self) -> &'static str {
        match (
            self.coverage(|r| r.covers(self.truth)) < self.floor(),
            self.coverage(|r| r.guarded_covers(self.truth)) < self.floor(),
        ) {
            (true, true) => "LOW both",
            (true, false) => "LOW plain",
            (false, true) => "LOW guarded",
            (false, false) => "",
        }
    }
}

pub fn run(args: &ValidateArgs) -> anyhow::Result<()> {
    let replicates = args.replicates.unwrap_or(if args.quick { 50 } else { 200 });
    anyhow::ensure!(replicates >= 2, "--replicates must be at least 2");
    anyhow::ensure!(
        (20..=100_000).contains(&args.stage_tests) && args.stage_tests.is_multiple_of(20),
        "--stage-tests must be a multiple of 20 from 20 to 100000, not {}",
        args.stage_tests
    );
    if let Some(dir) = &args.out {
        let names: &[&str] = if args.curve_to.is_some() {
            &["curve.md", "curve.csv"]
        } else {
            &["validation.md", "validation.csv", "methods.csv"]
        };
        let paths: Vec<PathBuf> = names.iter().map(|n| dir.join(n)).collect();
        crate::inputs::check_overwrite(&paths, args.force)?;
    }
    if let Some(to) = args.curve_to {
        return curves(args, replicates, to);
    }
    let mut setups_all = Vec::new();
    for case_name in &cases(args) {
        setups_all.extend(setups(case_name, args)?);
    }
    let mut rows = Vec::new();
    for (k, setup) in setups_all.iter().enumerate() {
        let label = format!(
            "[{}/{}] {} → {} replicates",
            k + 1,
            setups_all.len(),
            setup.surrogate,
            setup.vut
        );
        let row = crate::commands::progress::with_progress(&label, |progress| {
            replicate(setup, replicates, progress)
        })?;
        // Progress only: the table comes whole on stdout at the end.
        eprintln!(
            "[{}/{}] {} {} → {} ({}): coverage {:.3}, median {} tests",
            k + 1,
            setups_all.len(),
            row.case,
            row.surrogate,
            row.vut,
            row.method.name(),
            row.answer_coverage(),
            row.tests_quantile(0.5)
        );
        rows.push(row);
    }
    let table = markdown(&rows);
    outln!("{table}");
    outln!("{}", methods_markdown(&rows, args));
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir)?;
        std::fs::write(dir.join("validation.md"), &table)?;
        std::fs::write(dir.join("validation.csv"), csv(&rows))?;
        std::fs::write(dir.join("methods.csv"), methods_csv(&rows))?;
        eprintln!("written to {}", dir.display());
    }
    Ok(())
}

/// The pairings of a case: each surrogate with itself and with the other
/// vehicle, under every (n_min, min_events) asked for, plain and guarded.
fn setups(case_name: &str, args: &ValidateArgs) -> anyhow::Result<Vec<Setup>> {
    let descriptor = tslg_method::cases::descriptor(case_name)?;
    let Some(validation) = descriptor.validation.clone() else {
        let grid: Vec<&str> = tslg_method::cases::descriptors()
            .iter()
            .filter(|d| d.validation.is_some())
            .map(|d| d.name)
            .collect();
        anyhow::bail!(
            "tslg validate needs an exact answer; `{case_name}` has none (cases: {})",
            grid.join(", ")
        )
    };
    let preset = validation.quick_preset.filter(|_| args.quick);
    let pairs = validation.pairs.as_slice();
    let case = open_case(case_name, preset, &exposure(args)?)?;
    // Held-out programs, tested with the library of the case's first
    // surrogate.
    type Vehicle = (&'static str, serde_json::Value, Option<Arc<ProgramTable>>);
    let mut vehicles: Vec<Vehicle> = pairs
        .iter()
        .map(|&(surrogate, vut)| (surrogate, serde_json::json!({ "model": vut }), None))
        .collect();
    if !args.noise.is_empty() && case_name != "cut-in" {
        eprintln!("{case_name}: built-in noisy vehicles run on cut-in; --noise skipped");
    } else {
        // The first surrogate's library, on each built-in vehicle of the
        // case's pairings, with each noise.
        let mut models: Vec<&str> = Vec::new();
        for &(surrogate, _) in pairs {
            if !models.contains(&surrogate) {
                models.push(surrogate);
            }
        }
        for written in &args.noise {
            let noise = tslg_method::noise::Noise::parse_short(written)
                .map_err(|e| anyhow::anyhow!("--noise {written}: {e}"))?;
            for model in &models {
                let spec = serde_json::json!({ "model": model, "noise": noise });
                vehicles.push((pairs[0].0, spec, None));
            }
        }
    }
    for written in &args.vut {
        let spec = crate::inputs::vehicle_spec(case.as_ref(), written, "--vut")?;
        vehicles.push((pairs[0].0, spec, None));
    }
    for exec in &args.vut_exec {
        let Some(table) = held_out::tabulate(case.as_ref(), exec, args.program_runs)? else {
            eprintln!("{case_name}: `{exec}` does not drive this case; skipped");
            continue;
        };
        if table.noisy() {
            eprintln!(
                "{case_name}: noisy program `{}`, {} runs on every cell: P(A) {:.4e} \
                 (± {:.1e} as the program's)",
                table.name, table.runs, table.probability, table.standard_error
            );
        } else {
            eprintln!(
                "{case_name}: program `{}` on every cell: exact P(A) {:.4e}",
                table.name, table.probability
            );
        }
        let spec = table.spec.clone();
        vehicles.push((pairs[0].0, spec, Some(Arc::new(table))));
    }
    let mut setups = Vec::new();
    for (surrogate, vut, table) in vehicles {
        let library = case
            .build_library(
                &serde_json::json!({ "model": surrogate }),
                &BuildRequest {
                    threshold: None,
                    search: Some(LibrarySearch::Cells(SearchMethod::Exhaustive)),
                },
            )?
            .file;
        let truth = match &table {
            Some(t) => t.probability,
            None => case.exact_event_probability(&vut)?,
        };
        let name = match &table {
            Some(t) if t.noisy() => format!("{} (noisy program)", t.name),
            Some(t) => t.name.clone(),
            None => crate::inputs::vehicle_name(&vut, case_name),
        };
        // `--guard` asks for the guarded library campaign too. Its
        // allocation switches to exploring once the library stratum is
        // known, so the guard needs no large ε (docs/statistics.md); it
        // spreads ε by the exposure.
        let guarded_library = ValidateMethod {
            guarded: true,
            ..ValidateMethod::PLAIN
        };
        let variants: Vec<(ValidateMethod, f64, OutsideSpread)> = ValidateMethod::all()
            .into_iter()
            .filter(|m| args.methods.contains(m) || (args.guard && *m == guarded_library))
            .map(|m| {
                let outside = if m == guarded_library {
                    OutsideSpread::Ndd
                } else {
                    case.default_outside()
                };
                (m, args.epsilon, outside)
            })
            .collect();
        // A noisy vehicle's campaigns run under the guard unless told not
        // to, as the service runs them: its plain and guarded variants are
        // then one campaign, run once under the unguarded one's name.
        let noisy =
            tslg_method::noise::spec_is_noisy(&vut) || table.as_ref().is_some_and(|t| t.noisy());
        let mut variants = variants;
        if noisy {
            let asked: Vec<ValidateMethod> = variants.iter().map(|v| v.0).collect();
            variants.retain(|v| !asked.contains(&v.0.unguarded()) || v.0.unguarded() == v.0);
        }
        for &(method, epsilon, outside) in &variants {
            // An adaptive campaign's n_min counts its estimation tests.
            let share = (!method.adaptive())
                .then(|| case.descriptor().exploring_share(true, epsilon))
                .flatten();
            let n_mins = match args.n_min.as_slice() {
                [] => vec![default_n_min(share, args.max_tests)],
                given => given.to_vec(),
            };
            for (&n_min, &split) in n_mins
                .iter()
                .flat_map(|n| args.splits.iter().map(move |s| (n, s)))
            {
                for (&min_events, &interval) in args
                    .min_events
                    .iter()
                    .flat_map(|m| args.interval.iter().map(move |i| (m, i)))
                {
                    // No sequence for adaptive stages, nor for the random
                    // split (its outside has no bound valid at every n).
                    if interval == Interval::Anytime
                        && (method.adaptive() || split.split() == Split::Random)
                    {
                        continue;
                    }
                    let guard_outside = method.guarded
                        || tslg_method::noise::guards_by_default(noisy, interval == Interval::Wald);
                    let rule = StoppingRule {
                        beta: args.beta,
                        confidence: args.confidence,
                        n_min,
                        min_events,
                        max_tests: args.max_tests,
                        guard_outside,
                        interval,
                    };
                    rule.validate()?;
                    // A plain campaign gets the spread a campaign of this
                    // rule gets by default (ndd for an anytime interval).
                    let outside = if method == ValidateMethod::PLAIN {
                        default_outside(case.default_outside(), &rule)
                    } else {
                        outside
                    };
                    setups.push(Setup {
                        method,
                        case: Arc::clone(&case),
                        case_name: case_name.to_owned(),
                        surrogate,
                        vut: name.clone(),
                        spec: table.is_none().then(|| vut.clone()),
                        table: table.clone(),
                        library: library.clone(),
                        epsilon,
                        outside,
                        split: split.split(),
                        rule,
                        truth,
                        noisy,
                        stage_tests: args.stage_tests,
                    });
                }
            }
        }
    }
    Ok(setups)
}

/// The exposure `--ndd-table` names, or the built-in one.
fn exposure(args: &ValidateArgs) -> anyhow::Result<ExposureSource> {
    crate::inputs::exposure_source(args.ndd_table.as_deref())
}

/// The coverage curves of every setup: printed as a summary, written as
/// `curve.csv` (one row per setup and n).
fn curves(args: &ValidateArgs, replicates: u64, to: u64) -> anyhow::Result<()> {
    let mut table = String::from(
        "| case | exposure | surrogate | vehicle | ε | split | R | n_min | \
         worst coverage for n ≥ n_min (at n) | coverage at n_min and at N | \
         n ≥ n_min below the floor |\n\
         |---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut csv =
        String::from("case,exposure,surrogate,vehicle,epsilon,split,replicates,n,coverage\n");
    for case_name in &cases(args) {
        for setup in setups(case_name, args)?
            .iter()
            .filter(|s| !s.rule.guard_outside)
        {
            let curve = coverage_curve(setup, replicates, to)?;
            let exposure = setup.case.exposure_name().to_owned();
            for (k, c) in curve.iter().enumerate() {
                let _ = writeln!(
                    csv,
                    "{},{exposure},{},{},{},{},{replicates},{},{c}",
                    setup.case_name,
                    setup.surrogate,
                    setup.vut,
                    setup.epsilon,
                    setup.split.name(),
                    k + 2
                );
            }
            let c = args.confidence;
            let floor = c - 2.33 * (c * (1.0 - c) / replicates as f64).sqrt();
            // Where a campaign of the default rule can stop: n ≥ n_min.
            let n_min = setup.rule.n_min.clamp(2, to);
            let stoppable = &curve[(n_min - 2) as usize..];
            let (worst, at) = stoppable
                .iter()
                .enumerate()
                .map(|(k, &c)| (c, n_min + k as u64))
                .fold((f64::INFINITY, 0), |a, b| if b.0 < a.0 { b } else { a });
            let line = format!(
                "| {} | {exposure} | {} | {} | {} | {} | {replicates} | {n_min} | \
                 {worst:.3} ({at}) | {:.3}, {:.3} | {} of {} |",
                setup.case_name,
                setup.surrogate,
                setup.vut,
                setup.epsilon,
                setup.split.name(),
                stoppable[0],
                stoppable[stoppable.len() - 1],
                stoppable.iter().filter(|&&c| c < floor).count(),
                stoppable.len()
            );
            eprintln!(
                "{} {} → {} ({}): worst coverage {worst:.3} at {at} tests",
                setup.case_name,
                setup.surrogate,
                setup.vut,
                setup.split.name()
            );
            let _ = writeln!(table, "{line}");
        }
    }
    let _ = writeln!(
        table,
        "\nThe plain interval's coverage at every n (no stopping rule), nominal {:.2}; \
         the floor is c − 2.33 √(c(1 − c)/R).",
        args.confidence
    );
    outln!("{table}");
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir)?;
        std::fs::write(dir.join("curve.md"), &table)?;
        std::fs::write(dir.join("curve.csv"), &csv)?;
        eprintln!("written to {}", dir.display());
    }
    Ok(())
}

/// The share of replicates whose plain interval holds the exact `P(A)`
/// after `n` tests, for `n = 2 … to` (index `n − 2`): each seed's tests are
/// folded one by one, in index order, as a campaign folds them.
fn coverage_curve(setup: &Setup, replicates: u64, to: u64) -> anyhow::Result<Vec<f64>> {
    let z = setup.rule.z();
    let covered = (0..replicates)
        .into_par_iter()
        .map(|seed| {
            let tests = setup.tests(seed)?;
            let mut fold = PrefixFold::with_strata(tests.strata());
            let mut covers = Vec::with_capacity(to as usize - 1);
            let outcomes = tests
                .run_span(0, to)
                .unwrap_or_else(|| (0..to).map(|index| tests.run(index)).collect());
            for (index, outcome) in (0..to).zip(outcomes) {
                fold.push(outcome.weight, outcome.event, tests.explores(index));
                if index >= 1 {
                    let (low, high) = fold.interval(z);
                    covers.push(low <= setup.truth && setup.truth <= high);
                }
            }
            Ok(covers)
        })
        .collect::<anyhow::Result<Vec<Vec<bool>>>>()?;
    Ok((0..to as usize - 1)
        .map(|k| covered.iter().filter(|c| c[k]).count() as f64 / replicates as f64)
        .collect())
}

/// Runs the campaigns of seeds `0..replicates`, counting them on
/// `progress`.
fn replicate(
    setup: &Setup,
    replicates: u64,
    progress: &tslg_method::progress::Progress,
) -> anyhow::Result<Row> {
    progress.start(replicates);
    let (runs, held) = (0..replicates)
        .into_par_iter()
        .map(|seed| {
            let run = setup.campaign(seed);
            progress.add(1);
            run
        })
        .collect::<anyhow::Result<Vec<_>>>()?
        .into_iter()
        .unzip();
    Ok(Row {
        method: setup.method,
        exposure: setup.case.exposure_name().to_owned(),
        case: setup.case_name.clone(),
        surrogate: setup.surrogate,
        vut: setup.vut.clone(),
        epsilon: setup.epsilon,
        outside: setup.outside,
        split: setup.split,
        rule: setup.rule,
        truth: setup.truth,
        runs,
        noisy: setup.noisy,
        held,
    })
}

const HEADER: [&str; 21] = [
    "case",
    "surrogate",
    "vehicle",
    "ε",
    "outside",
    "split",
    "guard",
    "n_min",
    "min_events",
    "R",
    "exact P(A)",
    "tests median",
    "tests p90",
    "tests max",
    "coverage plain",
    "coverage guarded",
    "bias (± s.e.)",
    "flag",
    "method",
    "interval",
    "coverage every n",
];

fn cells(row: &Row) -> Vec<String> {
    let (bias, se) = row.bias();
    let exhausted = row
        .runs
        .iter()
        .filter(|r| r.status == Decision::Exhausted)
        .count();
    let flag = match exhausted {
        0 => row.flag().to_owned(),
        k => format!("{} {k} exhausted", row.flag()).trim().to_owned(),
    };
    vec![
        row.case.clone(),
        row.surrogate.into(),
        row.vut.clone(),
        format!("{}", row.epsilon),
        format!("{:?}", row.outside).to_lowercase(),
        row.split.name().into(),
        if row.rule.guard_outside { "yes" } else { "no" }.into(),
        row.rule.n_min.to_string(),
        row.rule.min_events.to_string(),
        row.runs.len().to_string(),
        format!("{:.4e}", row.truth),
        row.tests_quantile(0.5).to_string(),
        row.tests_quantile(0.9).to_string(),
        row.tests_quantile(1.0).to_string(),
        format!("{:.3}", row.coverage(|r| r.covers(row.truth))),
        format!("{:.3}", row.coverage(|r| r.guarded_covers(row.truth))),
        format!("{:+.3} ± {:.3}", bias, se),
        flag,
        row.method.name(),
        row.rule.interval.name().into(),
        row.coverage_every_n()
            .map_or("-".into(), |c| format!("{c:.3}")),
    ]
}

fn markdown_line(row: &Row) -> String {
    format!("| {} |", cells(row).join(" | "))
}

/// The table in Markdown, with the nominal level and the flag's threshold.
pub fn markdown(rows: &[Row]) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "| {} |", HEADER.join(" | "));
    let _ = writeln!(out, "|{}", "---|".repeat(HEADER.len()));
    for row in rows {
        let _ = writeln!(out, "{}", markdown_line(row));
    }
    if let Some(first) = rows.first() {
        let _ = writeln!(
            out,
            "\nNominal coverage {:.2}; LOW marks coverage below {:.3} (c − 2.33 √(c(1 − c)/R)). \
             Bias is mean estimate / exact − 1 at the stop. Coverage every n: the share of \
             replicates whose interval (the guarded one for a guarded campaign) held the exact \
             P(A) at every settlement (every n up to 32, then every 3 %) from n_min to the \
             stop.",
            first.rule.confidence,
            first.floor()
        );
    }
    out
}

fn csv(rows: &[Row]) -> String {
    let mut out = HEADER.join(",") + "\n";
    for row in rows {
        let line: Vec<String> = cells(row)
            .into_iter()
            .map(|c| {
                if c.contains(',') {
                    format!("\"{c}\"")
                } else {
                    c
                }
            })
            .collect();
        out += &(line.join(",") + "\n");
    }
    out
}

/// The expected tests of the NDD baseline to relative half-width β at
/// confidence c: `z²(1 − μ)/(β²μ)` with the exact `μ`.
fn ndd_tests(row: &Row) -> f64 {
    let z = row.rule.z();
    z * z * (1.0 - row.truth) / (row.rule.beta.powi(2) * row.truth)
}

/// The cells of one pairing and method: `case, exposure, surrogate, vut,
/// method, replicates, coverage, median_tests, ndd_tests, interval,
/// coverage_every_n, guarded_coverage, warned`.
fn method_cells(row: &Row) -> [String; 13] {
    [
        row.case.clone(),
        row.exposure.clone(),
        row.surrogate.into(),
        row.vut.clone(),
        row.method.name(),
        row.runs.len().to_string(),
        format!("{:.4}", row.answer_coverage()),
        row.tests_quantile(0.5).to_string(),
        format!("{:.0}", ndd_tests(row)),
        row.rule.interval.name().into(),
        row.coverage_every_n()
            .map_or("-".into(), |c| format!("{c:.4}")),
        row.guarded_coverage()
            .map_or("-".into(), |c| format!("{c:.4}")),
        format!("{:.4}", row.warned()),
    ]
}

/// One line per pairing and method ([`method_cells`]).
fn methods_csv(rows: &[Row]) -> String {
    let mut out = String::from(
        "case,exposure,surrogate,vut,method,replicates,coverage,median_tests,ndd_tests,interval,\
         coverage_every_n,guarded_coverage,warned\n",
    );
    for row in rows {
        let _ = writeln!(out, "{}", method_cells(row).join(","));
    }
    out
}

/// The same as a Markdown table, with the ratio of the NDD baseline's
/// tests to the median.
fn methods_markdown(rows: &[Row], args: &ValidateArgs) -> String {
    let mut out = String::from(
        "| case | exposure | surrogate | vehicle | method | R | coverage | median tests | NDD tests | \
         interval | coverage every n | guarded end covers | warned | NDD / median |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for row in rows {
        let ratio = ndd_tests(row) / row.tests_quantile(0.5).max(1) as f64;
        let _ = writeln!(out, "| {} | {ratio:.1} |", method_cells(row).join(" | "));
    }
    let _ = writeln!(
        out,
        "\nCoverage of the {:.0} % interval each method answers with (guarded and \
         adaptive-guarded: [ci_low, guarded_ci_high]); guarded end covers: of \
         [ci_low, guarded_ci_high] for every method that reports it; warned: the share of \
         campaigns with a warning; NDD tests z²(1 − μ)/(β²μ) at β {}.",
        100.0 * args.confidence,
        args.beta
    );
    out
}

/// The cases asked for, or every case with an exact answer.
fn cases(args: &ValidateArgs) -> Vec<String> {
    args.cases.clone().unwrap_or_else(|| {
        tslg_method::cases::descriptors()
            .iter()
            .filter(|d| d.validation.is_some())
            .map(|d| d.name.to_owned())
            .collect()
    })
}
