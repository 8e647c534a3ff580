//! Starting a library build: the request checked (names, threshold and
//! search), the case opened and the surrogate validated off the async
//! runtime, the library stored `building`, and the build placed on the
//! coordinator, on workers cell by cell, or whole on one worker.

use super::local::spawn_build;
use super::on_workers::{placement, Placement};
use super::request::build_request;
use crate::error::ServiceError;
use crate::state::AppState;
use crate::store::libraries::{self, LibraryRow, NewLibrary};
use crate::validate::check_name;
use tslg_api::{CreateLibrary, ExposureRequest};
use tslg_method::cases::open_case;

/// Starts the build `req` asks for; the library as stored, `building`.
pub async fn start(state: &AppState, req: CreateLibrary) -> Result<LibraryRow, ServiceError> {
    let request = build_request(&req).map_err(ServiceError::Unprocessable)?;
    check_name("case", &req.case, 64)?;
    if let Some(preset) = &req.preset {
        check_name("preset", preset, 64)?;
    }
    if let ExposureRequest::Table { name, .. } = &req.exposure {
        check_name("exposure.name", name, 256)?;
        if name.trim().is_empty() {
            return Err(ServiceError::Unprocessable(
                "exposure.name must not be empty".into(),
            ));
        }
    }
    let checked = req.clone();
    let place = state.config.library_builds;
    let (case, surrogate, placement) = tokio::task::spawn_blocking(move || {
        let case = open_case(
            &checked.case,
            checked.preset.as_deref(),
            &tslg_client::wire::exposure_source(&checked.exposure),
        )?;
        case.check_request(&request)?;
        let surrogate = case.normalise_vehicle(&tslg_api::vehicle_spec(&checked.surrogate))?;
        if tslg_method::noise::spec_is_noisy(&surrogate) {
            return Err(tslg_method::registry::CaseError::Request {
                case: case.descriptor().name,
                reason: tslg_method::noise::NOISY_SURROGATE.into(),
            });
        }
        let placement = placement(place, case.as_ref(), &request, &surrogate)
            .map_err(tslg_method::registry::CaseError::Unsupported)?;
        Ok::<_, tslg_method::registry::CaseError>((case, surrogate, placement))
    })
    .await
    .map_err(|e| ServiceError::Internal(e.into()))?
    .map_err(|e| ServiceError::Unprocessable(e.to_string()))?;
    let table = match &req.exposure {
        ExposureRequest::Builtin => None,
        ExposureRequest::Table { text, .. } => Some(text.clone()),
    };
    let request = serde_json::to_string(&req).map_err(|e| ServiceError::Internal(e.into()))?;
    let surrogate_spec = surrogate.clone();
    let surrogate = surrogate.to_string();
    let (name, preset, exposure_name) = (
        case.name().to_owned(),
        case.preset(),
        case.exposure_name().to_owned(),
    );
    let (fingerprint, note, total) = (
        case.exposure_fingerprint(),
        case.exposure_note(),
        case.total_scenarios(),
    );
    let row = state
        .db
        .write(move |conn| {
            libraries::insert(
                conn,
                &NewLibrary {
                    case_name: &name,
                    preset: &preset,
                    request: &request,
                    surrogate: &surrogate,
                    exposure_name: &exposure_name,
                    exposure_fingerprint: &fingerprint,
                    exposure_table: table.as_deref(),
                    exposure_note: note.as_deref(),
                    total_scenarios: total,
                },
            )
        })
        .await?;
    match placement {
        Placement::Coordinator => spawn_build(state.clone(), row.id),
        // Its surrogate runs are the workers' tests.
        Placement::Cells => {
            super::on_workers::start(state, &row, case, &surrogate_spec).await?;
        }
        Placement::Whole => {
            super::whole::start(state, &row, &surrogate_spec).await?;
        }
    }
    Ok(row)
}
