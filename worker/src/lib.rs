//! The tslg worker: pulls leases from a coordinator, reproduces each test's
//! scenario from the campaign's plan and the test index, simulates the
//! vehicle under test on a rayon pool and reports the outcomes.

pub mod backoff;
pub mod config;
pub mod external;
pub mod panics;
pub mod prepared;
pub mod report_parts;
pub mod run;
pub mod sending;

pub use config::WorkerConfig;
pub use run::{run, WorkerSummary};
