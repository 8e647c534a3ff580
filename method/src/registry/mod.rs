//! The cases a service can run, behind one object-safe interface, so the
//! coordinator and the worker handle every case with the same code: a case is
//! opened by name with a preset and an exposure source, vehicles are given as
//! JSON specifications, libraries are files in the case's own format, and a
//! campaign's tests are run (worker) and checked (coordinator) by index.
//! Adding a case means one entry in [`crate::cases::BUILTIN`].

mod adaptive_tests;
mod build;
mod campaign_tests;
pub mod cells;
mod error;
mod inert;
pub(crate) mod picture;
mod scenario_case;
mod stages;
pub(crate) mod vut;

pub use crate::library::LibrarySearch;
pub use build::{BuildRequest, BuiltLibrary, LibrarySummary};
pub use campaign_tests::{CampaignTests, PlannedTest, TestOutcome};
pub use error::{CaseError, ExposureSource};
pub use inert::parameters_inert;
pub use picture::PictureMap;
pub use scenario_case::{
    CampaignSampler, CaseIdentity, CaseViews, ExactAnswers, LibraryBuilder, ScenarioCase,
};
pub use stages::{AdaptiveProgress, AdaptiveRun, AdaptiveStages};
