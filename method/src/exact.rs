//! Exact answers on the grid for deterministic vehicles (SPEC §3, §8).
//!
//! - `P(A) = Σ_x P(A|x) P(x)` by enumeration;
//! - the per-test variance of the importance-sampling estimator with
//!   distribution `q`: `σ² = Σ_x (P(A|x)P(x))²/q(x) − P(A)²`;
//! - the expected tests to reach relative half-width β:
//!   `n ≈ z² σ² / (β² μ²)`, and for the NDD baseline (`q = P`, Bernoulli
//!   outcomes) `n ≈ z² (1 − μ) / (β² μ)`.

use crate::case::{parallel_chunk, Case};
use crate::sampling::LibraryDistribution;
use crate::tolerance::PROBABILITY_FLOOR;
use rayon::prelude::*;

/// The cells where a deterministic `vehicle` has the event, among cells of
/// positive exposure (the others contribute nothing), in increasing order.
/// Chunks of cells run in parallel, each in the case's batches
/// ([`Case::events`]).
pub fn event_cells<C: Case>(case: &C, vehicle: &C::Vehicle) -> Vec<usize> {
    let exposure = case.exposure();
    let cells: Vec<usize> = (0..case.grid().len())
        .filter(|&cell| exposure.p(cell) > 0.0)
        .collect();
    cells
        .par_chunks(parallel_chunk(cells.len()))
        .flat_map_iter(|chunk| {
            let mut events = vec![false; chunk.len()];
            case.events(vehicle, chunk, &mut events);
            chunk
                .iter()
                .zip(events)
                .filter_map(|(&cell, event)| event.then_some(cell))
                .collect::<Vec<_>>()
        })
        .collect()
}

/// `P(A)` from the event cells.
pub fn event_probability<C: Case>(case: &C, events: &[usize]) -> f64 {
    events.iter().map(|&c| case.exposure().p(c)).sum()
}

/// The analytic per-test variance `σ²` of library sampling.
pub fn library_variance<C: Case>(case: &C, events: &[usize], q: &LibraryDistribution) -> f64 {
    let mu = event_probability(case, events);
    let second: f64 = events
        .iter()
        .map(|&c| {
            let p = case.exposure().p(c);
            p * p / q.q(c).max(PROBABILITY_FLOOR)
        })
        .sum();
    second - mu * mu
}

/// The per-test variance of the stratified estimate
/// ([`crate::sampling::Split::Stratified`]): with the strata holding their
/// shares, `Var(μ̂ₙ) = σ²_strat/n` where
/// `σ²_strat = (1 − ε) Var_{q_in}(w A) + ε Var_{q_out}(w A)`, `w = P/q` the
/// mixture weight. It is the mixture's [`library_variance`] less the
/// between-strata part `(1 − ε) ε (μ_in/(1 − ε) − μ_out/ε)²`.
pub fn stratified_library_variance<C: Case>(
    case: &C,
    events: &[usize],
    q: &LibraryDistribution,
) -> f64 {
    let epsilon = q.epsilon();
    // Σ over events of q(x)·x and q(x)·x² per stratum, x = P/q.
    let (mut first, mut second) = ([0.0f64; 2], [0.0f64; 2]);
    for &c in events {
        let p = case.exposure().p(c);
        let stratum = usize::from(!q.contains(c));
        first[stratum] += p;
        second[stratum] += p * p / q.q(c).max(PROBABILITY_FLOOR);
    }
    let shares = [1.0 - epsilon, epsilon];
    (0..2)
        .filter(|&h| shares[h] > 0.0)
        .map(|h| {
            // Under q_h = q/π_h: E[x] = Σ q x/π_h, E[x²] = Σ q x²/π_h.
            let mean = first[h] / shares[h];
            shares[h] * (second[h] / shares[h] - mean * mean)
        })
        .sum()
}

/// `z² σ² / (β² μ²)`: expected library tests to relative half-width β.
pub fn expected_library_tests(variance: f64, mu: f64, beta: f64, z: f64) -> f64 {
    z * z * variance / (beta * beta * mu * mu)
}

/// `z² (1 − μ) / (β² μ)`: expected NDD tests to relative half-width β.
pub fn expected_ndd_tests(mu: f64, beta: f64, z: f64) -> f64 {
    z * z * (1.0 - mu) / (beta * beta * mu)
}

/// All exact figures for one vehicle and one library.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExactReport {
    /// The exact `P(A) = Σ_x P(x) A(x)` on the grid.
    pub probability: f64,
    /// The per-test variance of the library estimator, `Σ_x P(x)² A(x)/q(x) − P(A)²`.
    pub library_variance: f64,
    /// Tests the library needs for relative half-width β: `z² σ²/(β² P(A)²)`.
    pub library_tests: f64,
    /// Tests the NDD needs: `z² (1 − P(A))/(β² P(A))`.
    pub ndd_tests: f64,
}

impl ExactReport {
    /// The acceleration ratio NDD tests / library tests.
    pub fn ratio(&self) -> f64 {
        self.ndd_tests / self.library_tests
    }
}

/// Exact probability, variance and test counts for `vehicle` tested with the library distribution `q`, by enumeration of the grid.
pub fn exact_report<C: Case>(
    case: &C,
    vehicle: &C::Vehicle,
    q: &LibraryDistribution,
    beta: f64,
    z: f64,
) -> ExactReport {
    let events = event_cells(case, vehicle);
    let probability = event_probability(case, &events);
    let library_variance = library_variance(case, &events, q);
    ExactReport {
        probability,
        library_variance,
        library_tests: expected_library_tests(library_variance, probability, beta, z),
        ndd_tests: expected_ndd_tests(probability, beta, z),
    }
}
