//! A campaign's events as they leave the service (`GET
//! /api/v1/campaigns/{id}/events`, `…/tests/{index}/openscenario`): each
//! event of the resolved prefix with its test index, weight, scenario by
//! dimension name and the library's criticality of it, and any test of a
//! grid case as an OpenSCENARIO file. The scenario is the campaign's own
//! test `index` drawn again (SPEC §7), so nothing more is stored.

use crate::error::ServiceError;
use crate::state::AppState;
use crate::store::{campaigns, campaigns::CampaignRow, libraries, reports};
use anyhow::Context;
use std::collections::{BTreeMap, HashMap};
use tslg_api::{CampaignEvent, EventPage, DEFAULT_EVENTS_PAGE, MAX_EVENTS_PAGE};
use tslg_method::cases::open_case;
use tslg_method::registry::CaseViews;

async fn campaign(state: &AppState, id: i64) -> Result<CampaignRow, ServiceError> {
    Ok(state.db.read(move |conn| campaigns::get(conn, id)).await?)
}

fn case_of(row: &CampaignRow) -> Result<std::sync::Arc<dyn CaseViews>, ServiceError> {
    let case = open_case(&row.case_name, Some(&row.preset), &row.exposure_source())
        .with_context(|| format!("campaign {} cannot open its case", row.id))
        .map_err(ServiceError::Internal)?;
    Ok(case)
}

/// The page of campaign `id`'s events after test index `after` (from the
/// first when `None`), at most `limit` of them.
pub async fn page(
    state: &AppState,
    id: i64,
    after: Option<u64>,
    limit: Option<usize>,
) -> Result<EventPage, ServiceError> {
    let limit = limit.unwrap_or(DEFAULT_EVENTS_PAGE);
    if !(1..=MAX_EVENTS_PAGE).contains(&limit) {
        return Err(ServiceError::BadRequest(format!(
            "limit = {limit} must be in 1..={MAX_EVENTS_PAGE}"
        )));
    }
    let row = campaign(state, id).await?;
    let resolved = row.indices.max(0) as u64;
    let tests = state.samplers.peek(&state.db, &row).await?;
    // An adaptive campaign's estimate counts its estimation stages' tests
    // only: its library and search stages' events (where it looked for
    // the vehicle's failures) are not listed.
    let counted = |index: u64| {
        tests
            .adaptive()
            .is_none_or(|stages| stages.stage_kind(index) == Some("estimate"))
    };
    let mut from = after.map_or(0, |a| a.saturating_add(1));
    let mut found = Vec::new();
    while found.len() <= limit && from < resolved {
        let batch = state
            .db
            .read(move |conn| reports::events_page(conn, id, from, resolved, limit + 1))
            .await?;
        let last = batch.len() <= limit;
        from = batch.last().map_or(resolved, |&(i, _)| i + 1);
        found.extend(batch.into_iter().filter(|&(i, _)| counted(i)));
        if last {
            break;
        }
    }
    let more = found.len() > limit;
    found.truncate(limit);
    let library = match row.library_id {
        Some(library) if row.method.uses_library() => state
            .db
            .read(move |conn| libraries::file(conn, library))
            .await?
            .map(|f| f.bytes),
        _ => None,
    };
    let case_row = row.clone();
    let (dimensions, events) = tokio::task::spawn_blocking(move || {
        let case = case_of(&case_row)?;
        let dimensions = case.dimension_names();
        let criticality: HashMap<usize, f64> = match &library {
            Some(file) => case
                .library_criticalities(file)
                .context("the campaign's library cannot be read")?,
            None => HashMap::new(),
        };
        let events = found
            .into_iter()
            .map(|(index, weight)| {
                let planned = tests.planned(index);
                let scenario = planned.as_ref().map(|p| {
                    dimensions
                        .iter()
                        .cloned()
                        .zip(p.scenario.iter().copied())
                        .collect::<BTreeMap<_, _>>()
                });
                CampaignEvent {
                    test_index: index,
                    weight,
                    cell: planned.as_ref().map(|p| p.cell as u64),
                    scenario,
                    criticality: planned
                        .as_ref()
                        .and_then(|p| criticality.get(&p.cell).copied()),
                }
            })
            .collect::<Vec<_>>();
        Ok::<_, anyhow::Error>((dimensions, events))
    })
    .await
    .context("event export task failed")??;
    Ok(EventPage {
        campaign_id: id,
        case: row.case_name.clone(),
        dimensions,
        resolved,
        next_after: if more {
            events.last().map(|e| e.test_index)
        } else {
            None
        },
        events,
    })
}

/// Test `index` of campaign `id` as an OpenSCENARIO 1.0 document.
pub async fn openscenario(state: &AppState, id: i64, index: u64) -> Result<String, ServiceError> {
    let row = campaign(state, id).await?;
    let budget = row.max_tests.max(0) as u64;
    if index >= budget {
        return Err(ServiceError::NotFound(format!(
            "campaign {id} has no test {index} (its tests are 0..{budget})"
        )));
    }
    let tests = state.samplers.peek(&state.db, &row).await?;
    tokio::task::spawn_blocking(move || {
        let case = case_of(&row)?;
        let no_file = || {
            ServiceError::NotFound(format!(
                "campaign {id} is of case {}, whose scenarios have no OpenSCENARIO form \
                 (grid cases do: cut-in, highway-exit)",
                row.case_name
            ))
        };
        if !case.descriptor().is_grid() {
            return Err(no_file());
        }
        let planned = tests.planned(index).ok_or_else(|| {
            ServiceError::NotFound(format!(
                "test {index} of campaign {id} is not planned yet: an adaptive campaign plans \
                 each stage's tests when the stage before it is resolved"
            ))
        })?;
        case.openscenario(planned.cell).ok_or_else(no_file)
    })
    .await
    .context("OpenSCENARIO task failed")?
}
