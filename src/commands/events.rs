//! `tslg campaign events ID --format csv|json|xosc`: a campaign's events
//! leave the service, page by page (`GET /api/v1/campaigns/{id}/events`),
//! as a table, as JSON, or as one OpenSCENARIO file per event that another
//! simulator can replay (`GET …/tests/{index}/openscenario`, with the
//! straight road they name written beside them).

use crate::args::ServerArgs;
use crate::commands::remote::{block_on, client};
use anyhow::Context;
use clap::ValueEnum;
use std::path::Path;
use tslg_api::{CampaignEvent, EventPage, MAX_EVENTS_PAGE};
use tslg_method::openscenario::{straight_road_xodr, ROAD_FILE};

/// Every event of campaign `id` (at most `max`), with the first page's
/// case and dimensions.
async fn all_events(
    client: &tslg_client::Client,
    id: i64,
    max: Option<u64>,
) -> anyhow::Result<EventPage> {
    let mut page = client.events(id, None, MAX_EVENTS_PAGE).await?;
    let mut next = page.next_after.take();
    let full = |page: &EventPage| max.is_some_and(|m| page.events.len() as u64 >= m);
    while let (Some(after), false) = (next, full(&page)) {
        let more = client.events(id, Some(after), MAX_EVENTS_PAGE).await?;
        page.events.extend(more.events);
        next = more.next_after;
    }
    if let Some(max) = max {
        page.events.truncate(max as usize);
    }
    Ok(page)
}

/// How `tslg campaign events` writes the events.
#[derive(Debug, Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum EventFormat {
    Csv,
    Json,
    Xosc,
}

/// A number for the CSV: empty when absent.
fn cell(value: Option<f64>) -> String {
    value.map_or(String::new(), |v| v.to_string())
}

fn csv_row(page: &EventPage, e: &CampaignEvent) -> String {
    let mut row = format!("{},{},{}", e.test_index, e.weight, cell(e.criticality));
    for dimension in &page.dimensions {
        row.push(',');
        row.push_str(&cell(
            e.scenario.as_ref().and_then(|s| s.get(dimension).copied()),
        ));
    }
    row
}

pub fn export(
    server: &ServerArgs,
    id: i64,
    format: EventFormat,
    out: Option<&Path>,
    max: Option<u64>,
) -> anyhow::Result<()> {
    let client = client(server)?;
    match (format, out) {
        (EventFormat::Xosc, None) => {
            anyhow::bail!("--format xosc writes a file per event: give the directory with --out DIR")
        }
        (EventFormat::Csv | EventFormat::Json, Some(_)) => anyhow::bail!(
            "--out DIR is for --format xosc; csv and json go to stdout (redirect them: > events.csv)"
        ),
        _ => {}
    }
    block_on(async {
        let page = all_events(&client, id, max).await?;
        match format {
            EventFormat::Csv => {
                let mut header = String::from("test_index,weight,criticality");
                for dimension in &page.dimensions {
                    header.push(',');
                    header.push_str(dimension);
                }
                outln!("{header}");
                for e in &page.events {
                    outln!("{}", csv_row(&page, e));
                }
            }
            EventFormat::Json => outln!("{}", serde_json::to_string_pretty(&page)?),
            EventFormat::Xosc => {
                anyhow::ensure!(
                    !page.dimensions.is_empty(),
                    "campaign {id} is of case {}, whose scenarios have no OpenSCENARIO form \
                     (they are drawn decision by decision while a test runs)",
                    page.case
                );
                let dir = out.expect("checked above");
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("cannot create {}", dir.display()))?;
                let write = |name: &str, text: &str| {
                    let path = dir.join(name);
                    std::fs::write(&path, text)
                        .with_context(|| format!("cannot write {}", path.display()))
                };
                write(ROAD_FILE, &straight_road_xodr())?;
                for e in &page.events {
                    let xml = client.openscenario(id, e.test_index).await?;
                    write(&format!("campaign-{id}-test-{}.xosc", e.test_index), &xml)?;
                }
                eprintln!(
                    "{} OpenSCENARIO files and {ROAD_FILE} written to {}",
                    page.events.len(),
                    dir.display()
                );
            }
        }
        Ok(())
    })
}
