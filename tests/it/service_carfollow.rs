//! The car-following case through the real coordinator and workers: a
//! policy library learned by dynamic programming and served as a binary
//! file, library campaigns whose BV actions the workers sample while the
//! vehicle drives (reproduced bit for bit by an in-process run on the same
//! file), and NDD baselines whose intervals agree with them. The `risky`
//! preset keeps the NDD baselines to a few hundred thousand tests; the
//! paper preset's runs are in docs/models.md.

use crate::support::*;
use std::time::Duration;
use tslg_api::{
    CampaignStatus, CreateCampaign, CreateLibrary, LeaseRequest, Method, Outside, SearchRequest,
};

fn request(method: Method, library_id: i64, vut: &str, seed: u64) -> CreateCampaign {
    CreateCampaign {
        library_id: Some(library_id),
        max_tests: 5_000_000,
        seed,
        guard_outside: Some(false),
        ..CreateCampaign::new("car-following", method, serde_json::json!({ "model": vut }))
    }
}

/// The IDM's library on the risky preset, learned by `search` (the
/// case's default, dynamic programming, when `None`).
fn library_request(search: Option<SearchRequest>) -> CreateLibrary {
    CreateLibrary {
        case: "car-following".into(),
        preset: Some("risky".into()),
        surrogate: serde_json::json!({ "model": "idm" }),
        exposure: Default::default(),
        search,
        threshold: None,
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn car_following_library_campaigns_agree_with_ndd_baselines_with_far_fewer_tests() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let _workers = two_workers(&server.url);
    let client = server.client();
    let library = build_library(&client, &library_request(None)).await;
    assert_eq!(library.total_scenarios, 45_885);
    let size = library.size.unwrap();
    assert!((1_000..10_000).contains(&size), "{size} library states");
    // A zone run per state and a transition per dangerous state and action.
    assert!(library.sm_evaluations.unwrap() > 45_885 + 31 * size as u64);
    assert_eq!(library.mu_s, library.w);
    // Its picture over initial range × range rate (115 × 19): the library's
    // states are a part of the exposed ones.
    let (texts, exposure, sampled) = library_picture(&server.url, library.id).await;
    assert!(exposure > 1000 && exposure <= 115 * 19, "{exposure}");
    assert!(
        sampled > 0 && sampled <= exposure,
        "{sampled} of {exposure}"
    );
    assert!(texts.iter().any(|t| t == "range R (m)"), "{texts:?}");

    // The file is the compact binary form, not JSON.
    let http = reqwest::Client::new();
    let response = http
        .get(format!(
            "{}/api/v1/libraries/{}/file",
            server.url, library.id
        ))
        .send()
        .await
        .unwrap();
    assert_eq!(
        response.headers()["content-type"],
        "application/vnd.tslg.policy-library"
    );
    let file = response.bytes().await.unwrap().to_vec();
    assert_eq!(&file[..8], b"TSLGPOL\0");
    assert!(file.len() < 1_200_000, "{} bytes", file.len());

    // Without exploration the estimate would miss every accident outside
    // the library: refused when the campaign is created.
    let refused = http
        .post(format!("{}/api/v1/campaigns", server.url))
        .json(&CreateCampaign {
            epsilon: 0.0,
            ..request(Method::Library, library.id, "idm", 7)
        })
        .send()
        .await
        .unwrap();
    assert_eq!(refused.status(), reqwest::StatusCode::UNPROCESSABLE_ENTITY);
    let problem: serde_json::Value = refused.json().await.unwrap();
    assert!(
        problem["detail"].as_str().unwrap().contains("ε = 0"),
        "{problem}"
    );

    // An adaptive car-following campaign probes the vehicle from grid
    // states, which workers cannot be leased yet: refused with where it runs.
    let refused = http
        .post(format!("{}/api/v1/campaigns", server.url))
        .json(&request(Method::Adaptive, library.id, "idm", 7))
        .send()
        .await
        .unwrap();
    assert_eq!(refused.status(), reqwest::StatusCode::UNPROCESSABLE_ENTITY);
    let problem: serde_json::Value = refused.json().await.unwrap();
    assert!(
        problem["detail"]
            .as_str()
            .unwrap()
            .contains("tslg evaluate --library POLICY --method adaptive"),
        "{problem}"
    );

    // The surrogate, and the ACC+AEB: another controller, whose failures
    // the IDM's library covers (docs/statistics.md has the coverage of both).
    for vut in ["idm", "acc-aeb"] {
        let by_library = client
            .create_campaign(&request(Method::Library, library.id, vut, 7))
            .await
            .unwrap();
        assert_eq!(by_library.outside, Outside::Ndd, "the case's default");
        let by_ndd = client
            .create_campaign(&request(Method::Ndd, library.id, vut, 8))
            .await
            .unwrap();
        // A client that needs each test's scenario in its lease gets none
        // of these campaigns: their scenarios exist only as the tests run.
        let inline = client
            .claim(&LeaseRequest {
                worker: "inline".into(),
                threads: 1,
                include_tests: true,
                offers: Vec::new(),
                unhealthy: Vec::new(),
                max_tests: None,
                wait_seconds: None,
                audits_only: false,
                noisy: Vec::new(),
            })
            .await
            .unwrap();
        assert!(inline.is_none(), "{inline:?}");
        let l = finished(&client, by_library.id, Duration::from_secs(240)).await;
        let n = finished(&client, by_ndd.id, Duration::from_secs(240)).await;
        for view in [&l, &n] {
            assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
        }
        assert!(
            l.ci_low <= n.ci_high && n.ci_low <= l.ci_high,
            "{vut}: library [{:?}, {:?}] and NDD [{:?}, {:?}] disagree",
            l.ci_low,
            l.ci_high,
            n.ci_low,
            n.ci_high
        );
        assert!(
            l.tests * 1000 < n.tests,
            "{vut}: {} library vs {} NDD tests",
            l.tests,
            n.tests
        );
        // Two workers sampled the actions; an in-process run on the served
        // file stops at the same index with the same estimate.
        let reference = in_process_with_file(
            Some(&file),
            Some("risky"),
            &request(Method::Library, library.id, vut, 7),
        );
        assert_same(&l, &reference);
    }

    // TD(0) through the service reaches the same library.
    let td = build_library(
        &client,
        &library_request(Some(SearchRequest::TemporalDifference {
            alpha: 0.1,
            seed: 3,
        })),
    )
    .await;
    assert_eq!(td.size, library.size);
    let relative = (td.mu_s.unwrap() - library.mu_s.unwrap()).abs() / library.mu_s.unwrap();
    assert!(relative < 1e-6, "μ_S by TD vs DP: {relative:e}");
}
