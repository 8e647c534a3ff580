//! Exact answers on the grid (SPEC §3, §8): by enumeration for
//! deterministic vehicles; for a noisy one (`P(A|x)` strictly between 0 and
//! 1 near its failure boundary) `P(A|x)` per cell is a seeded Monte Carlo
//! whose standard error is stated ([`event_rates`]).
//!
//! - `P(A) = Σ_x P(A|x) P(x)` by enumeration;
//! - the per-test variance of the importance-sampling estimator with
//!   distribution `q`: `σ² = Σ_x (P(A|x)P(x))²/q(x) − P(A)²`;
//! - the expected tests to reach relative half-width β:
//!   `n ≈ z² σ² / (β² μ²)`, and for the NDD baseline (`q = P`, Bernoulli
//!   outcomes) `n ≈ z² (1 − μ) / (β² μ)`.

use crate::case::{parallel_chunk, Case};
use crate::guard_floor::GuardFloors;
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

/// Runs per cell of a noisy vehicle's Monte Carlo `P(A|x)`.
pub const NOISY_RUNS_PER_CELL: u32 = 1000;

/// The campaign seed of the exact answers' noise streams: run `j` of cell
/// `c` is test `c · runs + j` of it ([`crate::noise::noise_rng`]), so the
/// Monte Carlo is one fixed computation.
const EXACT_NOISE_SEED: u64 = 0x0065_7861_6374;

/// `P(A|x)` on the cells of positive exposure where it is positive.
#[derive(Debug, Clone, PartialEq)]
pub struct EventRates {
    /// `(cell, P(A|x))`, in increasing cell order.
    pub cells: Vec<(usize, f64)>,
    /// How a noisy vehicle's rates were obtained; `None` when they are
    /// exact (a deterministic vehicle: 1 on its event cells).
    pub monte_carlo: Option<MonteCarlo>,
}

/// A Monte Carlo `P(A) = Σ P(x) P(A|x)` of a noisy vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MonteCarlo {
    /// Runs of every cell of positive exposure.
    pub runs_per_cell: u32,
    /// Cells whose runs differed (some with the event, some without).
    pub varying_cells: usize,
    /// The standard error of `P(A)`: `√(Σ P(x)² p̂(1 − p̂)/(m − 1))`
    /// over the cells, `p̂` the share of `m` runs with the event. A cell
    /// whose `m` runs all agree adds nothing: its rate is taken as 0 or 1,
    /// which holds where the noise cannot move the outcome (far from the
    /// failure boundary) and is off by less than about `3/m` elsewhere.
    pub standard_error: f64,
}

/// `P(A|x)` of `vehicle` on every cell of positive exposure where it is
/// positive: 1 on a deterministic vehicle's event cells; for a noisy one
/// ([`Case::is_noisy`]), the share of [`NOISY_RUNS_PER_CELL`] runs with
/// the event, each with its own noise stream, cells in parallel.
pub fn event_rates<C: Case>(case: &C, vehicle: &C::Vehicle) -> EventRates {
    if !case.is_noisy(vehicle) {
        return EventRates {
            cells: event_cells(case, vehicle)
                .into_iter()
                .map(|c| (c, 1.0))
                .collect(),
            monte_carlo: None,
        };
    }
    let exposure = case.exposure();
    let runs = NOISY_RUNS_PER_CELL;
    let counted: Vec<(usize, u32)> = (0..case.grid().len())
        .into_par_iter()
        .filter(|&cell| exposure.p(cell) > 0.0)
        .map(|cell| {
            let first = cell as u64 * u64::from(runs);
            let events = (0..u64::from(runs))
                .filter(|j| {
                    let noise = crate::noise::noise_rng(EXACT_NOISE_SEED, first + j);
                    case.noisy_run(vehicle, cell, noise).0
                })
                .count() as u32;
            (cell, events)
        })
        .filter(|&(_, events)| events > 0)
        .collect();
    let m = f64::from(runs);
    let variance: f64 = counted
        .iter()
        .map(|&(cell, k)| {
            let (p, rate) = (exposure.p(cell), f64::from(k) / m);
            p * p * rate * (1.0 - rate) / (m - 1.0)
        })
        .sum();
    EventRates {
        monte_carlo: Some(MonteCarlo {
            runs_per_cell: runs,
            varying_cells: counted.iter().filter(|&&(_, k)| k < runs).count(),
            standard_error: variance.sqrt(),
        }),
        cells: counted
            .into_iter()
            .map(|(cell, k)| (cell, f64::from(k) / m))
            .collect(),
    }
}

/// `P(A) = Σ_x P(x) P(A|x)` from the rates.
pub fn rate_probability<C: Case>(case: &C, rates: &EventRates) -> f64 {
    rates
        .cells
        .iter()
        .map(|&(c, rate)| case.exposure().p(c) * rate)
        .sum()
}

/// The per-test variance of library sampling with rates `P(A|x)`: each
/// test's term is `w A` with `w = P/q` and `A` a draw of rate `P(A|x)`, so
/// `E[(w A)²] = Σ_x P(x)² P(A|x)/q(x)` and `σ² = E[(w A)²] − P(A)²` (for
/// rates of 0 and 1, [`library_variance`]).
pub fn rate_library_variance<C: Case>(
    case: &C,
    rates: &EventRates,
    q: &LibraryDistribution,
) -> f64 {
    let mu = rate_probability(case, rates);
    let second: f64 = rates
        .cells
        .iter()
        .map(|&(c, rate)| {
            let p = case.exposure().p(c);
            p * p * rate / q.q(c).max(PROBABILITY_FLOOR)
        })
        .sum();
    second - mu * mu
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
    let [inside, outside] = stratum_variances(case, events, q);
    (1.0 - epsilon) * inside + epsilon * outside
}

/// Each stratum's per-test variance of the wire terms `w A`, `w = P/q`
/// the mixture weight: `[Var_{q_in}(w A), Var_{q_out}(w A)]` (0 for a
/// stratum of share 0). With `n_in` and `n_out` tests of the strata, in
/// whatever proportion (the allocation of issue 49), the stratified
/// estimate has `Var(μ̂) = (1 − ε)² Var_in/n_in + ε² Var_out/n_out`.
pub fn stratum_variances<C: Case>(case: &C, events: &[usize], q: &LibraryDistribution) -> [f64; 2] {
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
    // Under q_h = q/π_h: E[x] = Σ q x/π_h, E[x²] = Σ q x²/π_h.
    std::array::from_fn(|h| {
        if shares[h] > 0.0 {
            let mean = first[h] / shares[h];
            second[h] / shares[h] - mean * mean
        } else {
            0.0
        }
    })
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
    /// For a noisy vehicle, how its `P(A|x)` were obtained.
    pub monte_carlo: Option<MonteCarlo>,
    /// For a noisy vehicle that fails, the fewest tests a guarded
    /// campaign told every cell's rate would need ([`crate::guard_floor`]).
    pub guard_floors: Option<GuardFloors>,
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
    confidence: f64,
) -> ExactReport {
    let z = crate::estimator::z_for_confidence(confidence);
    let rates = event_rates(case, vehicle);
    let probability = rate_probability(case, &rates);
    let library_variance = rate_library_variance(case, &rates, q);
    let guard_floors = rates.monte_carlo.and_then(|_| {
        let cells: Vec<(f64, f64)> = rates
            .cells
            .iter()
            .map(|&(c, rate)| (case.exposure().p(c), rate))
            .collect();
        // The cells that never failed hold the rest of the (normalised)
        // exposure.
        let failing: f64 = cells.iter().map(|&(p, _)| p).sum();
        let safe = (1.0 - failing).max(0.0);
        let all: Vec<(f64, f64)> = cells.into_iter().chain([(safe, 0.0)]).collect();
        GuardFloors::of(&all, beta, z, confidence)
    });
    ExactReport {
        guard_floors,
        probability,
        library_variance,
        library_tests: expected_library_tests(library_variance, probability, beta, z),
        ndd_tests: expected_ndd_tests(probability, beta, z),
        monte_carlo: rates.monte_carlo,
    }
}
