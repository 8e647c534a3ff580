//! The reproduction's tables: Markdown (tests, estimates, every campaign)
//! and CSV (one line per campaign, the row's figures repeated on each).

use super::row::{lower_median, NddSource, Row};
use std::fmt::Write as _;
use tslg_api::CampaignView;

impl Row {
    /// The library campaigns' test counts, sorted.
    fn library_tests(&self) -> Vec<u64> {
        let mut tests: Vec<u64> = self.library_runs.iter().map(|v| v.tests).collect();
        tests.sort_unstable();
        tests
    }

    /// The median test count of the library campaigns ([`lower_median`]).
    pub fn median_library_tests(&self) -> u64 {
        *lower_median(&self.library_tests()).expect("at least one library campaign")
    }

    /// The plain library campaigns, the guarded one, then the adaptive ones
    /// (the grid's search, then the lattice's).
    fn campaigns(&self) -> impl Iterator<Item = &CampaignView> {
        self.library_runs
            .iter()
            .chain(&self.guarded_run)
            .chain(&self.adaptive_runs)
            .chain(&self.lattice_runs)
    }

    /// Median tests of adaptive campaigns `runs` (every test: library,
    /// search and estimation), their range, and NDD tests / median; `-`
    /// without campaigns.
    fn adaptive_summary(&self, runs: &[CampaignView]) -> (String, String) {
        let mut tests: Vec<u64> = runs.iter().map(|v| v.indices).collect();
        tests.sort_unstable();
        match lower_median(&tests) {
            Some(&median) => (
                format!("{median} ({}–{})", tests[0], tests[tests.len() - 1]),
                format!("{:.3e}", self.ndd_tests / median.max(1) as f64),
            ),
            None => ("-".into(), "-".into()),
        }
    }

    /// How many of the intervals of `runs` contain the exact `P(A)`.
    fn adaptive_covering(&self, runs: &[CampaignView]) -> Option<usize> {
        let p = self.exact?.probability;
        Some(
            runs.iter()
                .filter(
                    |v| matches!((v.ci_low, v.ci_high), (Some(lo), Some(hi)) if lo <= p && p <= hi),
                )
                .count(),
        )
    }

    /// The adaptive searches this row ran, by name, with their campaigns.
    fn searches(&self) -> Vec<(&'static str, &[CampaignView])> {
        [
            ("grid", self.adaptive_runs.as_slice()),
            ("lattice", self.lattice_runs.as_slice()),
        ]
        .into_iter()
        .filter(|(_, runs)| !runs.is_empty())
        .collect()
    }

    /// NDD tests / median library tests.
    pub fn ratio(&self) -> f64 {
        self.ndd_tests / self.median_library_tests().max(1) as f64
    }

    /// The ratio as the table shows it, with the coverage beside it when
    /// a library interval missed the exact `P(A)`: a speed-up for a wrong
    /// answer is not one (`1.238e2 (covers 0 of 3: not an answer)`).
    pub fn ratio_text(&self) -> String {
        let ratio = format!("{:.3e}", self.ratio());
        let runs = self.library_runs.len();
        match self.covering() {
            Some((0, _)) => format!("{ratio} (covers 0 of {runs}: not an answer)"),
            Some((plain, _)) if plain < runs => format!("{ratio} (covers {plain} of {runs})"),
            _ => ratio,
        }
    }

    /// How many library intervals contain the exact `P(A)`: plain, guarded.
    fn covering(&self) -> Option<(usize, usize)> {
        let p = self.exact?.probability;
        let count = |high: &dyn Fn(&CampaignView) -> Option<f64>| {
            self.library_runs
                .iter()
                .filter(
                    |v| matches!((v.ci_low, high(v)), (Some(lo), Some(hi)) if lo <= p && p <= hi),
                )
                .count()
        };
        Some((count(&|v| v.ci_high), count(&|v| v.guarded_ci_high)))
    }
}

impl NddSource {
    pub fn as_str(self) -> &'static str {
        match self {
            NddSource::Run => "run",
            NddSource::AnalyticExact => "analytic (exact P(A))",
            NddSource::AnalyticEstimate => "analytic (library estimate)",
        }
    }
}

fn sci(value: Option<f64>) -> String {
    value.map_or("-".into(), |v| format!("{v:.3e}"))
}

fn interval(view: &CampaignView) -> String {
    format!(
        "{} [{}, {}]",
        sci(view.estimate),
        sci(view.ci_low),
        sci(view.ci_high)
    )
}

fn count(value: f64) -> String {
    if value >= 1e5 {
        format!("{value:.3e}")
    } else {
        format!("{value:.0}")
    }
}

pub fn markdown(rows: &[Row], replicates: u64, budget: u64) -> String {
    let mut out = String::from("# The paper's cases through the service\n\n");
    let _ = writeln!(
        out,
        "Each vehicle: {replicates} library campaign(s) (seeds from the first given), 90% \
         confidence, the default n_min and min_events; the NDD baseline run when its expected \
         tests are at most {budget}, else analytic. Ratio = NDD tests / median library tests.\n"
    );
    out += "## Tests\n\n";
    out += "Adaptive ratio = NDD tests / median adaptive tests (every test counted).\n\n";
    out += "| case | library: cells (paper) | vehicle | ε | β | library tests: median (range) | \
            analytic library tests | guarded campaign tests | adaptive tests: median (range) | \
            NDD tests | NDD from | ratio | adaptive ratio | analytic ratio | \
            paper: library / NDD tests (ratio) |\n";
    out += &"|---".repeat(15);
    out += "|\n";
    for row in rows {
        let tests = row.library_tests();
        let paper = row.paper;
        let (adaptive_tests, adaptive_ratio) = row.adaptive_summary(&row.adaptive_runs);
        let _ = writeln!(
            out,
            "| {} | {} of {} ({}) | {} | {} | {} | {} ({}–{}) | {} | {} | {adaptive_tests} | {} | {} | {} | {adaptive_ratio} | {} | {} / {} ({:.0}) |",
            row.case,
            row.library_size,
            row.total_scenarios,
            paper.library_size.map_or("-".into(), |n| n.to_string()),
            row.vehicle,
            row.epsilon,
            row.beta,
            row.median_library_tests(),
            tests[0],
            tests[tests.len() - 1],
            row.exact.map_or("-".into(), |e| count(e.library_tests)),
            row.guarded_run
                .as_ref()
                .map_or("-".into(), |v| v.tests.to_string()),
            count(row.ndd_tests),
            row.ndd_source.as_str(),
            row.ratio_text(),
            row.exact.map_or("-".into(), |e| format!("{:.3e}", e.ratio())),
            paper.library_tests,
            count(paper.ndd_tests),
            paper.ndd_tests / paper.library_tests,
        );
    }
    out += "\n## Estimates\n\n";
    out += "| case | vehicle | exact P(A) | library, first seed: estimate [90% interval] | \
            intervals covering P(A): plain, guarded, adaptive | outside bound U | guarded high | \
            campaigns with warnings | guarded campaign: estimate [low, guarded high] | \
            NDD: estimate [90% interval] |\n";
    out += &"|---".repeat(10);
    out += "|\n";
    for row in rows {
        let first = &row.library_runs[0];
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} | {} | {} | {} | {} of {} | {} | {} |",
            row.case,
            row.vehicle,
            sci(row.exact.map(|e| e.probability)),
            interval(first),
            row.covering()
                .map_or("- (no exact answer)".into(), |(plain, guarded)| {
                    format!(
                        "{plain}/{n}, {guarded}/{n}, {}/{}",
                        row.adaptive_covering(&row.adaptive_runs).unwrap_or(0),
                        row.adaptive_runs.len(),
                        n = row.library_runs.len()
                    )
                }),
            sci(first.outside_upper),
            sci(first.guarded_ci_high),
            row.library_runs
                .iter()
                .filter(|v| !v.warnings.is_empty())
                .count(),
            row.library_runs.len(),
            row.guarded_run.as_ref().map_or("-".into(), |v| format!(
                "{} [{}, {}]",
                sci(v.estimate),
                sci(v.ci_low),
                sci(v.guarded_ci_high)
            )),
            row.ndd_run.as_ref().map_or("not run".into(), interval),
        );
    }
    out += "\nAdaptive campaigns count every test they ran (library, search and estimation); \
            their interval assumes the vehicle's failures outside the library are reachable \
            through failures and near misses from what the tests met.\n";
    if rows.iter().any(|r| !r.searches().is_empty()) {
        adaptive_searches(&mut out, rows);
    }
    out += "\n## Library campaigns\n\n";
    out += "| case | vehicle | campaign | seed | status | tests | events | \
            estimate [90% interval] | outside tests, events | U | guarded high | answer | \
            warnings |\n";
    out += &"|---".repeat(13);
    out += "|\n";
    for row in rows {
        for v in row.campaigns() {
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} | {} | {} | {} | {} | {}, {} | {} | {} | {} | {} |",
                row.case,
                row.vehicle,
                kind(v),
                v.seed,
                v.status.as_str(),
                tests_run(v),
                v.events,
                interval(v),
                v.outside_tests,
                v.outside_events,
                sci(v.outside_upper),
                sci(v.guarded_ci_high),
                // The interval to report (the view's `answer`).
                v.answer.as_ref().map_or("-".into(), |a| format!(
                    "{} [{}, {}]",
                    a.interval.as_str(),
                    sci(Some(a.low)),
                    sci(Some(a.high))
                )),
                v.warnings.len(),
            );
        }
    }
    if let Some(warning) = rows
        .iter()
        .flat_map(|r| &r.library_runs)
        .find_map(|v| v.warnings.first())
    {
        let _ = writeln!(
            out,
            "\nA warning, as the coordinator words it: \"{warning}\""
        );
    }
    out
}

/// The "Adaptive searches" section: each adaptive search a row ran (the
/// grid's, and the lattice's on a fine grid), its tests, ratio and
/// coverage.
fn adaptive_searches(out: &mut String, rows: &[Row]) {
    *out += "\n## Adaptive searches\n\n";
    let _ = write!(
        out,
        "On a grid of more than {} cells the adaptive campaigns also search its coarser \
         lattice (`adaptive_search: lattice`; docs/adaptive-design.md, \"Fine grids\"): whole \
         blocks join the support untested, so the search costs the failure region's volume in \
         blocks, and failures in sheets thinner than a block go unseen. Ratio = NDD tests / \
         median tests.\n\n",
        tslg_method::adaptive::MAX_LATTICE_POINTS
    );
    *out +=
        "| case | vehicle | search | tests: median (range) | ratio | intervals covering P(A) |\n";
    *out += &"|---".repeat(6);
    *out += "|\n";
    for row in rows {
        for (search, runs) in row.searches() {
            let (tests, ratio) = row.adaptive_summary(runs);
            let _ = writeln!(
                out,
                "| {} | {} | {search} | {tests} | {ratio} | {} |",
                row.case,
                row.vehicle,
                row.adaptive_covering(runs)
                    .map_or("- (no exact answer)".into(), |k| format!(
                        "{k} of {}",
                        runs.len()
                    )),
            );
        }
    }
}

/// How a campaign sampled: the plain library campaign, the guarded one
/// (ε 0.5 spread by the exposure, the outside guard on), or adaptive
/// (searching the grid or its lattice).
fn kind(view: &CampaignView) -> &'static str {
    if let Some(adaptive) = &view.adaptive {
        match adaptive.search {
            tslg_api::AdaptiveSearch::Grid => "adaptive",
            tslg_api::AdaptiveSearch::Lattice => "adaptive-lattice",
        }
    } else if view.guard_outside {
        "library-guarded"
    } else {
        "library"
    }
}

/// The tests a campaign ran: an adaptive campaign's include those spent
/// finding where the vehicle fails, which its `tests` (the estimate's) do
/// not.
fn tests_run(view: &CampaignView) -> u64 {
    if view.adaptive.is_some() {
        view.indices
    } else {
        view.tests
    }
}

const CSV_HEADER: &str = "case,preset,exposure,surrogate,library_cells,total_scenarios,vehicle,\
campaign,epsilon,beta,seed,status,tests,events,estimate,ci_low,ci_high,outside_tests,outside_events,\
outside_upper,guarded_ci_high,warnings,exact_probability,analytic_library_tests,ndd_tests,\
ndd_from,ndd_estimate,ndd_ci_low,ndd_ci_high,median_library_tests,ratio,analytic_ratio,\
paper_library_cells,paper_library_tests,paper_ndd_tests";

pub fn csv(rows: &[Row]) -> String {
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:e}"));
    let mut out = format!("{CSV_HEADER}\n");
    for row in rows {
        let ndd = row.ndd_run.as_ref();
        for v in row.campaigns() {
            let fields = [
                row.case.to_owned(),
                row.preset.to_owned(),
                row.exposure.clone(),
                row.surrogate.to_owned(),
                row.library_size.to_string(),
                row.total_scenarios.to_string(),
                row.vehicle.to_owned(),
                kind(v).to_owned(),
                v.epsilon.to_string(),
                row.beta.to_string(),
                v.seed.to_string(),
                v.status.as_str().to_owned(),
                tests_run(v).to_string(),
                v.events.to_string(),
                opt(v.estimate),
                opt(v.ci_low),
                opt(v.ci_high),
                v.outside_tests.to_string(),
                v.outside_events.to_string(),
                opt(v.outside_upper),
                opt(v.guarded_ci_high),
                v.warnings.len().to_string(),
                opt(row.exact.map(|e| e.probability)),
                opt(row.exact.map(|e| e.library_tests)),
                format!("{:e}", row.ndd_tests),
                row.ndd_source.as_str().to_owned(),
                opt(ndd.and_then(|n| n.estimate)),
                opt(ndd.and_then(|n| n.ci_low)),
                opt(ndd.and_then(|n| n.ci_high)),
                row.median_library_tests().to_string(),
                format!("{:e}", row.ratio()),
                opt(row.exact.map(|e| e.ratio())),
                row.paper
                    .library_size
                    .map_or(String::new(), |n| n.to_string()),
                format!("{:e}", row.paper.library_tests),
                format!("{:e}", row.paper.ndd_tests),
            ];
            let quoted: Vec<String> = fields
                .into_iter()
                .map(|f| {
                    if f.contains([',', '"']) {
                        format!("\"{}\"", f.replace('"', "\"\""))
                    } else {
                        f
                    }
                })
                .collect();
            out += &(quoted.join(",") + "\n");
        }
    }
    out
}
