//! What the benches share.

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
