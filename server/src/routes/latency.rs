//! Request latencies, observed as requests are answered: a middleware
//! that times each request under its route template into
//! [`crate::telemetry::requests::Metrics`].
//!
//! A lease request that asks to wait (long polling) is held while there is
//! no work. That time is the workers' idleness, not the coordinator's
//! slowness: the latency leaves it out (so an alert on the lease route's
//! p99 means what it says), and a histogram of its own counts it.

use crate::telemetry::requests::Metrics;
use axum::extract::{MatchedPath, Request, State};
use axum::middleware::Next;
use axum::response::Response;
use std::future::Future;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Set on a response by a handler that held its request waiting for work:
/// how long it waited, which is not the request's latency.
#[derive(Debug, Clone, Copy)]
struct HeldForWork(Duration);

/// Times a held request: the time its asks of the store took is latency,
/// the rest is held time ([`HoldClock::mark`]).
pub struct HoldClock {
    started: Instant,
    asking_nanos: AtomicU64,
}

impl HoldClock {
    pub fn start() -> Self {
        Self {
            started: Instant::now(),
            asking_nanos: AtomicU64::new(0),
        }
    }

    /// Runs one ask, counting its time as latency.
    pub async fn ask<T>(&self, ask: impl Future<Output = T>) -> T {
        let asked = Instant::now();
        let answer = ask.await;
        let nanos = asked.elapsed().as_nanos().try_into().unwrap_or(u64::MAX);
        self.asking_nanos.fetch_add(nanos, Ordering::Relaxed);
        answer
    }

    /// Marks `response` with the time held: all but the asks.
    pub fn mark(&self, response: &mut Response) {
        let asking = Duration::from_nanos(self.asking_nanos.load(Ordering::Relaxed));
        let held = self.started.elapsed().saturating_sub(asking);
        response.extensions_mut().insert(HeldForWork(held));
    }
}

/// Middleware: observes each request's latency under its route template
/// (`/api/v1/campaigns/{id}`, so ids do not multiply the series).
pub async fn observe(
    State(metrics): State<Arc<Metrics>>,
    request: Request,
    next: Next,
) -> Response {
    let started = Instant::now();
    // Any token is a method to HTTP: only the standard ones become labels,
    // so requests cannot multiply the series.
    let method: &'static str = match request.method().as_str() {
        "GET" => "GET",
        "POST" => "POST",
        "PUT" => "PUT",
        "DELETE" => "DELETE",
        "HEAD" => "HEAD",
        "OPTIONS" => "OPTIONS",
        "PATCH" => "PATCH",
        _ => "other",
    };
    let route = request
        .extensions()
        .get::<MatchedPath>()
        .map_or_else(|| "unmatched".to_owned(), |p| p.as_str().to_owned());
    let response = next.run(request).await;
    let mut latency = started.elapsed();
    if let Some(HeldForWork(held)) = response.extensions().get::<HeldForWork>() {
        latency = latency.saturating_sub(*held);
        metrics.observe_held(held.as_secs_f64());
    }
    metrics.observe_latency(
        method,
        route.as_str(),
        response.status().as_str(),
        latency.as_secs_f64(),
    );
    response
}
