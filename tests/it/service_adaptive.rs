//! Adaptive campaigns through the service: the coordinator plans each stage
//! from the results of the stages before it, leases never reach past the
//! running stage and name each test's cell, and the answer is the in-process
//! one to the bit, whatever the lease size, the number of workers, a
//! coordinator restart mid-campaign, or a vehicle that is an external
//! program driven in step mode (its criticality measured by the case's own
//! loop) rather than the built-in model.

use crate::support::*;
use std::time::{Duration, Instant};
use tslg_api::{CampaignStatus, CampaignView, CreateCampaign, Method};
use tslg_method::adaptive::AdaptiveSettings;
use tslg_method::cases::open_case;
use tslg_method::estimator::{default_n_min, StoppingRule};
use tslg_method::library::SearchMethod;
use tslg_method::registry::{AdaptiveRun, BuildRequest, ExposureSource, LibrarySearch};

/// The same adaptive campaign in this process, on the IDM's exhaustive
/// library of the built-in cut-in.
fn adaptive_in_process(request: &CreateCampaign, vut: &str) -> AdaptiveRun {
    adaptive_in_process_with(request, vut, AdaptiveSettings::default())
}

/// [`adaptive_in_process`] with `settings`.
fn adaptive_in_process_with(
    request: &CreateCampaign,
    vut: &str,
    settings: AdaptiveSettings,
) -> AdaptiveRun {
    let case = open_case("cut-in", None, &ExposureSource::Builtin).unwrap();
    let library = case
        .build_library(
            &serde_json::json!({"model": "idm"}),
            &BuildRequest {
                threshold: None,
                search: Some(LibrarySearch::Cells(SearchMethod::Exhaustive)),
            },
        )
        .unwrap();
    let rule = StoppingRule {
        beta: request.beta,
        confidence: request.confidence,
        n_min: default_n_min(None, request.max_tests),
        min_events: 10,
        max_tests: request.max_tests,
        guard_outside: tslg_client::wire::guard_outside(request, true),
        interval: Default::default(),
    };
    case.adaptive_campaign(
        &library.file,
        &serde_json::json!({"model": vut}),
        request.epsilon,
        settings,
        &rule,
        request.seed,
    )
    .unwrap()
}

/// The service's campaign ended where the in-process run did, its
/// estimate and interval to the bit, with the same stages.
fn assert_same_adaptive(view: &CampaignView, own: &AdaptiveRun) {
    let r = &own.result;
    assert_eq!(view.indices, r.indices, "tests in all");
    // The stop is said in the counts the view shows: all tests used, and
    // of them the estimation tests (once "after test index 733").
    if view.status.as_str() == "converged" {
        let detail = view.status_detail.as_deref().unwrap_or_default();
        let said = format!(
            "after {} tests ({} estimation tests;",
            view.indices,
            view.tests + view.invalid
        );
        assert!(detail.contains(&said), "{detail}");
    }
    assert_eq!(
        (view.tests, view.events),
        (r.tests, r.events),
        "estimation tests"
    );
    let bits = |x: Option<f64>| x.map(f64::to_bits);
    assert_eq!(bits(view.estimate), Some(r.estimate.to_bits()), "estimate");
    assert_eq!(bits(view.ci_low), Some(r.ci_low.to_bits()), "ci_low");
    assert_eq!(bits(view.ci_high), Some(r.ci_high.to_bits()), "ci_high");
    // The bound on what the support leaves out, from the same exploring
    // tests, and the guarded upper end it gives.
    assert_eq!(
        (view.outside_tests, view.outside_events),
        (r.outside_tests, r.outside_events),
        "exploring tests"
    );
    assert_eq!(
        bits(view.outside_upper),
        bits(r.outside_upper),
        "outside_upper"
    );
    assert_eq!(
        bits(view.guarded_ci_high),
        bits(r.guarded_ci_high),
        "guarded_ci_high"
    );
    assert!(view.outside_upper.is_some());
    let a = view.adaptive.as_ref().expect("adaptive figures");
    assert_eq!(
        (a.library_tests, a.search_tests, a.stages, a.support),
        (
            own.library_tests,
            own.search_tests,
            own.stages,
            own.support.len() as u64
        ),
        "stages"
    );
    assert!(a.running.is_none());
}

/// What the campaign's page draws agrees with its view: its stages tile
/// every test it ran, library first, adding up to its library and search
/// tests, its estimation stages' events to its events, the last support to
/// its support; its history holds the estimate over its estimation tests,
/// enough points to draw a line, ending at its estimate.
async fn stages_and_history_agree(client: &tslg_client::Client, view: &CampaignView) {
    let a = view.adaptive.as_ref().unwrap();
    let stages = client.stages(view.id).await.unwrap().stages;
    assert_eq!(stages.len() as u64, a.stages, "{stages:?}");
    assert_eq!((stages[0].kind.as_str(), stages[0].start), ("library", 0));
    assert!(
        stages.windows(2).all(|w| w[0].end == w[1].start),
        "{stages:?}"
    );
    assert_eq!(stages.last().unwrap().end, view.indices);
    let tests_of = |kind: &str| -> u64 {
        stages
            .iter()
            .filter(|s| s.kind == kind)
            .map(|s| s.end - s.start)
            .sum()
    };
    assert_eq!(tests_of("library"), a.library_tests);
    assert_eq!(tests_of("search"), a.search_tests);
    // A guarded campaign's estimate starts again after a stage.
    let from = stages
        .iter()
        .rposition(|s| s.restarts_estimate)
        .map_or(0, |k| k + 1);
    assert_eq!(
        stages.iter().any(|s| s.restarts_estimate),
        view.guard_outside,
        "{stages:?}"
    );
    let events: u64 = stages[from..]
        .iter()
        .filter(|s| s.kind == "estimate")
        .map(|s| s.events)
        .sum();
    assert_eq!(events, view.events);
    assert_eq!(stages.last().unwrap().support, a.support);
    let points = client.history(view.id).await.unwrap().points;
    assert!(points.len() >= 3, "{points:?}");
    assert!(points.windows(2).all(|w| w[0].tests < w[1].tests));
    let last = points.last().unwrap();
    assert_eq!(
        (last.tests, last.estimate),
        (view.tests, view.estimate.unwrap())
    );
}

/// Waits until campaign `id` has resolved three stages and is still
/// running: the moment a test kills its coordinator.
async fn running_after_three_stages(client: &tslg_client::Client, id: i64) {
    let started = Instant::now();
    loop {
        let view = client.campaign(id).await.unwrap();
        if view.adaptive.as_ref().map_or(0, |a| a.stages) >= 3 || view.status.is_final() {
            assert_eq!(
                view.status,
                CampaignStatus::Running,
                "killed too late: {view:?}"
            );
            return;
        }
        assert!(started.elapsed() < Duration::from_secs(60), "{view:?}");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

/// A coordinator on a scratch database with leases of 37 tests (stages of
/// 100 end inside leases), two workers, and the IDM's exhaustive cut-in
/// library.
struct CutInService {
    _dir: tempfile::TempDir,
    database: std::path::PathBuf,
    server: ServerProcess,
    address: String,
    _workers: [WorkerProcess; 2],
    library: tslg_api::LibraryView,
}

async fn cut_in_service() -> CutInService {
    let dir = scratch();
    let database = dir.path().join("db.sqlite");
    let server = ServerProcess::start(&database, &["--lease-size", "37"]);
    let address = server.address.clone();
    let workers = two_workers(&server.url);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    CutInService {
        _dir: dir,
        database,
        server,
        address,
        _workers: workers,
        library,
    }
}

fn adaptive(library_id: i64, vut: serde_json::Value, seed: u64) -> CreateCampaign {
    CreateCampaign {
        vut,
        ..campaign(Method::Adaptive, library_id, "fvdm", 0.2, seed)
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_adaptive_campaign_through_the_service_is_the_in_process_one() {
    let service = cut_in_service().await;
    let (client, library) = (service.server.client(), &service.library);
    let exact = exact("fvdm");

    // The IDM's library misses most of the FVDM's failures; the adaptive
    // campaign finds them and its interval holds P(A).
    let request = adaptive(library.id, serde_json::json!({"model": "fvdm"}), 3);
    let own = adaptive_in_process(&request, "fvdm");
    assert!(own.search_tests > 0, "{own:?}");
    let id = client.create_campaign(&request).await.unwrap().id;
    let view = finished(&client, id, Duration::from_secs(120)).await;
    assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
    assert_eq!(view.method, Method::Adaptive);
    assert_same_adaptive(&view, &own);
    stages_and_history_agree(&client, &view).await;
    assert!(
        view.ci_low.unwrap() <= exact && exact <= view.ci_high.unwrap(),
        "{view:?}"
    );
    // No lease reached past the stage the campaign stopped in.
    let stage = AdaptiveSettings::default().stage_tests;
    assert!(view.leased - view.indices < stage, "{view:?}");
    // The same campaign started by `tslg campaign start --wait`: its
    // progress line counts every test it ran, as the demo's table does, not
    // only the estimation tests.
    let library_id = library.id.to_string();
    let o = tslg(&[
        "campaign",
        "start",
        "--server",
        &service.server.url,
        "--method",
        "adaptive",
        "--library-id",
        &library_id,
        "--vut",
        "fvdm",
        "--seed",
        "3",
        "--wait",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let progress = String::from_utf8_lossy(&o.stderr);
    assert!(view.tests < view.indices, "{view:?}");
    let line = format!(" {} tests {:>6} events", view.indices, view.events);
    assert!(progress.lines().any(|l| l.contains(&line)), "{progress}");
    // So does its line in `campaign list`.
    let o = tslg(&["campaign", "list", "--server", &service.server.url]);
    let list = String::from_utf8_lossy(&o.stdout);
    let row = list
        .lines()
        .find(|l| l.trim_start().starts_with(&format!("{id} ")))
        .unwrap_or_else(|| panic!("{list}"));
    let columns: Vec<&str> = row.split_whitespace().collect();
    assert_eq!(columns[5], view.indices.to_string(), "{list}");
    // The gate judges the campaign on its guarded upper end, which holds
    // what its support may leave out: above a limit between its interval's
    // upper end and the guarded one it fails (exit 3), above the guarded
    // one it passes.
    let guarded = view.guarded_ci_high.unwrap();
    let high = view.ci_high.unwrap();
    assert!(high < guarded, "{view:?}");
    for (limit, code, said) in [
        ((high + guarded) / 2.0, 3, "gate failed"),
        (guarded * 1.01, 0, "gate passed"),
    ] {
        let o = tslg(&[
            "campaign",
            "watch",
            &id.to_string(),
            "--server",
            &service.server.url,
            "--fail-above",
            &limit.to_string(),
        ]);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(code), "{stderr}");
        assert!(
            stderr.contains(said) && stderr.contains("guarded upper bound"),
            "{stderr}"
        );
    }

    // A coordinator killed mid-campaign rebuilds its stages from the
    // database and ends at the same answer.
    let request = adaptive(library.id, serde_json::json!({"model": "fvdm"}), 11);
    let own = adaptive_in_process(&request, "fvdm");
    let id = client.create_campaign(&request).await.unwrap().id;
    running_after_three_stages(&client, id).await;
    service.server.kill();
    let server =
        ServerProcess::start_on(&service.database, &service.address, &["--lease-size", "37"]);
    let client = server.client();
    let view = finished(&client, id, Duration::from_secs(120)).await;
    assert_same_adaptive(&view, &own);
    // The stages resolved before the kill are recorded once, as after it.
    stages_and_history_agree(&client, &view).await;

    // Guarded: it explores until the bound on what its support leaves out
    // is within β of its estimate, and is the in-process campaign.
    let guarded = CreateCampaign {
        guard_outside: Some(true),
        ..adaptive(library.id, serde_json::json!({"model": "fvdm"}), 1)
    };
    let own = adaptive_in_process(&guarded, "fvdm");
    let id = client.create_campaign(&guarded).await.unwrap().id;
    let view = finished(&client, id, Duration::from_secs(180)).await;
    assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
    assert!(view.guard_outside);
    assert_same_adaptive(&view, &own);
    stages_and_history_agree(&client, &view).await;
    let (upper, estimate) = (view.outside_upper.unwrap(), view.estimate.unwrap());
    let outside_part = view.outside_share.unwrap_or(0.0) * estimate;
    assert!(
        upper <= (view.beta * estimate + outside_part) * (1.0 + 1e-12),
        "the guard holds at the stop: {view:?}"
    );
    assert!(
        view.guarded_ci_high.unwrap() - view.ci_high.unwrap() <= view.beta * estimate,
        "{view:?}"
    );

    // Refused with a precise reason: car-following.
    let following = CreateCampaign {
        case: "car-following".into(),
        ..adaptive(library.id, serde_json::json!({"model": "fvdm"}), 1)
    };
    let refused = client
        .create_campaign(&following)
        .await
        .unwrap_err()
        .to_string();
    assert!(
        refused.contains("422") && refused.contains("grid case"),
        "{refused}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_external_program_in_step_mode_runs_the_adaptive_campaign_of_its_built_in_twin() {
    // examples/fvdm_vut.rs drives the FVDM as the built-in model does; in
    // step mode the case's loop measures its mnpETTC, so its near misses
    // and the stages planned from them are the built-in FVDM's.
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &["--lease-size", "64"]);
    let bin = example_binary("fvdm_vut");
    let exec = format!("rs-fvdm={}", bin.display());
    let _worker = WorkerProcess::start_with(&server.url, 2, "rs", &["--vut-exec", &exec]);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let request = adaptive(
        library.id,
        serde_json::json!({"external": "rs-fvdm", "mode": "step"}),
        5,
    );
    let own = adaptive_in_process(&request, "fvdm");
    let id = client.create_campaign(&request).await.unwrap().id;
    let view = finished(&client, id, Duration::from_secs(240)).await;
    assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
    assert_same_adaptive(&view, &own);
}

/// `adaptive_search: lattice` through the service, on highway-exit's paper
/// grid (1,640,961 scenarios, searched on every 4th index): the campaign is
/// the in-process lattice campaign to the bit, its search a fraction of the
/// grid search's, its view says which search ran; asked of a method that
/// does not search, it is refused with the reason, over HTTP and by the
/// command line.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_lattice_search_through_the_service_is_the_in_process_one_on_the_paper_grid() {
    let dir = scratch();
    let database = dir.path().join("db.sqlite");
    let server = ServerProcess::start(&database, &[]);
    let address = server.address.clone();
    let _workers = two_workers(&server.url);
    let client = server.client();
    let library = build_library(
        &client,
        &tslg_api::CreateLibrary {
            case: "highway-exit".into(),
            preset: Some("paper".into()),
            surrogate: serde_json::json!({"model": "mobil"}),
            exposure: Default::default(),
            search: Some(tslg_api::SearchRequest::Exhaustive),
            threshold: None,
        },
    )
    .await;
    let request = CreateCampaign {
        case: "highway-exit".into(),
        vut: serde_json::json!({"model": "mobil"}),
        adaptive_search: Some(tslg_api::AdaptiveSearch::Lattice),
        stage_tests: None,
        ..campaign(Method::Adaptive, library.id, "mobil", 0.2, 5)
    };
    let case = open_case("highway-exit", Some("paper"), &ExposureSource::Builtin).unwrap();
    let file = client.library_file(library.id).await.unwrap();
    let rule = StoppingRule {
        n_min: default_n_min(None, request.max_tests),
        ..StoppingRule::new(0.2, request.max_tests)
    };
    let in_process = |settings: AdaptiveSettings| {
        case.adaptive_campaign(&file, &request.vut, 0.1, settings, &rule, 5)
            .unwrap()
    };
    let own = in_process(AdaptiveSettings {
        lattice: true,
        ..AdaptiveSettings::default()
    });
    let grid = in_process(AdaptiveSettings::default());
    // The grid search walks the failure region cell by cell.
    assert!(
        2 * own.search_tests < grid.search_tests,
        "lattice {} search tests, grid {}",
        own.search_tests,
        grid.search_tests
    );
    let id = client.create_campaign(&request).await.unwrap().id;
    // Killed mid-campaign, the coordinator plans the rest from what it
    // stored, on the lattice.
    running_after_three_stages(&client, id).await;
    server.kill();
    let server = ServerProcess::start_on(&database, &address, &[]);
    let client = server.client();
    let view = finished(&client, id, Duration::from_secs(300)).await;
    assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
    assert_same_adaptive(&view, &own);
    stages_and_history_agree(&client, &view).await;
    assert_eq!(
        view.adaptive.as_ref().unwrap().search,
        tslg_api::AdaptiveSearch::Lattice
    );
    // A plain adaptive campaign says it searched the grid.
    let plain = client
        .create_campaign(&CreateCampaign {
            adaptive_search: None,
            stage_tests: None,
            max_tests: 100,
            ..request.clone()
        })
        .await
        .unwrap();
    assert_eq!(
        plain.adaptive.unwrap().search,
        tslg_api::AdaptiveSearch::Grid
    );

    // Refused where nothing searches.
    let refused = client
        .create_campaign(&CreateCampaign {
            method: Method::Library,
            ..request.clone()
        })
        .await
        .unwrap_err()
        .to_string();
    assert!(
        refused.contains("422") && refused.contains("adaptive_search chooses"),
        "{refused}"
    );
    let library_id = library.id.to_string();
    let o = tslg(&[
        "campaign",
        "start",
        "--server",
        &server.url,
        "--library-id",
        &library_id,
        "--vut",
        "mobil",
        "--adaptive-search",
        "lattice",
    ]);
    let said = String::from_utf8_lossy(&o.stderr);
    assert!(clean_refusal(&o), "{said}");
    assert!(said.contains("use it with --method adaptive"), "{said}");
}

/// A coordinator whose plan, made again after a restart, does not reach
/// the campaign's stored stage (a campaign planned by another version, or
/// a stored state changed by hand: here its running stage's start or end
/// moved by one test) fails the campaign with the reason, rather than
/// holding its workers on a stage no report can resolve.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_campaign_whose_stages_cannot_be_planned_again_fails_with_the_reason() {
    use sqlx::Connection;
    // The start one test on, or the end one test short: both stall
    // without the check.
    for (column, shift) in [("stage_start", "+ 1"), ("stage_end", "- 1")] {
        let service = cut_in_service().await;
        let (client, library) = (service.server.client(), &service.library);
        let request = adaptive(library.id, serde_json::json!({"model": "fvdm"}), 11);
        let id = client.create_campaign(&request).await.unwrap().id;
        running_after_three_stages(&client, id).await;
        service.server.kill();
        let url = format!("sqlite://{}", service.database.display());
        let mut conn = sqlx::SqliteConnection::connect(&url).await.unwrap();
        let (start, end): (i64, i64) = sqlx::query_as(&format!(
            "UPDATE campaigns SET {column} = {column} {shift} WHERE id = ? \
             RETURNING stage_start, stage_end"
        ))
        .bind(id)
        .fetch_one(&mut conn)
        .await
        .unwrap();
        let server =
            ServerProcess::start_on(&service.database, &service.address, &["--lease-size", "37"]);
        let client = server.client();
        let view = finished(&client, id, Duration::from_secs(60)).await;
        assert_eq!(view.status, CampaignStatus::Failed, "{column}: {view:?}");
        let detail = view.status_detail.clone().unwrap_or_default();
        assert!(
            detail.contains(&format!("stage {start}..{end} (they run"))
                && detail.contains("cannot go on"),
            "{column}: {detail}"
        );
        // Its leases ended with it: none is held or handed out again.
        let active: i64 = sqlx::query_scalar(
            "SELECT COUNT(*) FROM leases WHERE campaign_id = ? AND state = 'active'",
        )
        .bind(id)
        .fetch_one(&mut conn)
        .await
        .unwrap();
        assert_eq!(active, 0, "{column}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_large_fleet_gets_stages_of_about_five_rounds_and_the_in_process_answer() {
    // One worker of 32 threads: stages of 20 ⌈5 · 32/20⌉ = 160 tests, so
    // that a stage keeps them busy, and searches of at least 32 cells a
    // stage where the rings reach that far; the campaign is the in-process one
    // with that length, to the bit. A length given is kept; one for a
    // method without stages, or not a multiple of 20, is refused.
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let _worker = WorkerProcess::start(&server.url, 32, "wide");
    let client = server.client();
    let started = std::time::Instant::now();
    while client.workers().await.unwrap().workers.is_empty() {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "the worker seen"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let library = ready_library(&client, "idm", true).await;
    let request = adaptive(library.id, serde_json::json!({"model": "fvdm"}), 3);
    let id = client.create_campaign(&request).await.unwrap().id;
    let view = finished(&client, id, Duration::from_secs(120)).await;
    assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
    assert_eq!(view.adaptive.as_ref().unwrap().stage_tests, 160, "{view:?}");
    // Its search is widened to a round of the fleet it was sized for.
    let settings = AdaptiveSettings {
        stage_tests: 160,
        search_width: AdaptiveSettings::fleet_search_width(160),
        ..AdaptiveSettings::default()
    };
    assert_eq!(settings.search_width, 32);
    assert_same_adaptive(&view, &adaptive_in_process_with(&request, "fvdm", settings));
    let stages = client.stages(id).await.unwrap().stages;
    let estimates: Vec<u64> = stages
        .iter()
        .filter(|s| s.kind == "estimate")
        .map(|s| s.end - s.start)
        .collect();
    assert!(!estimates.is_empty(), "{stages:?}");
    let (last, full) = estimates.split_last().unwrap();
    assert!(
        full.iter().all(|&n| n == 160) && *last <= 160,
        "{estimates:?}"
    );

    let given = client
        .create_campaign(&CreateCampaign {
            stage_tests: Some(200),
            ..adaptive(library.id, serde_json::json!({"model": "fvdm"}), 4)
        })
        .await
        .unwrap();
    assert_eq!(given.adaptive.unwrap().stage_tests, 200);
    for (request, reason) in [
        (
            CreateCampaign {
                stage_tests: Some(200),
                ..campaign(Method::Library, library.id, "fvdm", 0.2, 5)
            },
            "method `library` has no stages",
        ),
        (
            CreateCampaign {
                stage_tests: Some(110),
                ..request.clone()
            },
            "stage_tests = 110 must be a multiple of 20 from 20 to 100000",
        ),
    ] {
        let refused = client
            .create_campaign(&request)
            .await
            .unwrap_err()
            .to_string();
        assert!(
            refused.contains("422") && refused.contains(reason),
            "{refused}"
        );
    }
}
