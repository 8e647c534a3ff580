//! Starting a campaign: the request checked against the method's ranges
//! and the coordinator's libraries, its tests prepared as a worker will
//! (what a worker could not prepare is refused here, not leased forever),
//! and the campaign stored `running`, or `pending` while its library builds.

use super::stage_size;
use crate::error::ServiceError;
use crate::state::AppState;
use crate::store::campaigns::{self, CampaignRow, NewCampaign};
use crate::store::libraries::{self, LibraryRow};
use crate::store::pairs;
use crate::validate::check_name;
use std::sync::Arc;
use tslg_api::{
    CampaignStatus, CreateCampaign, IntervalKind, LibraryStatus, Method, EXACT_MAX_SCENARIOS,
};
use tslg_client::wire;
use tslg_method::adaptive::AdaptiveSettings;
use tslg_method::cases::open_case;
use tslg_method::cases::{descriptor, descriptors};
use tslg_method::estimator::{default_n_min, StoppingRule, DEFAULT_MIN_EVENTS};
use tslg_method::external::ExternalVut;
use tslg_method::registry::{CampaignTests, CaseError, ExposureSource, ScenarioCase};
use tslg_method::sampling::{check_epsilon, default_outside, OutsideSpread, Split};

fn bad(message: impl Into<String>) -> ServiceError {
    ServiceError::Unprocessable(message.into())
}

/// The names of the grid cases, comma-separated.
fn grid_cases() -> String {
    descriptors()
        .iter()
        .filter(|d| d.is_grid())
        .map(|d| d.name)
        .collect::<Vec<_>>()
        .join(", ")
}

/// The stopping rule a request asks for, with the defaults filled in, and
/// every number checked against the method's ranges; pure.
pub fn rule_of(req: &CreateCampaign) -> Result<StoppingRule, ServiceError> {
    check_name("case", &req.case, 64)?;
    let method = req.method.spec();
    if !method.requestable {
        return Err(bad(format!(
            "method `{}` is the coordinator's own, for library builds on workers: POST \
             /api/v1/libraries starts one",
            req.method.as_str()
        )));
    }
    let case = descriptor(&req.case).map_err(|e| bad(e.to_string()))?;
    check_epsilon(req.epsilon).map_err(|e| bad(e.to_string()))?;
    // A noisy vehicle's campaign runs under the guard unless it says not to.
    let guard_outside = wire::guard_outside(req, case.is_grid());
    let rule = StoppingRule {
        beta: req.beta,
        confidence: req.confidence,
        n_min: req.n_min.unwrap_or_else(|| {
            default_n_min(
                case.exploring_share(method.waits_for_explorers, req.epsilon),
                req.max_tests,
            )
        }),
        min_events: req.min_events.unwrap_or(DEFAULT_MIN_EVENTS),
        max_tests: req.max_tests,
        guard_outside,
        interval: wire::interval(req.interval),
    };
    rule.validate().map_err(|e| bad(e.to_string()))?;
    if guard_outside && !method.explores {
        return Err(bad(
            "guard_outside bounds the failure mass outside a library; an ndd campaign samples \
             every scenario by its exposure and has no outside to guard",
        ));
    }
    if method.in_stages && !case.is_grid() {
        return Err(bad(format!(
            "method `adaptive` runs through the service on the grid cases ({}); a {} adaptive \
             campaign probes the vehicle from grid states, which workers cannot be leased yet: \
             run it in process with `tslg library build --case {} -o POLICY` and `tslg \
             evaluate --library POLICY --method adaptive` (docs/adaptive-design.md)",
            grid_cases(),
            req.case,
            req.case
        )));
    }
    if req.adaptive_search.is_some() && !method.in_stages {
        return Err(bad(format!(
            "adaptive_search chooses how an adaptive campaign searches around its failures; method \
             `{}` does not search: leave it out, or use method `adaptive`",
            req.method.as_str()
        )));
    }
    match req.stage_tests {
        Some(_) if !method.in_stages => {
            return Err(bad(format!(
                "stage_tests sets the length of an adaptive campaign's estimation stages; \
                 method `{}` has no stages: leave it out, or use method `adaptive`",
                req.method.as_str()
            )))
        }
        Some(tests) if !stage_size::valid(tests) => {
            return Err(bad(format!(
                "stage_tests = {tests} must be a multiple of 20 from 20 to {}",
                stage_size::MAX_STAGE_TESTS
            )))
        }
        _ => {}
    }
    if req.paired_with.is_some() && !method.pairs {
        return Err(bad(format!(
            "paired_with runs methods `library` and `ndd`: an {} campaign's stages follow \
             one vehicle's failures, so two vehicles would not draw the same tests",
            req.method.as_str()
        )));
    }
    if req.paired_with.is_some() && guard_outside {
        return Err(bad(
            "paired_with estimates the difference of two rates; guard_outside bounds one \
             campaign's outside mass, and no guard is defined for a difference: run the \
             guarded campaigns separately",
        ));
    }
    if req.interval == IntervalKind::Anytime && !(case.is_grid() && method.anytime) {
        return Err(bad(format!(
            "interval `anytime` applies to the library and ndd campaigns of the grid cases ({}): {}",
            grid_cases(),
            if !case.is_grid() {
                "a car-following test's weight has no known largest value to bet against"
            } else {
                "an adaptive campaign's stages and a library build have no confidence sequence yet"
            }
        )));
    }
    if req.interval == IntervalKind::Anytime
        && method.explores
        && req.split == Some(tslg_api::Split::Random)
    {
        return Err(bad(
            "interval `anytime` reads one sequence per stratum of a library campaign, which \
             needs split `stratified` (the default): under the random split the outside has no \
             bound that holds at every n",
        ));
    }
    if req.interval == IntervalKind::Anytime && req.paired_with.is_some() {
        return Err(bad(
            "paired_with stops on the difference of two rates at its looks; interval `anytime` is a sequence for one rate: run the two campaigns apart",
        ));
    }
    if guard_outside && !case.is_grid() {
        return Err(bad(format!(
            "guard_outside applies to the grid cases ({}): a {} campaign explores per \
             decision, and no bound on its outside mass is defined",
            grid_cases(),
            req.case
        )));
    }
    Ok(rule)
}

/// The library a request names, checked against it.
async fn library_of(
    state: &AppState,
    req: &CreateCampaign,
) -> Result<Option<LibraryRow>, ServiceError> {
    let library = match req.library_id {
        None if req.method.uses_library() => {
            return Err(bad(format!(
                "method `{}` needs a library_id",
                req.method.as_str()
            )))
        }
        None => None,
        Some(id) => Some(
            state
                .db
                .read(move |conn| libraries::get(conn, id))
                .await
                .map_err(|_| bad(format!("library_id {id} does not name a library")))?,
        ),
    };
    if let Some(lib) = &library {
        if lib.case_name != req.case {
            return Err(bad(format!(
                "library {} was built for case `{}`, not `{}`",
                lib.id, lib.case_name, req.case
            )));
        }
        if lib.status == LibraryStatus::Failed && req.method.uses_library() {
            return Err(bad(format!(
                "library {} failed to build: {}",
                lib.id,
                lib.error.as_deref().unwrap_or("unknown reason")
            )));
        }
    }
    Ok(library)
}

/// The case opened for the campaign, its vehicle in full, the spread of ε,
/// its tests when they can be prepared now (an NDD campaign, or a ready
/// library) and its exact `P(A)` where the case can enumerate it.
struct Opened {
    case: Arc<dyn ScenarioCase>,
    vut: serde_json::Value,
    outside: OutsideSpread,
    split: Split,
    tests: Option<Arc<dyn CampaignTests>>,
    exact_probability: Option<f64>,
    parameters_inert: Option<bool>,
}

fn open(
    req: &CreateCampaign,
    rule: &StoppingRule,
    preset: Option<&str>,
    exposure: &ExposureSource,
    file: Option<&[u8]>,
) -> Result<Opened, CaseError> {
    let case = open_case(&req.case, preset, exposure)?;
    let vut = case.normalise_vehicle(&tslg_api::vehicle_spec(&req.vut))?;
    let outside = match req.outside {
        Some(o) => wire::outside_spread(o),
        None => default_outside(case.default_outside(), rule),
    };
    let split = req.split.map_or(Split::default(), wire::split);
    // The coordinator's copy of the campaign's tests: the one place a
    // method's sampler is chosen (a build's tests come from its library's
    // build, builds/on_workers.rs).
    let tests = match (req.method, file) {
        (Method::Adaptive, Some(file)) => Some(case.adaptive_tests(
            file,
            &vut,
            req.epsilon,
            wire::adaptive_settings(
                req.vehicle_noise,
                req.adaptive_search.unwrap_or_default(),
                req.stage_tests.unwrap_or(stage_size::DEFAULT_STAGE_TESTS),
            ),
            rule,
            req.seed,
        )?),
        (Method::Ndd, _) | (Method::Library, Some(_)) => {
            Some(case.campaign(file, &vut, req.epsilon, outside, split, req.seed)?)
        }
        _ => None,
    };
    // Built-in vehicles on small grids only: an external program does not
    // run on the coordinator, car-following has no grid to enumerate, and a
    // large grid would hold the request for seconds.
    // A noisy vehicle's is a Monte Carlo of 1,000 runs a cell: smaller grids.
    let limit = if tslg_method::noise::spec_is_noisy(&vut) {
        tslg_method::noise::NOISY_EXACT_MAX_SCENARIOS
    } else {
        EXACT_MAX_SCENARIOS
    };
    let exact_probability = (case.total_scenarios() <= limit)
        .then(|| case.exact_event_probability(&vut).ok())
        .flatten();
    let parameters_inert = exact_probability
        .and_then(|p| tslg_method::registry::parameters_inert(case.as_ref(), &vut, p));
    Ok(Opened {
        case,
        vut,
        outside,
        split,
        tests,
        exact_probability,
        parameters_inert,
    })
}

/// Starts the campaign `req` asks for; for a paired regression campaign
/// (`paired_with`), both of its campaigns, linked, and answers vehicle a's.
pub async fn start(state: &AppState, req: CreateCampaign) -> Result<CampaignRow, ServiceError> {
    let rule = rule_of(&req)?;
    // An adaptive campaign's stages keep the fleet that offers its vehicle
    // busy ([`stage_size`]), unless the request fixes their length.
    let req = match (req.method.in_stages(), req.stage_tests) {
        (true, None) => {
            let requires = requirement(&tslg_api::vehicle_spec(&req.vut), &req.case);
            let threads = state.workers.fleet().serving(requires.as_deref());
            CreateCampaign {
                stage_tests: Some(stage_size::for_fleet(threads)),
                ..req
            }
        }
        _ => req,
    };
    let library = library_of(state, &req).await?;
    let exposure = library.as_ref().map_or(ExposureSource::Builtin, |lib| {
        wire::stored_exposure(&lib.exposure_name, lib.exposure_table.as_ref())
    });
    let preset = library.as_ref().map(|l| l.preset.clone());
    let file = match &library {
        Some(lib) if req.method.uses_library() && lib.status == LibraryStatus::Ready => Some({
            let id = lib.id;
            state
                .db
                .read(move |conn| libraries::file(conn, id))
                .await?
                .ok_or_else(|| {
                    ServiceError::Internal(anyhow::anyhow!("ready library {} has no file", lib.id))
                })?
                .bytes
        }),
        _ => None,
    };
    // Vehicle b of a pair: the same request with its vehicle.
    let requests: Vec<CreateCampaign> = std::iter::once(req.clone())
        .chain(
            req.paired_with
                .clone()
                .map(|vut| CreateCampaign { vut, ..req.clone() }),
        )
        .collect();
    let (source, requested) = (exposure.clone(), requests.clone());
    let paired = req.paired_with.is_some();
    let opened = tokio::task::spawn_blocking(move || {
        requested
            .iter()
            .enumerate()
            .map(|(k, request)| {
                open(request, &rule, preset.as_deref(), &source, file.as_deref()).map_err(
                    |e| match (paired, k) {
                        (false, _) => e.to_string(),
                        (true, 0) => format!("vut: {e}"),
                        (true, _) => format!("paired_with: {e}"),
                    },
                )
            })
            .collect::<Result<Vec<Opened>, String>>()
    })
    .await
    .map_err(|e| ServiceError::Internal(e.into()))?
    .map_err(bad)?;
    let status = match &library {
        Some(lib) if req.method.uses_library() && lib.status == LibraryStatus::Building => {
            CampaignStatus::Pending
        }
        _ => CampaignStatus::Running,
    };
    let table = match exposure {
        ExposureSource::Table { text, .. } => Some(text),
        ExposureSource::Builtin => None,
    };
    let news: Vec<NewCampaign> = opened
        .iter()
        .map(|o| new_campaign(&req, o, rule, status, table.clone()))
        .collect();
    if req.vehicle_noise && news.iter().all(|n| n.requires.is_none()) {
        return Err(bad(
            "vehicle_noise marks an external program whose runs of one test may differ; a \
             built-in vehicle is deterministic, and the coordinator replays its tests exactly",
        ));
    }
    let rows = state
        .db
        .write(move |conn| -> Result<_, ServiceError> {
            let rows = news
                .iter()
                .map(|new| campaigns::insert(conn, new))
                .collect::<Result<Vec<_>, _>>()?;
            if let [a, b] = rows.as_slice() {
                pairs::link(conn, a.id, b.id)?;
                return Ok(vec![
                    campaigns::get(conn, a.id)?,
                    campaigns::get(conn, b.id)?,
                ]);
            }
            Ok(rows)
        })
        .await?;
    for (row, opened) in rows.iter().zip(opened) {
        if let Some(tests) = opened.tests {
            state.samplers.insert(row.id, tests);
        }
    }
    if status == CampaignStatus::Running {
        state.work.announce();
    }
    Ok(rows.into_iter().next().expect("a campaign was inserted"))
}

/// What a worker must offer to run `vut` on `case` (`NAME:case:mode`); none
/// for a built-in vehicle, which every worker runs.
fn requirement(vut: &serde_json::Value, case: &str) -> Option<String> {
    ExternalVut::from_spec(vut)
        .and_then(Result::ok)
        .map(|e| e.requirement(case))
}

/// The row to insert for `req`'s vehicle as `opened`.
fn new_campaign(
    req: &CreateCampaign,
    opened: &Opened,
    rule: StoppingRule,
    status: CampaignStatus,
    exposure_table: Option<String>,
) -> NewCampaign {
    // Only workers offering an external program get its tests.
    let requires = requirement(&opened.vut, opened.case.name());
    let external = requires.is_some();
    NewCampaign {
        case_name: opened.case.name().to_owned(),
        preset: opened.case.preset(),
        method: req.method,
        library_id: req.library_id,
        exposure_name: opened.case.exposure_name().to_owned(),
        exposure_fingerprint: opened.case.exposure_fingerprint(),
        exposure_table,
        vut: opened.vut.to_string(),
        requires,
        epsilon: req.epsilon,
        outside: wire::outside(opened.outside),
        split: wire::wire_split(opened.split),
        rule,
        seed: req.seed,
        status,
        exact_probability: opened.exact_probability,
        parameters_inert: opened.parameters_inert,
        // A built-in vehicle of a pair stays exactly replayed.
        vehicle_noise: req.vehicle_noise && external,
        adaptive_search: req.adaptive_search.unwrap_or_default(),
        stage_tests: req.stage_tests.unwrap_or(stage_size::DEFAULT_STAGE_TESTS),
        search_width: if req.method.in_stages() {
            AdaptiveSettings::fleet_search_width(
                req.stage_tests.unwrap_or(stage_size::DEFAULT_STAGE_TESTS),
            )
        } else {
            0
        },
        first_stage: req.method.in_stages().then(|| {
            (
                0,
                AdaptiveSettings::default()
                    .library_tests
                    .min(rule.max_tests),
                "library",
            )
        }),
    }
}
