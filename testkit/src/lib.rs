//! What the workspace's integration tests share (a dev-dependency only).
//!
//! - [`skip`]: a test that cannot run says so where the run's summary
//!   shows it. Cargo hides a passing test's output, so a skip is also
//!   written to the file `TSLG_SKIP_LOG` names (`scripts/test` sets it,
//!   counts the skips in its summary line, and under CI fails on any whose
//!   reason is not in `.ci/allowed-skips`).
//! - [`shared_data`]: the folder of reference fixtures (the authors' cut-in
//!   table), `TSLG_SHARED_DATA` or `../shared/data` beside the workspace:
//!   the one place that decides where it is.
//! - [`coverage_floor`] and [`power_against`]: the floor a coverage test
//!   asserts, from the binomial at the nominal coverage, and the chance
//!   that floor catches a regression.

pub mod coverage;
mod skip;

pub use coverage::{coverage_floor, power_against, CoverageCheck};
pub use skip::{authors_table, shared_data, skip};
