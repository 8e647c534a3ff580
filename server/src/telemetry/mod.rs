//! What the coordinator measures of itself and its campaigns: request
//! latencies ([`requests`]), each running campaign's rate ([`throughput`])
//! and series ([`campaign_metrics`]), and the whole as `/metrics`
//! ([`metrics`]).

pub mod campaign_metrics;
pub mod metrics;
pub mod requests;
pub mod throughput;
