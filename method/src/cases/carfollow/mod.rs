//! Case 3 of the paper: car-following (safety, SPEC §6). A scenario is a
//! sequence: an initial state `s₁ = (v_BV, R, Ṙ)` and 30 BV accelerations,
//! 33 dimensions that no enumeration reaches. The library is a policy,
//! `Q(s, u)` over 45,885 states and 31 actions, learned for a surrogate
//! model, and tests sample the BV's actions from it while they run.

pub mod adaptive;
pub mod batch;
pub mod case;
pub mod descriptor;
pub mod exposure;
mod exposure_model;
pub mod file;
pub mod library;
pub mod opener;
pub mod sampling;
pub(crate) mod service;
pub mod states;
pub mod world;

pub use case::{CarFollowing, FollowPreset, PolicySolver};
pub use exposure::FollowExposure;
pub use exposure_model::FollowExposureModel;
pub use file::PolicyLibraryFile;
pub use library::{dynamic_programming, temporal_difference, PolicyLibrary, Transitions, Zone};
pub use sampling::{FollowDecision, FollowSampler, FollowTest};
pub use states::StateGrid;
pub use world::{FollowState, FollowWorld};

use crate::vehicle::VehicleModel;

/// A built-in model by name with this case's defaults
/// ([`CarFollowing::vehicle`]): the highway IDM (the surrogate) and the
/// ACC+AEB set to 36 m/s.
pub fn highway_vehicle(name: &str) -> Option<VehicleModel> {
    CarFollowing::vehicle(&serde_json::json!({ "model": name })).ok()
}

/// Names [`highway_vehicle`] knows.
pub const FOLLOW_MODELS: [&str; 2] = ["idm", "acc-aeb"];
