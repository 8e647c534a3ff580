//! The tslg worker: pulls leases from a coordinator, reproduces each test's
//! scenario from the campaign's plan and the test index, simulates the
//! vehicle under test on a rayon pool and reports the outcomes.

mod backoff;
mod building;
mod chunks;
mod config;
mod credential_file;
pub mod external;
mod heartbeat;
mod lease_work;
mod panics;
pub mod prepared;
mod range;
mod report_parts;
mod run;
mod sending;
mod worker;

pub use config::{WorkerConfig, MAX_VUT_SECONDS};
pub use run::run;
pub use worker::WorkerSummary;
