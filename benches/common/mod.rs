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
