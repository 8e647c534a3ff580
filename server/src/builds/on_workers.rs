//! Library builds on workers. The coordinator runs no program, so a
//! build whose surrogate is one always runs here; with `--library-builds
//! workers` so does an exhaustive build with a built-in surrogate. The
//! surrogate's runs on every cell with exposure are the
//! tests of a campaign of method `enumerate` (test `i`: the surrogate on the
//! `i`-th cell; `library_id`: the library being built), leased to the
//! workers that offer the program under the same fences, reports, checks
//! and restarts as any campaign. When every test has its result, the
//! events give the exhaustive library ([`ScenarioCase::library_from_enumeration`]);
//! a test without a valid outcome fails the build with the program's reason.
//! The library is the same whatever the number of workers and whoever ran
//! which cell: each cell's outcome is the program's, and the library a
//! function of the set of cells with the event.

use crate::error::ServiceError;
use crate::state::AppState;
use crate::store::campaigns::{self, CampaignRow, NewCampaign};
use crate::store::libraries::{self, Built, LibraryRow};
use crate::store::reports;
use std::sync::Arc;
use tslg_api::{CampaignStatus, CreateLibrary, LibraryStatus, Method, Outside, Split};
use tslg_method::estimator::StoppingRule;
use tslg_method::external::ExternalVut;
use tslg_method::prefix::SparseOutcome;
use tslg_method::registry::{BuildRequest, LibraryBuilder};

/// Whether a build request's surrogate is a program, which only workers
/// can run.
fn is_program(surrogate: &serde_json::Value) -> bool {
    ExternalVut::from_spec(surrogate).is_some()
}

/// Where a library is built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Placement {
    /// On the coordinator ([`crate::builds::local`]).
    Coordinator,
    /// On workers, cell by cell: a campaign of method `enumerate`.
    Cells,
    /// On one worker, whole: a campaign of method `build`
    /// ([`crate::builds::whole`]).
    Whole,
}

/// Where the build of `surrogate` runs: a program's always on workers
/// (when [`check`] allows it), a built-in surrogate's on workers when the
/// coordinator sends builds there (`place`). An exhaustive search of a
/// grid case is leased cell by cell; a search that picks its next runs
/// from the last (multistart, a car-following policy) goes whole to one
/// worker.
pub fn placement(
    place: crate::config::BuildPlace,
    case: &dyn LibraryBuilder,
    request: &BuildRequest,
    surrogate: &serde_json::Value,
) -> Result<Placement, String> {
    use tslg_method::library::{LibrarySearch, SearchMethod};
    let search = request.search.unwrap_or(case.descriptor().default_search);
    if is_program(surrogate) {
        // A user-defined case's worker runs a multistart search through
        // its program: whole, on one worker offering it.
        let user = tslg_method::cases::user::registry::get(case.name()).is_some();
        if user
            && matches!(
                request.search,
                Some(LibrarySearch::Cells(SearchMethod::Multistart { .. }))
            )
        {
            return Ok(Placement::Whole);
        }
        return check(case, request).map(|()| Placement::Cells);
    }
    let by_cells =
        case.descriptor().is_grid() && search == LibrarySearch::Cells(SearchMethod::Exhaustive);
    Ok(match place {
        crate::config::BuildPlace::Coordinator => Placement::Coordinator,
        crate::config::BuildPlace::Workers if by_cells => Placement::Cells,
        crate::config::BuildPlace::Workers => Placement::Whole,
    })
}

/// Checks that a program surrogate's build can run on workers: a grid case
/// and exhaustive search (the search the cells' runs make; multistart with
/// a program runs offline, `tslg library build --case-file`).
pub fn check(case: &dyn LibraryBuilder, request: &BuildRequest) -> Result<(), String> {
    if !case.descriptor().is_grid() {
        return Err(format!(
            "a library of case {} is learned from a built-in surrogate; programs drive its \
             campaigns, not its builds",
            case.name()
        ));
    }
    match request.search {
        None
        | Some(tslg_method::library::LibrarySearch::Cells(
            tslg_method::library::SearchMethod::Exhaustive,
        )) => Ok(()),
        Some(_) => Err(
            "a build with a program as surrogate on a built-in case runs on workers by \
             exhaustive search (every cell once); multistart through a program runs on a \
             user-defined case (tslg case create) or offline (tslg library build --case-file)"
                .into(),
        ),
    }
}

/// Starts the build of `library` on workers: its enumeration campaign.
pub async fn start(
    state: &AppState,
    library: &LibraryRow,
    case: Arc<dyn LibraryBuilder>,
    surrogate: &serde_json::Value,
) -> Result<CampaignRow, ServiceError> {
    let spec = surrogate.clone();
    let (tests, len) = tokio::task::spawn_blocking(move || {
        let tests = case.enumeration(&spec)?;
        Ok::<_, tslg_method::registry::CaseError>((tests, case.enumeration_len()))
    })
    .await
    .map_err(|e| ServiceError::Internal(e.into()))?
    .map_err(|e| ServiceError::Unprocessable(e.to_string()))?;
    // Every cell once: the rule holds only when all are in.
    let rule = StoppingRule {
        n_min: len,
        min_events: 1,
        ..StoppingRule::new(tslg_method::estimator::MAX_BETA, len.max(1))
    };
    let row = insert_build(state, library, Method::Enumerate, surrogate, rule).await?;
    state.samplers.insert(row.id, tests);
    state.work.announce();
    tracing::info!(
        library = library.id,
        campaign = row.id,
        cells = len,
        "library build leased to workers"
    );
    Ok(row)
}

/// Inserts the campaign that builds `library` on workers (method
/// `enumerate` or `build`), running; a program's build goes only to workers
/// offering it.
pub async fn insert_build(
    state: &AppState,
    library: &LibraryRow,
    method: Method,
    surrogate: &serde_json::Value,
    rule: StoppingRule,
) -> Result<CampaignRow, ServiceError> {
    let requires = ExternalVut::from_spec(surrogate)
        .and_then(Result::ok)
        .map(|e| e.requirement(&library.case_name));
    let new = NewCampaign {
        case_name: library.case_name.clone(),
        preset: library.preset.clone(),
        method,
        library_id: Some(library.id),
        exposure_name: library.exposure_name.clone(),
        exposure_fingerprint: library.exposure_fingerprint.clone(),
        exposure_table: library.exposure_table.clone(),
        vut: surrogate.to_string(),
        requires,
        epsilon: 0.0,
        outside: Outside::Uniform,
        split: Split::Random,
        rule,
        seed: 0,
        status: CampaignStatus::Running,
        exact_probability: None,
        parameters_inert: None,
        vehicle_noise: false,
        adaptive_search: tslg_api::AdaptiveSearch::Grid,
        // A build has no stages; the column holds the default length.
        stage_tests: tslg_method::adaptive::AdaptiveSettings::default().stage_tests,
        search_width: 0,
        first_stage: None,
    };
    Ok(state
        .db
        .write(move |conn| campaigns::insert(conn, &new))
        .await?)
}

/// The enumeration campaign of library `id`, if it is built on workers.
pub async fn campaign_of(state: &AppState, id: i64) -> Result<Option<CampaignRow>, ServiceError> {
    Ok(state
        .db
        .read(move |conn| campaigns::building_library(conn, id))
        .await?)
}

/// Records the library of a stopped enumeration campaign: ready from its
/// events, or failed with the reason (a cell without a valid outcome, a
/// cancelled build). Harmless when the library is done already.
pub async fn finish(state: &AppState, campaign_id: i64) -> Result<(), ServiceError> {
    let campaign = state
        .db
        .read(move |conn| campaigns::get(conn, campaign_id))
        .await?;
    let Some(id) = campaign
        .library_id
        .filter(|_| campaign.method.builds_library())
    else {
        return Ok(());
    };
    let library = state.db.read(move |conn| libraries::get(conn, id)).await?;
    if library.status != LibraryStatus::Building || !campaign.status.is_final() {
        return Ok(());
    }
    if matches!(
        campaign.status,
        CampaignStatus::Cancelled | CampaignStatus::Failed
    ) {
        let reason = format!(
            "its build (campaign {campaign_id}) was {}: {}",
            campaign.status.as_str(),
            campaign
                .status_detail
                .as_deref()
                .unwrap_or("no reason given")
        );
        return mark_failed(state, id, reason).await;
    }
    if campaign.method.runs_whole() {
        // Its upload recorded the library with the campaign's end.
        return Ok(());
    }
    let indices = campaign.indices as u64;
    let (outcomes, invalid) = state
        .db
        .read(move |conn| -> Result<_, ServiceError> {
            let outcomes = reports::outcomes(conn, campaign_id, 0, indices)?;
            let Some(&(index, _)) = outcomes
                .iter()
                .find(|(_, o)| matches!(o, SparseOutcome::Invalid))
            else {
                return Ok((outcomes, None));
            };
            let reason = reports::invalid_reason(conn, campaign_id, index)?;
            Ok((outcomes, Some((index, reason))))
        })
        .await?;
    if let Some((index, reason)) = invalid {
        let reason = format!(
            "the surrogate gave no valid outcome at test {index} of its build (campaign \
             {campaign_id}): {}",
            reason.unwrap_or_else(|| "no reason recorded".into())
        );
        return mark_failed(state, id, reason).await;
    }
    let events: Vec<u64> = outcomes.into_iter().map(|(i, _)| i).collect();
    let request: CreateLibrary =
        serde_json::from_str(&library.request).map_err(|e| ServiceError::Internal(e.into()))?;
    let threshold = crate::builds::request::build_request(&request)
        .map_err(ServiceError::Unprocessable)?
        .threshold;
    let source = library.exposure_source();
    let surrogate: serde_json::Value =
        serde_json::from_str(&campaign.vut).map_err(|e| ServiceError::Internal(e.into()))?;
    let (case_name, preset) = (library.case_name.clone(), library.preset.clone());
    let built = tokio::task::spawn_blocking(move || {
        let case = tslg_method::cases::open_case(&case_name, Some(&preset), &source)?;
        case.library_from_enumeration(&surrogate, threshold, &events)
    })
    .await
    .map_err(|e| ServiceError::Internal(e.into()))?;
    match built {
        Ok(built) => {
            let (size, seconds) = (built.size, campaign.worker_seconds);
            state
                .db
                .write(move |conn| libraries::mark_ready(conn, id, &Built::of(&built, seconds)))
                .await?;
            // Its pending campaigns run now.
            state.work.announce();
            tracing::info!(library = id, size, "library built on workers");
            Ok(())
        }
        Err(e) => mark_failed(state, id, e.to_string()).await,
    }
}

/// Marks library `id` failed for `reason`.
async fn mark_failed(state: &AppState, id: i64, reason: String) -> Result<(), ServiceError> {
    Ok(state
        .db
        .write(move |conn| libraries::mark_failed(conn, id, &reason))
        .await?)
}

/// What a library built on workers shows while it builds: its cells done
/// of all, and, while no live worker offers its program, that it waits for
/// one.
pub async fn progress(
    state: &AppState,
    view: &mut tslg_api::LibraryView,
) -> Result<(), ServiceError> {
    if view.status != LibraryStatus::Building {
        return Ok(());
    }
    let Some(campaign) = campaign_of(state, view.id).await? else {
        return Ok(());
    };
    if campaign.method.runs_whole() {
        view.status_detail = Some(if state.workers.counts().0 == 0 {
            "waiting for a worker: the coordinator leases this build whole to one worker \
             (--library-builds workers)"
                .to_owned()
        } else {
            format!(
                "built whole by one worker as campaign {} (GET /api/v1/workers lists them)",
                campaign.id
            )
        });
        return Ok(());
    }
    view.progress = Some(tslg_api::BuildProgress {
        done: campaign.indices as u64,
        total: campaign.max_tests as u64,
    });
    view.status_detail = Some(match &campaign.requires {
        Some(requirement) if state.workers.live_offering(requirement).is_empty() => format!(
            "waiting for a worker offering {requirement} (tslg-worker --vut-exec; GET \
             /api/v1/workers lists what each offers): the coordinator runs no program"
        ),
        None if state.workers.counts().0 == 0 => format!(
            "waiting for a worker: the coordinator leases this build's {} surrogate runs to \
             workers (--library-builds workers)",
            campaign.max_tests
        ),
        _ => format!(
            "surrogate runs leased to workers as campaign {}: {} of {} cells",
            campaign.id, campaign.indices, campaign.max_tests
        ),
    });
    Ok(())
}
