//! `tslg reproduce`: the paper's three cases through the service, in one
//! command. A coordinator on a scratch SQLite file and local workers build
//! each case's library through the API with the paper's settings where they
//! are known (ε 0.05 and β 0.3 for cut-in, ε 0.1 and β 0.2 for the others,
//! 90% confidence, the authors' exposure table when given), run R seeded
//! library campaigns per vehicle (and on the grid cases one guarded and R
//! adaptive campaigns), and then the NDD baseline when its
//! expected number of tests fits the budget; otherwise the NDD count is the
//! analytic `z² (1 − μ)/(β² μ)` with μ the exact `P(A)` or, for
//! car-following, the library campaigns' median estimate. The table
//! ([`table`]) puts the paper's numbers beside ours.

mod row;
mod table;

use row::{lower_median, NddSource, Row};

use crate::args::CaseArgs;
use crate::commands::local::{build_library, exact_report, watch_campaigns, ExactQuestion, Local};
use crate::commands::remote::exposure_request;
use std::path::PathBuf;
use tslg_api::{
    AdaptiveSearch, CampaignView, CreateCampaign, CreateLibrary, ExposureRequest, LibraryView,
    Method, Outside, SearchRequest,
};
use tslg_client::Client;
use tslg_method::estimator::z_for_confidence;
use tslg_method::exact::{expected_ndd_tests, ExactReport};

#[derive(Debug, clap::Args)]
pub struct ReproduceArgs {
    /// The cases to run (default: every case).
    #[arg(long, value_delimiter = ',')]
    pub cases: Option<Vec<String>>,
    /// The cut-in exposure table (the paper's: the authors' table,
    /// `../shared/data/cutin_ndd_spmd.csv`); default: the built-in model
    /// fitted to it.
    #[arg(long, env = "TSLG_NDD_TABLE")]
    pub ndd_table: Option<PathBuf>,
    /// Library campaigns per vehicle (seeds seed, seed + 1, …); default 5, 3
    /// with --quick.
    #[arg(long)]
    pub replicates: Option<u64>,
    /// The first seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Run an NDD baseline when its expected tests are at most this (default
    /// 10⁸: every case, car-following's in about ten minutes; 2 × 10⁶ with
    /// --quick); beyond it report the analytic count.
    #[arg(long)]
    pub ndd_budget: Option<u64>,
    /// A couple of minutes: 3 replicates and no NDD baseline beyond 2 × 10⁶
    /// expected tests (car-following's is then analytic).
    #[arg(long)]
    pub quick: bool,
    /// Local workers.
    #[arg(long, default_value_t = 2)]
    pub workers: usize,
    /// Where to write reproduction.md and reproduction.csv (created if missing).
    #[arg(long, default_value = "reproduction")]
    pub out: PathBuf,
}

/// The paper's own figures for a case (Part II, Section IV).
pub use tslg_method::cases::PaperFigures as Paper;

/// One case as the paper ran it, and the vehicles we test with its library
/// (the case's descriptor, [`tslg_method::cases::Reproduction`]).
struct CaseSetting {
    case: &'static str,
    preset: &'static str,
    surrogate: &'static str,
    search: SearchRequest,
    epsilon: f64,
    beta: f64,
    /// `(label, specification)`: the surrogate's own model first where the
    /// vehicles differ in how well the library covers them.
    vehicles: Vec<(&'static str, serde_json::Value)>,
    paper: Paper,
    /// Grid cases also run a guarded and adaptive campaigns.
    grid: bool,
    /// Whether `--ndd-table` applies.
    takes_table: bool,
}

fn settings(case: &str) -> anyhow::Result<CaseSetting> {
    let descriptor = tslg_method::cases::descriptor(case)?;
    let r = descriptor
        .reproduction
        .clone()
        .ok_or_else(|| anyhow::anyhow!("case {case} is not one of the paper's"))?;
    Ok(CaseSetting {
        case: descriptor.name,
        preset: r.preset,
        surrogate: r.surrogate,
        search: tslg_client::wire::search_request(r.search),
        epsilon: r.epsilon,
        beta: r.beta,
        vehicles: r.vehicles,
        paper: r.paper,
        grid: descriptor.is_grid(),
        takes_table: r.takes_table,
    })
}

pub fn run(args: &ReproduceArgs) -> anyhow::Result<()> {
    let replicates = args.replicates.unwrap_or(if args.quick { 3 } else { 5 });
    anyhow::ensure!(replicates >= 1, "--replicates must be at least 1");
    let budget = args
        .ndd_budget
        .unwrap_or(if args.quick { 2_000_000 } else { 100_000_000 });
    let names: Vec<String> = args.cases.clone().unwrap_or_else(|| {
        tslg_method::cases::descriptors()
            .iter()
            .map(|d| d.name.to_owned())
            .collect()
    });
    let cases = names
        .iter()
        .map(|c| settings(c))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let exposure = exposure_request(&CaseArgs {
        ndd_table: args.ndd_table.clone(),
        ..CaseArgs::default()
    })?;
    let rows = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?
        .block_on(async {
            let local = Local::start(None, args.workers, "reproduce").await?;
            eprintln!(
                "coordinator {}, {} workers × {} threads",
                local.service.url, args.workers, local.threads
            );
            let client = local.client()?;
            let mut rows = Vec::new();
            let mut outcome = Ok(());
            for case in &cases {
                let exposure = if case.takes_table {
                    exposure.clone()
                } else {
                    ExposureRequest::Builtin
                };
                match run_case(&client, case, exposure, replicates, args.seed, budget).await {
                    Ok(mut case_rows) => rows.append(&mut case_rows),
                    Err(e) => {
                        outcome = Err(e);
                        break;
                    }
                }
            }
            local.stop().await?;
            outcome.map(|()| rows)
        })?;
    let markdown = table::markdown(&rows, replicates, budget);
    outln!("{markdown}");
    std::fs::create_dir_all(&args.out)?;
    std::fs::write(args.out.join("reproduction.md"), &markdown)?;
    std::fs::write(args.out.join("reproduction.csv"), table::csv(&rows))?;
    eprintln!(
        "written to {}",
        args.out.join("reproduction.{md,csv}").display()
    );
    Ok(())
}

/// Builds the case's library, runs the library campaigns of every vehicle,
/// then the NDD baselines that fit the budget.
async fn run_case(
    client: &Client,
    setting: &CaseSetting,
    exposure: ExposureRequest,
    replicates: u64,
    seed: u64,
    budget: u64,
) -> anyhow::Result<Vec<Row>> {
    let library = build_library(
        client,
        &CreateLibrary {
            case: setting.case.into(),
            preset: Some(setting.preset.into()),
            surrogate: serde_json::json!({"model": setting.surrogate}),
            exposure: exposure.clone(),
            search: Some(setting.search),
            threshold: None,
        },
    )
    .await?;
    eprintln!(
        "{}: library {} of {} ({} of {}, {:.1} s)",
        setting.case,
        library.id,
        setting.surrogate,
        library.size.unwrap_or(0),
        library.total_scenarios,
        library.build_seconds.unwrap_or(f64::NAN)
    );
    let file = client.library_file(library.id).await?;
    let mut rows = Vec::new();
    for (label, vut) in &setting.vehicles {
        let vehicle = Vehicle {
            setting,
            library: &library,
            file: &file,
            exposure: &exposure,
            label,
            vut,
            seed,
        };
        rows.push(vehicle.run(client, replicates, budget).await?);
    }
    Ok(rows)
}

/// One vehicle tested with one case's library.
struct Vehicle<'a> {
    setting: &'a CaseSetting,
    library: &'a LibraryView,
    /// The library's file, for the exact answer.
    file: &'a [u8],
    exposure: &'a ExposureRequest,
    label: &'static str,
    vut: &'a serde_json::Value,
    seed: u64,
}

impl Vehicle<'_> {
    /// A campaign of this vehicle on the library with `method` and `seed`,
    /// at the case's ε and β.
    fn request(&self, method: Method, seed: u64) -> CreateCampaign {
        CreateCampaign {
            library_id: Some(self.library.id),
            epsilon: self.setting.epsilon,
            beta: self.setting.beta,
            seed,
            // The documented numbers are those of stages of 100, whatever
            // the cores of the machine that reproduces them.
            stage_tests: method
                .in_stages()
                .then_some(tslg_method::adaptive::AdaptiveSettings::default().stage_tests),
            ..CreateCampaign::new(self.setting.case, method, self.vut.clone())
        }
    }

    /// Its row: the library campaigns (and on grid cases the guarded and
    /// the adaptive ones), the exact answer, and the NDD baseline run when
    /// it fits the budget (else its analytic count).
    async fn run(&self, client: &Client, replicates: u64, budget: u64) -> anyhow::Result<Row> {
        let setting = self.setting;
        let grid = setting.grid;
        let ids = self.start(client, replicates).await?;
        let label = format!("{} {}", setting.case, self.label);
        let mut library_runs = watch(client, &ids, &label).await?;
        let lattice_runs = if self.searches_lattice() {
            library_runs.split_off(library_runs.len() - replicates as usize)
        } else {
            Vec::new()
        };
        let adaptive_runs = if grid {
            library_runs.split_off(library_runs.len() - replicates as usize)
        } else {
            Vec::new()
        };
        let guarded_run = grid.then(|| library_runs.pop()).flatten();
        let exact = exact_report(ExactQuestion {
            case: setting.case.into(),
            preset: Some(setting.preset.into()),
            exposure: self.exposure.clone(),
            vut: self.vut.clone(),
            library_file: self.file.to_vec(),
            epsilon: setting.epsilon,
            outside: library_runs[0].outside,
            beta: setting.beta,
            confidence: 0.9,
        })
        .await?;
        let (expected, source) = expected_ndd(&library_runs, exact.as_ref(), setting.beta);
        let ndd_run = if expected.is_finite() && expected <= budget as f64 {
            Some(self.ndd_baseline(client, expected, &label).await?)
        } else {
            None
        };
        let (ndd_tests, ndd_source) = match &ndd_run {
            Some(v) => (v.tests as f64, NddSource::Run),
            None => (expected, source),
        };
        Ok(Row {
            case: setting.case,
            preset: setting.preset,
            exposure: self.library.exposure.clone(),
            surrogate: setting.surrogate,
            library_size: self.library.size.unwrap_or(0),
            total_scenarios: self.library.total_scenarios,
            vehicle: self.label,
            epsilon: setting.epsilon,
            beta: setting.beta,
            library_runs,
            guarded_run,
            adaptive_runs,
            lattice_runs,
            ndd_run,
            ndd_tests,
            ndd_source,
            exact,
            paper: setting.paper,
        })
    }

    /// Whether its adaptive campaigns also search a coarser lattice: on a
    /// grid too fine to search cell by cell (highway-exit's paper grid;
    /// docs/adaptive-design.md, "Fine grids"). On a smaller grid the
    /// lattice is the grid and the campaigns would repeat the grid's.
    fn searches_lattice(&self) -> bool {
        self.setting.grid
            && self.library.total_scenarios > tslg_method::adaptive::MAX_LATTICE_POINTS as u64
    }

    /// Starts the seeded library campaigns and, on grid cases, one that
    /// does not assume the library covers the vehicle's failures (the
    /// outside guard, with ε 0.5 spread by the exposure so exploring tests
    /// weigh at most P(X∖Φ)/ε) and as many adaptive campaigns, same seeds
    /// (stages that learn where this vehicle fails; docs/statistics.md),
    /// then on a fine grid as many that search its lattice.
    async fn start(&self, client: &Client, replicates: u64) -> anyhow::Result<Vec<i64>> {
        let mut ids = Vec::new();
        for k in 0..replicates {
            let request = self.request(Method::Library, self.seed + k);
            ids.push(client.create_campaign(&request).await?.id);
        }
        if self.setting.grid {
            let mut request = self.request(Method::Library, self.seed);
            request.epsilon = 0.5;
            request.outside = Some(Outside::Ndd);
            request.guard_outside = Some(true);
            ids.push(client.create_campaign(&request).await?.id);
            for k in 0..replicates {
                let request = self.request(Method::Adaptive, self.seed + k);
                ids.push(client.create_campaign(&request).await?.id);
            }
        }
        if self.searches_lattice() {
            for k in 0..replicates {
                let request = CreateCampaign {
                    adaptive_search: Some(AdaptiveSearch::Lattice),
                    ..self.request(Method::Adaptive, self.seed + k)
                };
                ids.push(client.create_campaign(&request).await?.id);
            }
        }
        Ok(ids)
    }

    /// The NDD baseline run to β, with room for an unlucky run: a budget of
    /// five times the `expected` count.
    async fn ndd_baseline(
        &self,
        client: &Client,
        expected: f64,
        label: &str,
    ) -> anyhow::Result<CampaignView> {
        let mut ndd = self.request(Method::Ndd, self.seed);
        ndd.max_tests = ((5.0 * expected) as u64).max(100_000);
        let id = client.create_campaign(&ndd).await?.id;
        Ok(watch(client, &[id], &format!("{label} ndd")).await?[0].clone())
    }
}

/// The NDD baseline's expected tests at β, 90%: from the exact `P(A)` where
/// it exists, else from the median of the library campaigns' estimates.
fn expected_ndd(
    library_runs: &[CampaignView],
    exact: Option<&ExactReport>,
    beta: f64,
) -> (f64, NddSource) {
    if let Some(report) = exact {
        return (report.ndd_tests, NddSource::AnalyticExact);
    }
    let mut estimates: Vec<f64> = library_runs.iter().filter_map(|v| v.estimate).collect();
    estimates.sort_by(f64::total_cmp);
    match lower_median(&estimates) {
        Some(&mu) if mu > 0.0 => (
            expected_ndd_tests(mu, beta, z_for_confidence(0.9)),
            NddSource::AnalyticEstimate,
        ),
        _ => (f64::INFINITY, NddSource::AnalyticEstimate),
    }
}

/// Polls the campaigns `ids` with a bar each until all have stopped.
async fn watch(client: &Client, ids: &[i64], label: &str) -> anyhow::Result<Vec<CampaignView>> {
    let labels: Vec<String> = (0..ids.len())
        .map(|k| {
            if ids.len() == 1 {
                label.to_owned()
            } else {
                format!("{label} ({})", k + 1)
            }
        })
        .collect();
    watch_campaigns(
        client,
        ids,
        &labels.iter().map(String::as_str).collect::<Vec<_>>(),
    )
    .await
}
