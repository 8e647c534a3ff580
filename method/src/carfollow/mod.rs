//! Case 3 of the paper: car-following (safety, SPEC §6). A scenario is a
//! sequence: an initial state `s₁ = (v_BV, R, Ṙ)` and 30 BV accelerations,
//! 33 dimensions that no enumeration reaches. The library is a policy,
//! `Q(s, u)` over 45,885 states and 31 actions, learned for a surrogate
//! model, and tests sample the BV's actions from it while they run.

mod exposure_model;
pub mod library;
pub mod sampling;
pub mod states;
pub mod world;

pub use exposure_model::FollowExposureModel;
pub use library::{dynamic_programming, temporal_difference, PolicyLibrary, Transitions, Zone};
pub use sampling::{FollowSampler, FollowTest};
pub use states::StateGrid;
pub use world::{FollowState, FollowWorld};

use crate::vehicle::VehicleModel;

/// The built-in vehicles of this case: the cut-in models' parameters are
/// tuned for 20 m/s (the IDM's desired speed is 18 m/s, the FVDM's top speed
/// 14.7 m/s), so on a highway at 20–40 m/s they would brake for speed alone.
/// Here the IDM (the surrogate) desires 36 m/s and measures the bumper gap
/// (`length` 0, as `R` here); the ACC+AEB is set to 36 m/s.
pub fn highway_vehicle(name: &str) -> Option<VehicleModel> {
    let spec = match name {
        "idm" => serde_json::json!({"model": "idm", "v0": 36.0, "length": 0.0}),
        "acc-aeb" => serde_json::json!({"model": "acc-aeb", "set_speed": 36.0}),
        _ => return None,
    };
    Some(serde_json::from_value(spec).expect("valid built-in parameters"))
}

/// Names [`highway_vehicle`] knows.
pub const FOLLOW_MODELS: [&str; 2] = ["idm", "acc-aeb"];
