//! The car-following library: Q-values over states and actions (SPEC §6,
//! paper §V, Theorems 1–2).
//!
//! For the surrogate model (SM, a deterministic car-following controller)
//! let `T(s, u)` be the state one decision after the BV takes `u` in state
//! `s` (looked up at the nearest grid state), an accident, or "free"
//! (range beyond the grid). The maneuver challenge of a state,
//! `P(S|s)`, is the probability that the SM has an accident from `s` when
//! the BV keeps acting by the NDD, and
//!
//! `Q(s, u) = P(S|u, s) P(u|s) = P(u|s) · P(S|T(s, u))`,
//! `P(S|s) = Σ_u Q(s, u)`,
//!
//! with `P(S|accident) = 1` and `P(S|free) = P(S|safe state) = 0`. The
//! **zones**: collision (`R ≤ 1 m`), safe (no accident even if the BV brakes
//! at its hardest for the whole run with the SM following), dangerous (the
//! rest). Two solvers reach the same fixed point: backward dynamic
//! programming (value iteration over the dangerous states until nothing
//! changes by more than `tolerance`) and the paper's TD(0) (sweeps of
//! uniformly ordered updates `Q ← Q + α δ`, `δ = P(u|s) Σ_{u'} Q(s', u') −
//! Q(s, u)`, until every `|δ| < tolerance`).

use super::exposure::FollowExposure;
use super::states::StateGrid;
use super::world::{advance, FollowState, FollowWorld};
use crate::progress::Progress;
use crate::vehicle::VehicleModel;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// Where a state lies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Zone {
    /// Range ≤ the accident range: the accident has happened.
    Collision,
    /// No accident even if the BV brakes at −4 m/s² for the rest of the test.
    Safe,
    /// Neither: an accident is possible and depends on the BV's actions.
    Dangerous,
}

/// Where one BV decision leads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Next {
    /// The decision leads to an accident.
    Accident,
    /// No accident can follow: the state leaves the grid or is not dangerous.
    Free,
    /// The grid state the decision leads to.
    State(usize),
}

/// The SM's one-decision transitions and zones on the grid: the model the
/// library is computed from.
#[derive(Debug, Clone)]
pub struct Transitions {
    /// The grid of states.
    pub grid: StateGrid,
    /// The zone of each grid state.
    pub zones: Vec<Zone>,
    /// `next[s · actions + k]`.
    pub next: Vec<Next>,
    /// `P(u|s)` as `action_probability[s · actions + k]`.
    pub action_probability: Vec<f64>,
    /// Actions per state.
    pub actions: usize,
}

impl Transitions {
    /// The surrogate's transitions from every grid state under every action.
    pub fn compute(
        world: &FollowWorld,
        grid: StateGrid,
        exposure: &FollowExposure,
        surrogate: &VehicleModel,
    ) -> Self {
        Self::compute_observed(world, grid, exposure, surrogate, &Progress::default())
    }

    /// [`Transitions::compute`], counting in `progress` each state's zone
    /// run and each state-action transition.
    pub fn compute_observed(
        world: &FollowWorld,
        grid: StateGrid,
        exposure: &FollowExposure,
        surrogate: &VehicleModel,
        progress: &Progress,
    ) -> Self {
        let actions = world.actions;
        progress.start((grid.len() * (1 + actions)) as u64);
        let zones: Vec<Zone> = (0..grid.len())
            .into_par_iter()
            .map(|s| {
                progress.add(1);
                zone(world, grid.state(s), surrogate)
            })
            .collect();
        let next: Vec<Next> = (0..grid.len() * actions)
            .into_par_iter()
            .map(|i| {
                progress.add(1);
                let (s, k) = (i / actions, i % actions);
                if zones[s] != Zone::Dangerous {
                    return Next::Free;
                }
                let mut controller = surrogate.controller();
                match advance(world, grid.state(s), world.action(k), &mut controller) {
                    None => Next::Accident,
                    Some(x) => grid.nearest(&x).map_or(Next::Free, Next::State),
                }
            })
            .collect();
        // P(u|v) depends on the BV's speed only: one law per grid speed.
        let by_speed = &exposure.actions;
        let action_probability = (0..grid.len())
            .flat_map(|s| {
                let i = grid.speed_index(grid.state(s).bv_speed);
                by_speed[i * actions..(i + 1) * actions].iter().copied()
            })
            .collect();
        Self {
            grid,
            zones,
            next,
            action_probability,
            actions,
        }
    }

    /// The share of grid states in the dangerous zone.
    pub fn dangerous_share(&self) -> f64 {
        let n = self.zones.iter().filter(|&&z| z == Zone::Dangerous).count();
        n as f64 / self.zones.len() as f64
    }

    fn challenge_of(&self, challenge: &[f64], next: Next) -> f64 {
        match next {
            Next::Accident => 1.0,
            Next::Free => 0.0,
            Next::State(t) => challenge[t],
        }
    }

    fn initial_challenge(&self) -> Vec<f64> {
        self.zones
            .iter()
            .map(|&z| if z == Zone::Collision { 1.0 } else { 0.0 })
            .collect()
    }
}

/// The zone of a grid state: collision at `R ≤ 1 m`; safe when the SM
/// survives the BV braking at `u_min` for all `decisions`.
pub fn zone(world: &FollowWorld, state: FollowState, surrogate: &VehicleModel) -> Zone {
    if state.range <= world.accident_range {
        return Zone::Collision;
    }
    let mut controller = surrogate.controller();
    let mut x = state;
    for _ in 0..world.decisions {
        match advance(world, x, world.u_min, &mut controller) {
            None => return Zone::Dangerous,
            Some(next) => x = next,
        }
    }
    Zone::Safe
}

/// A learned library: `Q(s, u)` and `P(S|s) = Σ_u Q(s, u)`.
#[derive(Debug, Clone, PartialEq)]
pub struct PolicyLibrary {
    /// Actions per state.
    pub actions: usize,
    /// `Q(s, u)` as `q[s · actions + u]`: the chance of an accident after action `u` in state `s`, times `P(u|s)`.
    pub q: Vec<f64>,
    /// `P(S|s) = Σ_u Q(s, u)` per state.
    pub challenge: Vec<f64>,
    /// Sweeps (DP) or single updates (TD) until the tolerance held.
    pub iterations: u64,
}

impl PolicyLibrary {
    /// A library from its Q-values; `P(S|s)` is each row's sum.
    pub fn new(actions: usize, q: Vec<f64>, iterations: u64) -> Self {
        let challenge = q.chunks(actions).map(|row| row.iter().sum()).collect();
        Self {
            actions,
            q,
            challenge,
            iterations,
        }
    }

    /// `P(u|s, S) = Q(s, u) / Σ_u Q(s, u)`, or `None` where `P(S|s) = 0`.
    pub fn action_distribution(&self, s: usize) -> Option<Vec<f64>> {
        let row = &self.q[s * self.actions..(s + 1) * self.actions];
        let total: f64 = row.iter().sum();
        (total > 0.0).then(|| row.iter().map(|q| q / total).collect())
    }

    /// The largest `|Q − Q'|` between two libraries.
    pub fn max_difference(&self, other: &PolicyLibrary) -> f64 {
        self.q
            .iter()
            .zip(&other.q)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max)
    }
}

/// The solvers stop here whether or not the tolerance held; a library that
/// reached a cap is not at the fixed point.
pub const DP_MAX_SWEEPS: u64 = 10_000;
/// The most TD(0) updates before the solver stops.
pub const TD_MAX_UPDATES: u64 = 20_000_000_000;

/// Backward dynamic programming: Gauss–Seidel value iteration
/// `P(S|s) ← Σ_u P(u|s) P(S|T(s, u))` over the dangerous states, in order
/// of increasing range (the direction most transitions of a dangerous state
/// go), until the largest change is below `tolerance`.
pub fn dynamic_programming(t: &Transitions, tolerance: f64) -> PolicyLibrary {
    let mut challenge = t.initial_challenge();
    let dangerous: Vec<usize> = dangerous_by_range(t);
    let mut sweeps = 0;
    loop {
        sweeps += 1;
        let mut change: f64 = 0.0;
        for &s in &dangerous {
            let value: f64 = (0..t.actions)
                .map(|k| {
                    let i = s * t.actions + k;
                    t.action_probability[i] * t.challenge_of(&challenge, t.next[i])
                })
                .sum();
            change = change.max((value - challenge[s]).abs());
            challenge[s] = value;
        }
        if change < tolerance || sweeps >= DP_MAX_SWEEPS {
            break;
        }
    }
    let q = (0..t.next.len())
        .map(|i| {
            if t.zones[i / t.actions] == Zone::Dangerous {
                t.action_probability[i] * t.challenge_of(&challenge, t.next[i])
            } else {
                0.0
            }
        })
        .collect();
    PolicyLibrary::new(t.actions, q, sweeps)
}

/// The paper's TD(0) with a uniform behaviour policy and learning rate
/// `alpha`: sweeps over every dangerous state-action pair in a random order
/// (seed `seed`), each applying `Q(s,u) += α δ`, until a whole sweep has
/// `|δ| < tolerance`. `P(S|s')` is kept as the running sum of its Q-row.
pub fn temporal_difference(
    t: &Transitions,
    alpha: f64,
    tolerance: f64,
    seed: u64,
) -> PolicyLibrary {
    let mut q = vec![0.0; t.next.len()];
    let mut challenge = t.initial_challenge();
    let mut pairs: Vec<usize> = dangerous_by_range(t)
        .into_iter()
        .flat_map(|s| (0..t.actions).map(move |k| s * t.actions + k))
        .collect();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut updates = 0u64;
    loop {
        pairs.shuffle(&mut rng);
        let mut largest: f64 = 0.0;
        for &i in &pairs {
            let target = t.action_probability[i] * t.challenge_of(&challenge, t.next[i]);
            let delta = target - q[i];
            largest = largest.max(delta.abs());
            q[i] += alpha * delta;
            challenge[i / t.actions] += alpha * delta;
            updates += 1;
        }
        if largest < tolerance || updates >= TD_MAX_UPDATES {
            break;
        }
    }
    PolicyLibrary::new(t.actions, q, updates)
}

fn dangerous_by_range(t: &Transitions) -> Vec<usize> {
    let mut dangerous: Vec<usize> = (0..t.zones.len())
        .filter(|&s| t.zones[s] == Zone::Dangerous)
        .collect();
    dangerous.sort_by(|&a, &b| t.grid.state(a).range.total_cmp(&t.grid.state(b).range));
    dangerous
}
