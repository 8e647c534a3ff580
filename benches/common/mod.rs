//! What the benches share.

// Not every bench that shares this module uses each of its helpers.
#![allow(dead_code)]

use std::sync::Arc;
use tslg_method::cases::open_case;
use tslg_method::registry::{CampaignTests, ExposureSource};

/// The cut-in NDD baseline's tests, in this process: the IDM, the
/// built-in exposure, ε 0.1, `seed`.
pub fn cutin_idm_ndd(seed: u64) -> Arc<dyn CampaignTests> {
    let case = open_case("cut-in", None, &ExposureSource::Builtin).unwrap();
    case.campaign(
        None,
        &serde_json::json!({"model": "idm"}),
        0.1,
        Default::default(),
        Default::default(),
        seed,
    )
    .unwrap()
}

/// The IDM's exhaustive cut-in library built through the service: its id.
pub async fn idm_library(client: &tslg_client::Client) -> anyhow::Result<i64> {
    let mut view = client
        .create_library(&tslg_api::CreateLibrary {
            case: "cut-in".into(),
            preset: None,
            surrogate: serde_json::json!({"model": "idm"}),
            exposure: tslg_api::ExposureRequest::Builtin,
            search: Some(tslg_api::SearchRequest::Exhaustive),
            threshold: None,
        })
        .await?;
    while view.status == tslg_api::LibraryStatus::Building {
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
        view = client.library(view.id).await?;
    }
    Ok(view.id)
}

/// `examples/fvdm_vut.rs` built in release mode, next to the bench that
/// runs (the FVDM as an external program; `--sleep d` makes it slow).
pub fn fvdm_vut_example() -> std::path::PathBuf {
    let exe = std::env::current_exe().expect("the bench's path");
    let path = exe
        .parent()
        .and_then(std::path::Path::parent)
        .expect("target/release")
        .join("examples/fvdm_vut");
    assert!(
        path.exists(),
        "build the example first: cargo build --release --example fvdm_vut"
    );
    path
}

/// A cut-in campaign of `method` on the external program `program` in
/// episode mode (β 0.2, c 0.9, ε 0.1), with `library` and `seed`.
pub fn program_campaign(
    method: tslg_api::Method,
    program: &str,
    library: Option<i64>,
    seed: u64,
) -> tslg_api::CreateCampaign {
    tslg_api::CreateCampaign {
        library_id: library,
        max_tests: 1_000_000,
        seed,
        guard_outside: Some(false),
        ..tslg_api::CreateCampaign::new(
            "cut-in",
            method,
            serde_json::json!({"external": program, "mode": "episode"}),
        )
    }
}
