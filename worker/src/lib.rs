//! The tslg worker: pulls leases from a coordinator, reproduces each test's
//! scenario from the campaign's plan and the test index, simulates the
//! vehicle under test on a rayon pool and reports the outcomes.

mod backoff;
mod building;
mod config;
pub mod external;
mod panics;
pub mod prepared;
mod report_parts;
mod run;
mod sending;

pub use config::WorkerConfig;
pub use run::{run, WorkerSummary};
