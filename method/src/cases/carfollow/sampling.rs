//! Car-following tests: the initial state and the BV's actions are drawn
//! while the test runs, from the state the vehicle under test produces
//! (SPEC §6).
//!
//! - **NDD**: `s₁ ~ P(s)`, `u_k ~ P(u|v_k)`; weight 1.
//! - **Library**: `s₁ ~ q(s) = (1 − ε) P(S|s) P(s) / μ_S + ε e(s)` and, in
//!   each decision at grid state `s_k` (the nearest to the continuous
//!   state), `u_k ~ q(u|s_k) = (1 − ε) Q(s_k, u)/P(S|s_k) + ε e(u|v_k)`
//!   where `P(S|s_k) > 0`, else the NDD. The exploration laws `e` are the
//!   NDD's (`e(s) = P(s)`, `e(u|v) = P(u|v)`: every per-step ratio is at
//!   most `1/ε`) or uniform (`1/N(X)` over the states, `1/31` over the
//!   actions: the paper's ε-greedy form). The weight is
//!   `P(s₁)/q(s₁) · Π_k P(u_k|v_k)/q(u_k|s_k)`, kept as its logarithm.
//!
//! The NDD action law is read at the BV speed of the nearest grid state
//! (clamped to the grid), so the weights use exactly the law the NDD
//! baseline samples from. Every draw comes from the counter-based stream of
//! `(seed, index)`, so a test is reproducible from its index alone.

use super::exposure::FollowExposure;
use super::library::PolicyLibrary;
use super::states::StateGrid;
use super::world::{advance_with, FollowState, FollowWorld, Odometer};
use crate::alias::AliasTable;
use crate::sampling::{long_test_rng, OutsideSpread, SamplingError};
use crate::vehicle::{FollowDriver, VehicleModel};
use rand::Rng;
use std::sync::Arc;

/// One car-following test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowTest {
    /// Whether the test ended in an accident.
    pub accident: bool,
    /// `ln w`: 0 for the NDD.
    pub log_weight: f64,
    /// The initial grid state.
    pub initial_state: usize,
}

impl FollowTest {
    /// The test's importance weight `w = exp(log_weight)`.
    pub fn weight(&self) -> f64 {
        self.log_weight.exp()
    }
}

/// One BV decision of a test ([`FollowSampler::run_traced`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowDecision {
    /// The continuous state the decision was taken in.
    pub from: FollowState,
    /// The BV's action (index into the world's actions).
    pub action: usize,
    /// The state one decision later; `None` for an accident.
    pub to: Option<FollowState>,
}

/// Draws `k` with probability `p[k]` by inverse CDF (31 actions: a scan is
/// exact and cheaper than building an alias table per state).
fn draw_index(p: &[f64], r: f64) -> usize {
    let mut acc = 0.0;
    for (k, &pk) in p.iter().enumerate() {
        acc += pk;
        if r < acc {
            return k;
        }
    }
    p.iter().rposition(|&pk| pk > 0.0).unwrap_or(0)
}

/// [`draw_index`] from the running sums `cdf` of `p` (`cdf[k] = p[0] + … +
/// p[k]`, added in that order): a binary search for the first `k` with
/// `r < cdf[k]`, the same `k` as the scan, in five comparisons instead of
/// up to 31.
fn draw_from_cdf(p: &[f64], cdf: &[f64], r: f64) -> usize {
    let k = cdf.partition_point(|&acc| acc <= r);
    if k < cdf.len() {
        k
    } else {
        p.iter().rposition(|&pk| pk > 0.0).unwrap_or(0)
    }
}

/// The running sums of each row of `rows` (`width` entries a row), added
/// as [`draw_index`] adds them.
fn running_sums(rows: &[f64], width: usize) -> Vec<f64> {
    let mut sums = Vec::with_capacity(rows.len());
    for row in rows.chunks(width) {
        let mut acc = 0.0;
        for &p in row {
            acc += p;
            sums.push(acc);
        }
    }
    sums
}

/// What tests of a campaign are drawn from.
#[derive(Debug, Clone)]
pub struct FollowSampler {
    world: FollowWorld,
    grid: StateGrid,
    /// `P(u|v)` per grid speed index, `speeds × actions`.
    ndd_actions: Vec<f64>,
    /// Their running sums, row by row ([`draw_from_cdf`]).
    ndd_cdf: Vec<f64>,
    /// `P(s)` and the initial-state distribution `q(s)` (= `P(s)` for the NDD).
    initial: Vec<f64>,
    initial_q: Vec<f64>,
    initial_alias: Arc<AliasTable>,
    library: Option<LibraryMix>,
}

/// The library's share and how ε explores.
#[derive(Debug, Clone)]
struct LibraryMix {
    library: Arc<PolicyLibrary>,
    epsilon: f64,
    outside: OutsideSpread,
}

impl FollowSampler {
    /// The NDD baseline.
    pub fn ndd(world: FollowWorld, grid: StateGrid, exposure: &FollowExposure) -> Self {
        let initial = exposure.initial.clone();
        Self::build(world, grid, exposure, initial.clone(), initial, None)
    }

    /// Library sampling with exploration share `epsilon` spread by
    /// `outside`.
    pub fn library(
        world: FollowWorld,
        grid: StateGrid,
        exposure: &FollowExposure,
        library: Arc<PolicyLibrary>,
        epsilon: f64,
        outside: OutsideSpread,
    ) -> Result<Self, SamplingError> {
        crate::sampling::check_epsilon(epsilon)?;
        if epsilon == 0.0 {
            return Err(SamplingError::NoExploration);
        }
        if library.challenge.len() != grid.len() {
            return Err(SamplingError::GridMismatch {
                library: library.challenge.len(),
                exposure: grid.len(),
            });
        }
        let initial = exposure.initial.clone();
        let mu: f64 = initial
            .iter()
            .zip(&library.challenge)
            .map(|(p, c)| p * c)
            .sum();
        if mu <= 0.0 {
            return Err(SamplingError::EmptyLibrary);
        }
        let states = grid.len() as f64;
        let q = initial
            .iter()
            .zip(&library.challenge)
            .map(|(p, c)| {
                let explore = match outside {
                    OutsideSpread::Ndd => *p,
                    OutsideSpread::Uniform => 1.0 / states,
                };
                (1.0 - epsilon) * p * c / mu + epsilon * explore
            })
            .collect();
        let mix = LibraryMix {
            library,
            epsilon,
            outside,
        };
        Ok(Self::build(world, grid, exposure, initial, q, Some(mix)))
    }

    fn build(
        world: FollowWorld,
        grid: StateGrid,
        exposure: &FollowExposure,
        initial: Vec<f64>,
        initial_q: Vec<f64>,
        library: Option<LibraryMix>,
    ) -> Self {
        let ndd_actions = exposure.actions.clone();
        let ndd_cdf = running_sums(&ndd_actions, world.actions);
        let initial_alias =
            Arc::new(AliasTable::new(initial_q.clone()).expect("a positive initial distribution"));
        Self {
            world,
            grid,
            ndd_actions,
            ndd_cdf,
            initial,
            initial_q,
            initial_alias,
            library,
        }
    }

    /// Test `index`'s random stream, initial state and the logarithm of
    /// its initial weight `P(s₁)/q(s₁)`.
    pub(super) fn start(&self, seed: u64, index: u64) -> (rand_chacha::ChaCha8Rng, usize, f64) {
        let mut rng = long_test_rng(seed, index);
        let s1 = self.initial_alias.sample(&mut rng);
        let log_weight = (self.initial[s1] / self.initial_q[s1]).ln();
        (rng, s1, log_weight)
    }

    /// The BV's action at `x`: from the library's mix where it guides
    /// (adding `ln P(u|v)/q(u|s)` to `log_weight`), else from the NDD;
    /// `mixed` is scratch of one entry per action.
    pub(super) fn draw_action(
        &self,
        x: &FollowState,
        rng: &mut impl Rng,
        mixed: &mut [f64],
        log_weight: &mut f64,
    ) -> usize {
        let actions = self.world.actions;
        let iv = self.grid.speed_index(x.bv_speed);
        let ndd = &self.ndd_actions[iv * actions..(iv + 1) * actions];
        let r: f64 = rng.random();
        let guided = self.library.as_ref().and_then(|mix| {
            let s = self.grid.nearest(x)?;
            let total = mix.library.challenge[s];
            (total > 0.0).then(|| {
                let row = &mix.library.q[s * actions..(s + 1) * actions];
                let uniform = 1.0 / actions as f64;
                for ((m, q), p) in mixed.iter_mut().zip(row).zip(ndd) {
                    let explore = match mix.outside {
                        OutsideSpread::Ndd => *p,
                        OutsideSpread::Uniform => uniform,
                    };
                    *m = (1.0 - mix.epsilon) * q / total + mix.epsilon * explore;
                }
            })
        });
        match guided {
            Some(()) => {
                let k = draw_index(mixed, r);
                *log_weight += (ndd[k] / mixed[k]).ln();
                k
            }
            None => draw_from_cdf(ndd, &self.ndd_cdf[iv * actions..(iv + 1) * actions], r),
        }
    }

    /// The world the tests run in.
    pub fn world(&self) -> &FollowWorld {
        &self.world
    }

    /// The grid of states.
    pub fn grid(&self) -> &StateGrid {
        &self.grid
    }

    /// Runs test `index` of a campaign with seed `seed` on `vut`.
    pub fn run(&self, vut: &VehicleModel, seed: u64, index: u64) -> FollowTest {
        let Ok(test) = self.run_with(&mut vut.controller(), seed, index);
        test
    }

    /// Runs test `index` of a campaign with seed `seed` with a fresh
    /// `driver` as the vehicle under test; a driver error ends the test.
    pub fn run_with<D: FollowDriver>(
        &self,
        driver: &mut D,
        seed: u64,
        index: u64,
    ) -> Result<FollowTest, D::Error> {
        self.run_traced(driver, seed, index, |_| {})
    }

    /// [`FollowSampler::run_with`], telling `observe` each BV decision as
    /// it is taken: where the vehicle was, what the BV did, where the
    /// vehicle ended (what an adaptive campaign learns the vehicle from).
    pub fn run_traced<D: FollowDriver>(
        &self,
        driver: &mut D,
        seed: u64,
        index: u64,
        mut observe: impl FnMut(FollowDecision),
    ) -> Result<FollowTest, D::Error> {
        let (mut rng, s1, mut log_weight) = self.start(seed, index);
        let mut odometer = Odometer::default();
        let mut x = self.grid.state(s1);
        let mut mixed = vec![0.0; self.world.actions];
        for _ in 0..self.world.decisions {
            let k = self.draw_action(&x, &mut rng, &mut mixed, &mut log_weight);
            let action = self.world.action(k);
            let next = advance_with(&self.world, x, action, driver, &mut odometer)?;
            observe(FollowDecision {
                from: x,
                action: k,
                to: next,
            });
            match next {
                None => {
                    return Ok(FollowTest {
                        accident: true,
                        log_weight,
                        initial_state: s1,
                    })
                }
                Some(next) => x = next,
            }
        }
        Ok(FollowTest {
            accident: false,
            log_weight,
            initial_state: s1,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cases::carfollow::FollowExposureModel;

    #[test]
    fn the_binary_search_draws_what_the_scan_draws() {
        let world = FollowWorld::paper();
        let grid = StateGrid::paper();
        let exposure = FollowExposure::from_model(&FollowExposureModel::default(), &world, &grid);
        let rows = &exposure.actions;
        let cdf = running_sums(rows, world.actions);
        let mut rs: Vec<f64> = (0..=4096).map(|i| i as f64 / 4096.0).collect();
        // Every running sum itself and its neighbours: the boundaries.
        for &acc in &cdf {
            rs.extend([acc, acc.next_down(), acc.next_up()]);
        }
        // A row whose mass sums below 1: the fallback to the last action
        // with mass.
        let short = [0.2, 0.3, 0.0, 0.1, 0.0];
        let short_cdf = running_sums(&short, short.len());
        for &r in &rs {
            for (row, sums) in rows
                .chunks(world.actions)
                .zip(cdf.chunks(world.actions))
                .chain([(&short[..], &short_cdf[..])])
            {
                assert_eq!(draw_from_cdf(row, sums, r), draw_index(row, r), "r = {r}");
            }
        }
    }
}
