//! Results leave the service: a campaign's events, paged through the API,
//! as CSV and JSON from `tslg campaign events`, and as OpenSCENARIO files
//! that the official schema accepts and a maintained OpenSCENARIO library
//! (PyPI scenariogeneration, `scripts/check-xosc`) reads back to the
//! scenario's numbers.

use crate::support::*;
use serde_json::Value;
use std::path::Path;
use std::process::Command;
use std::time::Duration;
use tslg_api::{CampaignEvent, EventPage, Method};
use tslg_method::cases::open_case;
use tslg_method::registry::ExposureSource;

/// What `scripts/check-xosc` read from each file, after it checked them all
/// against the schema and parsed them back.
fn check_xosc(files: &[std::path::PathBuf]) -> Vec<Value> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let python = root.join("target/xosc-venv/bin/python");
    assert!(
        python.exists(),
        "scripts/install-test-deps installs the OpenSCENARIO checker into target/xosc-venv"
    );
    let o = Command::new(python)
        .arg(root.join("scripts/check-xosc"))
        .args(files)
        .output()
        .expect("run scripts/check-xosc");
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    text.lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

fn close(a: &Value, b: f64) -> bool {
    (a.as_f64().unwrap() - b).abs() < 1e-9
}

async fn get_status(url: &str) -> u16 {
    reqwest::get(url).await.unwrap().status().as_u16()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn events_leave_the_service_as_pages_tables_and_openscenario_files() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let _workers = two_workers(&server.url);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    // The FVDM on the IDM's library: events inside the library and outside.
    let request = campaign(Method::Library, library.id, "fvdm", 0.2, 3);
    let id = client.create_campaign(&request).await.unwrap().id;
    let view = finished(&client, id, Duration::from_secs(120)).await;

    // Pages of 7 hold every event of the resolved prefix once, in order.
    let mut events: Vec<CampaignEvent> = Vec::new();
    let mut after = None;
    loop {
        let page = client.events(id, after, 7).await.unwrap();
        assert_eq!(page.dimensions, ["range", "range_rate"]);
        assert_eq!(page.resolved, view.indices);
        assert!(page.events.len() <= 7);
        events.extend(page.events);
        match page.next_after {
            Some(next) => {
                assert!(after.is_none_or(|a| next > a), "the cursor moves on");
                after = Some(next);
            }
            None => break,
        }
    }
    assert_eq!(events.len() as u64, view.events);
    assert!(events.windows(2).all(|w| w[0].test_index < w[1].test_index));
    assert!(events.iter().all(|e| e.test_index < view.indices));

    // Each is the campaign's own test drawn again: its cell, its values,
    // its weight; the criticality is the library's for cells it holds.
    let file = client.library_file(library.id).await.unwrap();
    let case = open_case("cut-in", None, &ExposureSource::Builtin).unwrap();
    let tests = case
        .campaign(
            Some(&file),
            &request.vut,
            request.epsilon,
            tslg_client::wire::outside_spread(view.outside),
            tslg_client::wire::split(view.split),
            request.seed,
        )
        .unwrap();
    let criticality = case.library_criticalities(&file).unwrap();
    let (mut inside, mut outside) = (0, 0);
    for e in &events {
        let planned = tests.planned(e.test_index).unwrap();
        assert_eq!(e.cell, Some(planned.cell as u64));
        assert_eq!(e.weight, planned.weight);
        let scenario = e.scenario.as_ref().unwrap();
        assert_eq!(scenario["range"], planned.scenario[0]);
        assert_eq!(scenario["range_rate"], planned.scenario[1]);
        assert_eq!(e.criticality, criticality.get(&planned.cell).copied());
        match e.criticality {
            Some(_) => inside += 1,
            None => outside += 1,
        }
    }
    assert!(
        inside > 0 && outside > 0,
        "{inside} inside, {outside} outside"
    );

    // The command line: CSV and JSON hold the same events.
    let (url, ids) = (server.url.as_str(), id.to_string());
    let o = tslg(&["campaign", "events", &ids, "--server", url]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = String::from_utf8_lossy(&o.stdout);
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines[0], "test_index,weight,criticality,range,range_rate");
    assert_eq!(lines.len(), events.len() + 1);
    let first = &events[0];
    let scenario = first.scenario.as_ref().unwrap();
    let row = format!(
        "{},{},{},{},{}",
        first.test_index,
        first.weight,
        first.criticality.map_or(String::new(), |c| c.to_string()),
        scenario["range"],
        scenario["range_rate"]
    );
    assert_eq!(lines[1], row);
    let o = tslg(&[
        "campaign", "events", &ids, "--server", url, "--format", "json",
    ]);
    let page: EventPage = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(page.events, events);
    assert_eq!(page.next_after, None);

    // OpenSCENARIO: a file per event and the road they name, valid against
    // the 1.0 schema and read back to the scenario's numbers.
    let out = dir.path().join("xosc");
    let o = tslg(&[
        "campaign",
        "events",
        &ids,
        "--server",
        url,
        "--format",
        "xosc",
        "--max",
        "6",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut files: Vec<_> = events[..6]
        .iter()
        .map(|e| out.join(format!("campaign-{id}-test-{}.xosc", e.test_index)))
        .collect();
    files.push(out.join("tslg_straight_road.xodr"));
    assert_eq!(std::fs::read_dir(&out).unwrap().count(), 7);
    let read = check_xosc(&files);
    assert_eq!(read[6]["schema"], "opendrive_17_core.xsd");
    for (e, file) in events[..6].iter().zip(&read) {
        assert_eq!(file["schema"], "OpenSCENARIO_1_0.xsd");
        assert_eq!(file["entities"], serde_json::json!(["Ego", "CutIn"]));
        assert_eq!(file["road"], "tslg_straight_road.xodr");
        let scenario = e.scenario.as_ref().unwrap();
        let (range, rate) = (scenario["range"], scenario["range_rate"]);
        let (ego, cut_in) = (&file["init"]["Ego"], &file["init"]["CutIn"]);
        // The cut-in vehicle's rear is R ahead of the ego's front (5 m
        // vehicles), at the ego's speed (20 m/s) plus the range rate.
        assert!(
            close(&ego["speed"], 20.0) && close(&ego["s"], 100.0),
            "{file}"
        );
        assert!(close(&cut_in["s"], 105.0 + range), "{file}");
        assert!(close(&cut_in["speed"], 20.0 + rate), "{file}");
        assert_eq!(
            (ego["lane"].as_i64(), cut_in["lane"].as_i64()),
            (Some(-2), Some(-1))
        );
        let change = &file["lane_changes"][0];
        assert_eq!(change["actors"], serde_json::json!(["CutIn"]));
        assert_eq!(change["lane"], -2);
    }

    // Bad requests are refused with the reason.
    let api = format!("{url}/api/v1/campaigns/{id}");
    assert_eq!(get_status(&format!("{api}/events?limit=0")).await, 400);
    assert_eq!(get_status(&format!("{api}/events?limit=10001")).await, 400);
    assert_eq!(get_status(&format!("{api}/events?after=x")).await, 400);
    assert_eq!(get_status(&format!("{api}/events?page=2")).await, 400);
    assert_eq!(
        get_status(&format!("{url}/api/v1/campaigns/999/events")).await,
        404
    );
    let beyond = format!("{api}/tests/{}/openscenario", request.max_tests);
    assert_eq!(get_status(&beyond).await, 404);
    let o = tslg(&[
        "campaign", "events", &ids, "--server", url, "--format", "xosc",
    ]);
    assert!(clean_refusal(&o));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--out DIR"));
    let o = tslg(&["campaign", "events", &ids, "--server", url, "--out", "x"]);
    assert!(clean_refusal(&o));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--out DIR is for --format xosc"));
    // An adaptive campaign lists its estimation stages' events only: the
    // ones its estimate counts (its library and search stages looked for
    // the vehicle's failures).
    let adaptive = tslg_api::CreateCampaign {
        method: Method::Adaptive,
        ..request.clone()
    };
    let adaptive = client.create_campaign(&adaptive).await.unwrap().id;
    let view = finished(&client, adaptive, Duration::from_secs(120)).await;
    let page = client.events(adaptive, None, 10_000).await.unwrap();
    assert_eq!(page.events.len() as u64, view.events);
    let sum: f64 = page.events.iter().map(|e| e.weight).sum();
    let estimate = view.estimate.unwrap();
    assert!(
        (sum / view.tests as f64 - estimate).abs() <= 1e-12 * estimate,
        "{sum}"
    );
    // Its tests past the last planned stage have no scenario yet.
    let unplanned = format!("{url}/api/v1/campaigns/{adaptive}/tests/9000000/openscenario");
    let answer = reqwest::get(&unplanned).await.unwrap();
    assert_eq!(answer.status().as_u16(), 404);
    assert!(answer.text().await.unwrap().contains("not planned yet"));
    // Past the last event: an empty last page.
    let last = events.last().unwrap().test_index;
    let page = client.events(id, Some(last), 10).await.unwrap();
    assert!(page.events.is_empty() && page.next_after.is_none());
}

/// Every highway-exit preset's scenarios, first, middle and last cell, and
/// the cut-in's table preset, as files the schema accepts, read back to the
/// vehicles' places and speeds.
#[test]
fn highway_exit_and_cut_in_scenarios_read_back_from_openscenario() {
    let dir = scratch();
    let mut files = Vec::new();
    let mut expected = Vec::new();
    for (case_name, preset) in [("highway-exit", None), ("cut-in", Some("paper-table"))] {
        let case = open_case(case_name, preset, &ExposureSource::Builtin).unwrap();
        let cells = case.total_scenarios();
        for cell in [0, cells / 2, cells - 1] {
            let path = dir.path().join(format!("{case_name}-{cell}.xosc"));
            std::fs::write(&path, case.openscenario(cell).unwrap()).unwrap();
            files.push(path);
            expected.push((case_name, case.cell_values(cell).unwrap()));
        }
        assert!(case.openscenario(cells).is_none(), "no cell past the grid");
    }
    let read = check_xosc(&files);
    for (file, (case_name, values)) in read.iter().zip(&expected) {
        let init = &file["init"];
        if *case_name == "highway-exit" {
            // p1, v1, p2, v2: fronts from 200 m into the road, rears 5 m back.
            assert_eq!(file["entities"], serde_json::json!(["Ego", "BV1", "BV2"]));
            assert!(close(&init["Ego"]["s"], 195.0) && close(&init["Ego"]["speed"], 30.0));
            assert!(close(&init["BV1"]["s"], 195.0 + values[0]), "{file}");
            assert!(close(&init["BV1"]["speed"], values[1]), "{file}");
            assert!(close(&init["BV2"]["s"], 195.0 + values[2]), "{file}");
            assert!(close(&init["BV2"]["speed"], values[3]), "{file}");
            assert_eq!(init["Ego"]["lane"], -1);
            assert_eq!(init["BV1"]["lane"], -2);
            assert_eq!(
                file["lane_changes"][0]["actors"],
                serde_json::json!(["Ego"])
            );
        } else {
            assert!(close(&init["CutIn"]["s"], 105.0 + values[0]), "{file}");
            assert!(close(&init["CutIn"]["speed"], 20.0 + values[1]), "{file}");
        }
    }
    // The car-following case draws its scenario while it runs: no file.
    let follow = open_case("car-following", None, &ExposureSource::Builtin).unwrap();
    assert!(follow.openscenario(0).is_none());
}
