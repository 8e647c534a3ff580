//! Library builds one worker runs whole: a multistart search (each descent
//! picks its next run from the last, so its runs cannot be leased cell by
//! cell) or a car-following policy (dynamic programming or temporal
//! difference over every state). With `--library-builds workers` the
//! coordinator leases such a build as a campaign of method `build` with one
//! test: the worker that takes it builds the library as `tslg library
//! build` does, heartbeating while it runs, and uploads the file to `POST
//! /api/v1/leases/{id}/library`. A worker killed mid-build stops
//! heartbeating; its lease expires and another worker builds the same
//! library from the start (the build is deterministic: its seed is in the
//! request). The coordinator checks that the file is a library of the
//! case, preset, exposure and surrogate it asked for and, on grid cases,
//! runs the surrogate again on a sample of the library's cells: each must
//! be a failure of it.

use crate::error::ServiceError;
use crate::leasing::fence;
use crate::state::AppState;
use crate::store::campaigns::{self, CampaignRow};
use crate::store::leases;
use crate::store::libraries::{self, Built, LibraryRow};
use tslg_api::{CampaignStatus, LibraryStatus, LibraryUpload, Method};
use tslg_method::estimator::StoppingRule;
use tslg_method::registry::BuiltLibrary;

/// Longest failure reason a worker's upload may carry.
const MAX_FAILURE_REASON: usize = 2000;
/// Library cells of a grid case the coordinator runs the surrogate on to
/// check an uploaded library (a few microseconds each for the built-in
/// vehicles).
const CHECKED_CELLS: usize = 64;

/// Starts the build of `library` by one worker: its campaign of method
/// `build`, one test.
pub async fn start(
    state: &AppState,
    library: &LibraryRow,
    surrogate: &serde_json::Value,
) -> Result<CampaignRow, ServiceError> {
    let rule = StoppingRule {
        n_min: 1,
        min_events: 1,
        ..StoppingRule::new(tslg_method::estimator::MAX_BETA, 1)
    };
    let row =
        crate::builds::on_workers::insert_build(state, library, Method::Build, surrogate, rule)
            .await?;
    state.work.announce();
    tracing::info!(
        library = library.id,
        campaign = row.id,
        "library build leased whole to a worker"
    );
    Ok(row)
}

/// What a worker's upload says: the library's bytes, or why the build
/// failed.
enum Uploaded {
    File(Vec<u8>),
    Failed(String),
}

fn parse(upload: &LibraryUpload) -> Result<Uploaded, ServiceError> {
    let bad = |m: String| Err(ServiceError::Unprocessable(m));
    if !(upload.seconds.is_finite() && upload.seconds >= 0.0) {
        return bad(format!(
            "seconds = {} must be a finite number ≥ 0",
            upload.seconds
        ));
    }
    match (&upload.file, &upload.failed) {
        (Some(file), None) => {
            use base64::Engine;
            base64::engine::general_purpose::STANDARD
                .decode(file)
                .map(Uploaded::File)
                .or_else(|e| bad(format!("file is not base64: {e}")))
        }
        (None, Some(reason)) if reason.is_empty() || reason.len() > MAX_FAILURE_REASON => bad(
            format!("failed must say why in 1 to {MAX_FAILURE_REASON} bytes"),
        ),
        (None, Some(reason)) => Ok(Uploaded::Failed(reason.clone())),
        _ => bad("an upload carries exactly one of file and failed".into()),
    }
}

/// The lease's campaign and library, when `upload` may be recorded on
/// lease `id`: its holder's, of a running campaign of method `build`
/// whose library is building.
fn holder_of(
    conn: &rusqlite::Connection,
    id: i64,
    upload: &Holder,
) -> Result<(CampaignRow, LibraryRow), ServiceError> {
    let lease = fence::get_unless_flagged(conn, id, &upload.worker)?;
    fence::check_fence(&lease, &upload.worker, upload.attempt, upload.key.as_str())?;
    let campaign = campaigns::get(conn, lease.campaign_id)?;
    if !campaign.method.runs_whole() {
        return Err(ServiceError::Conflict(format!(
            "lease {id} is of campaign {} of method {}: its results go to POST \
             /api/v1/leases/{id}/results",
            campaign.id,
            campaign.method.as_str()
        )));
    }
    if campaign.status != CampaignStatus::Running || lease.state != leases::LeaseState::Active {
        return Err(ServiceError::Conflict(format!(
            "campaign {} is {}: the build is no longer wanted",
            campaign.id,
            campaign.status.as_str()
        )));
    }
    let library_id = campaign
        .library_id
        .ok_or_else(|| ServiceError::Internal(anyhow::anyhow!("build without a library")))?;
    let library = libraries::get(conn, library_id)?;
    if library.status != LibraryStatus::Building {
        return Err(ServiceError::Conflict(format!(
            "library {library_id} is {}: the build is no longer wanted",
            library.status.as_str()
        )));
    }
    Ok((campaign, library))
}

/// Checks an uploaded file against what the coordinator asked for
/// ([`ScenarioCase::built_elsewhere`] and the summary's case, preset,
/// exposure and surrogate); CPU work: call off the async runtime.
///
/// [`ScenarioCase::built_elsewhere`]: tslg_method::registry::ScenarioCase::built_elsewhere
fn check_file(
    campaign: &CampaignRow,
    library: &LibraryRow,
    file: &[u8],
) -> Result<BuiltLibrary, String> {
    let case = tslg_method::cases::open_case(
        &campaign.case_name,
        Some(&campaign.preset),
        &campaign.exposure_source(),
    )
    .map_err(|e| e.to_string())?;
    let summary = case
        .library_summary(file)
        .map_err(|e| format!("it is not a library: {e}"))?;
    let surrogate: serde_json::Value =
        serde_json::from_str(&library.surrogate).map_err(|e| e.to_string())?;
    let differs = |what: &str, got: &dyn std::fmt::Debug, want: &dyn std::fmt::Debug| {
        Err(format!("its {what} is {got:?}, the build's {want:?}"))
    };
    if summary.case != campaign.case_name {
        return differs("case", &summary.case, &campaign.case_name);
    }
    if summary.preset != campaign.preset {
        return differs("preset", &summary.preset, &campaign.preset);
    }
    if summary.exposure.fingerprint != campaign.exposure_fingerprint {
        return differs(
            "exposure",
            &summary.exposure.fingerprint,
            &campaign.exposure_fingerprint,
        );
    }
    if summary.surrogate != surrogate {
        return differs("surrogate", &summary.surrogate, &surrogate);
    }
    if summary.total as i64 != library.total_scenarios {
        return differs("scenario count", &summary.total, &library.total_scenarios);
    }
    case.built_elsewhere(file, &surrogate, CHECKED_CELLS)
        .map_err(|e| e.to_string())
}

/// Who sends an upload: the lease's fence.
#[derive(Clone)]
struct Holder {
    worker: String,
    attempt: i64,
    key: String,
}

/// Records a worker's upload on lease `id`: the library ready (and its
/// campaign converged), or failed with the worker's reason. A file that is
/// not the library asked for is a 422 and changes nothing: the lease
/// expires and another worker builds it.
pub async fn upload(state: &AppState, id: i64, upload: &LibraryUpload) -> Result<(), ServiceError> {
    let uploaded = parse(upload)?;
    let holder = Holder {
        worker: upload.worker.clone(),
        attempt: upload.attempt,
        key: upload.key.as_str().to_owned(),
    };
    let (campaign, library) = {
        let holder = holder.clone();
        state
            .db
            .read(move |conn| holder_of(conn, id, &holder))
            .await?
    };
    let checked = match uploaded {
        Uploaded::Failed(reason) => Err(reason),
        Uploaded::File(file) => {
            let (c, l) = (campaign.clone(), library.clone());
            let built = tokio::task::spawn_blocking(move || check_file(&c, &l, &file))
                .await
                .map_err(|e| ServiceError::Internal(e.into()))?;
            Ok(built.map_err(|e| {
                ServiceError::Unprocessable(format!(
                    "the uploaded file is not library {}: {e}",
                    library.id
                ))
            })?)
        }
    };
    let ok = checked.is_ok();
    let seconds = upload.seconds;
    let (campaign, library) = state
        .db
        .write(move |conn| -> Result<_, ServiceError> {
            // Again in the transaction: only the first upload of the holder
            // counts.
            let (campaign, library) = holder_of(conn, id, &holder)?;
            let (status, detail) = match &checked {
                Ok(built) => {
                    libraries::mark_ready(conn, library.id, &Built::of(built, seconds))?;
                    (CampaignStatus::Converged, None)
                }
                Err(reason) => {
                    let reason = format!("worker `{}` could not build it: {reason}", holder.worker);
                    libraries::mark_failed(conn, library.id, &reason)?;
                    (CampaignStatus::Failed, Some(reason))
                }
            };
            campaigns::finish_whole_build(conn, campaign.id, status, detail.as_deref(), seconds)?;
            leases::finish(conn, id)?;
            Ok((campaign, library))
        })
        .await?;
    if ok {
        // The library's pending campaigns run now.
        state.work.announce();
    }
    tracing::info!(
        library = library.id,
        campaign = campaign.id,
        worker = %upload.worker,
        ok,
        "library built whole on a worker"
    );
    Ok(())
}
