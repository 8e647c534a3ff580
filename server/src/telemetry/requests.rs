//! The request latencies observed as requests are answered (by method,
//! route template and status), and the time lease requests were held for
//! work, which `/metrics` exposes. The routes observe them
//! (`routes/latency.rs`).

use prometheus::{Histogram, HistogramOpts, HistogramVec, Registry};

/// Latency buckets in seconds: 0.5 ms to 10 s.
const LATENCY_BUCKETS: [f64; 14] = [
    0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0,
];

/// Buckets of the time a lease request was held, seconds: 10 ms to past
/// the longest wait a request may ask (30 s, which the last ask may pass).
const HELD_BUCKETS: [f64; 10] = [0.01, 0.05, 0.1, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0];

/// The metrics observed while serving.
pub struct Metrics {
    registry: Registry,
    latency: HistogramVec,
    held: Histogram,
}

impl Default for Metrics {
    fn default() -> Self {
        let registry = Registry::new();
        let latency = HistogramVec::new(
            HistogramOpts::new(
                "tslg_http_request_duration_seconds",
                "Time to answer an HTTP request, by method, route template and status.",
            )
            .buckets(LATENCY_BUCKETS.to_vec()),
            &["method", "route", "status"],
        )
        .expect("valid histogram");
        let held = Histogram::with_opts(
            HistogramOpts::new(
                "tslg_lease_request_held_seconds",
                "Time lease requests that asked to wait were held for work \
                 (left out of their latency): the workers' idle time.",
            )
            .buckets(HELD_BUCKETS.to_vec()),
        )
        .expect("valid histogram");
        for metric in [
            Box::new(latency.clone()) as Box<dyn prometheus::core::Collector>,
            Box::new(held.clone()),
        ] {
            registry.register(metric).expect("registered once");
        }
        Self {
            registry,
            latency,
            held,
        }
    }
}

impl Metrics {
    /// The observed series, for a scrape.
    pub fn gather(&self) -> Vec<prometheus::proto::MetricFamily> {
        self.registry.gather()
    }
}

impl Metrics {
    /// A request of `method` on `route` answered with `status` after
    /// `seconds` (its held time left out).
    pub fn observe_latency(&self, method: &str, route: &str, status: &str, seconds: f64) {
        self.latency
            .with_label_values(&[method, route, status])
            .observe(seconds);
    }

    /// A lease request held `seconds` waiting for work.
    pub fn observe_held(&self, seconds: f64) {
        self.held.observe(seconds);
    }
}
