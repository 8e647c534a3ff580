//! The feasible lane-change zone `F` and its area `S(F)` (paper §IV-B).
//!
//! A task solution is a lane-change point `(t, p)`. It is feasible when the
//! VUT can be at `p` at time `t` and the right lane is free there:
//!
//! - **reachable**: from `(0, v₀)` with `a ∈ [a_min, a_max]` and
//!   `v ∈ [v_min, v_max]`, the VUT can be anywhere in
//!   `[p_min(t), p_max(t)]`, where `p_min` brakes at `a_min` down to `v_min`
//!   and `p_max` accelerates at `a_max` up to `v_max`; and `0 ≤ p ≤ L`.
//!   (The paper's lane-change boundary `v_min t ≤ p ≤ min(v_max t, L)`,
//!   `t ∈ [0, 10]` encloses `U_S = 500 m·s`; the acceleration bounds cut it
//!   to 298.2 m·s for v₀ = 30 m/s.)
//! - **safe**: for every BV at `(b, u)`, the bumper gap is at least the safe
//!   time gap at the BV's speed, `|p − b| − ℓ ≥ t_min u`. A BV blocks the open
//!   interval `(b − ℓ − t_min u, b + ℓ + t_min u)`.
//!
//! At each time step the zone is the reachable interval minus the blocked
//! intervals: at most three pieces, computed exactly, so a scenario costs a
//! hundred interval subtractions rather than a 2-D raster. The area is the
//! trapezoid rule over the steps: `S(F) = Δt Σ_k c_k |F(t_k)|` with
//! `c_0 = c_K = ½`, else 1.

use super::world::{ExitWorld, Traffic};

/// The reachable interval `[p_min(t), p_max(t)] ∩ [0, L]`, or `None` once
/// the VUT must have passed the exit.
pub fn reachable(world: &ExitWorld, t: f64) -> Option<(f64, f64)> {
    let v0 = world.start_speed;
    let (v_min, v_max) = world.speed;
    let (a_min, a_max) = world.accel;
    let extreme = |a: f64, v_end: f64| {
        // Constant acceleration `a` until the speed reaches `v_end`, then cruise.
        let t_end = if a == 0.0 {
            f64::INFINITY
        } else {
            (v_end - v0) / a
        };
        if t <= t_end {
            v0 * t + 0.5 * a * t * t
        } else {
            v0 * t_end + 0.5 * a * t_end * t_end + v_end * (t - t_end)
        }
    };
    let low = extreme(a_min, v_min).max(0.0);
    let high = extreme(a_max, v_max).min(world.exit);
    (low <= high).then_some((low, high))
}

/// The interval a BV at `(b, u)` blocks for lane changes.
pub fn blocked(world: &ExitWorld, position: f64, speed: f64) -> (f64, f64) {
    let margin = world.length + world.t_min * speed;
    (position - margin, position + margin)
}

/// `[low, high]` minus the union of open intervals `cuts`: the free pieces,
/// in increasing order.
pub fn subtract(low: f64, high: f64, cuts: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut cuts: Vec<(f64, f64)> = cuts.to_vec();
    cuts.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut pieces = Vec::with_capacity(cuts.len() + 1);
    let mut from = low;
    for (a, b) in cuts {
        if a > from {
            pieces.push((from, a.min(high)));
        }
        from = from.max(b);
        if from >= high {
            break;
        }
    }
    if from < high {
        pieces.push((from, high));
    }
    pieces.retain(|(a, b)| b > a);
    pieces
}

/// The zone at one time step: its free pieces.
#[derive(Debug, Clone, PartialEq)]
pub struct ZoneSlice {
    /// The time of the slice (s).
    pub t: f64,
    /// The free intervals `(from, to)` of the right lane (m), ascending.
    pub pieces: Vec<(f64, f64)>,
}

impl ZoneSlice {
    /// The total length of the free pieces (m).
    pub fn length(&self) -> f64 {
        self.pieces.iter().map(|(a, b)| b - a).sum()
    }
}

/// The zone of a scenario, step by step over `t ∈ [0, horizon]`.
pub fn zone(world: &ExitWorld, x: [f64; 4]) -> Vec<ZoneSlice> {
    let mut traffic = Traffic::new(x);
    let mut slices = Vec::with_capacity(world.zone_steps() + 1);
    for k in 0..=world.zone_steps() {
        let t = k as f64 * world.dt;
        let pieces = match reachable(world, t) {
            Some((low, high)) => {
                let cuts = traffic.bvs.map(|bv| blocked(world, bv.position, bv.speed));
                subtract(low, high, &cuts)
            }
            None => Vec::new(),
        };
        slices.push(ZoneSlice { t, pieces });
        traffic.step(world);
    }
    slices
}

/// `S(F)` by the trapezoid rule over the steps (m·s).
pub fn zone_area(world: &ExitWorld, x: [f64; 4]) -> f64 {
    let lengths: Vec<f64> = zone(world, x).iter().map(ZoneSlice::length).collect();
    trapezoid(world.dt, &lengths)
}

/// The area of the reachable region alone (no BVs), by the same rule.
pub fn reachable_area(world: &ExitWorld) -> f64 {
    let lengths: Vec<f64> = (0..=world.zone_steps())
        .map(|k| reachable(world, k as f64 * world.dt).map_or(0.0, |(low, high)| high - low))
        .collect();
    trapezoid(world.dt, &lengths)
}

fn trapezoid(dt: f64, lengths: &[f64]) -> f64 {
    let last = lengths.len().saturating_sub(1);
    dt * lengths
        .iter()
        .enumerate()
        .map(|(k, &len)| if k == 0 || k == last { 0.5 * len } else { len })
        .sum::<f64>()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subtracting_intervals_leaves_the_free_pieces() {
        assert_eq!(subtract(0.0, 10.0, &[]), vec![(0.0, 10.0)]);
        assert_eq!(
            subtract(0.0, 10.0, &[(6.0, 7.0), (2.0, 3.0)]),
            vec![(0.0, 2.0), (3.0, 6.0), (7.0, 10.0)]
        );
        // Overlapping and covering cuts.
        assert_eq!(
            subtract(0.0, 10.0, &[(2.0, 5.0), (4.0, 8.0)]),
            vec![(0.0, 2.0), (8.0, 10.0)]
        );
        assert!(subtract(0.0, 10.0, &[(-1.0, 4.0), (3.0, 11.0)]).is_empty());
        assert_eq!(
            subtract(0.0, 10.0, &[(-5.0, -1.0), (12.0, 14.0)]),
            vec![(0.0, 10.0)]
        );
    }

    #[test]
    fn the_reachable_interval_follows_the_acceleration_and_speed_bounds() {
        let world = ExitWorld::paper();
        assert_eq!(reachable(&world, 0.0), Some((0.0, 0.0)));
        // t = 2 s: braking 30·2 − 2·4 = 52 m; accelerating 30·2 + 4 = 64 m.
        assert_eq!(reachable(&world, 2.0), Some((52.0, 64.0)));
        // t = 4 s: v_min reached at 2.5 s (62.5 m), then 20 m/s: 92.5 m;
        // a_max gives 30·4 + 16 = 136 m.
        assert_eq!(reachable(&world, 4.0), Some((92.5, 136.0)));
        // t = 6 s: 40 m/s from 5 s (175 m) would give 215 m: capped at L.
        assert_eq!(reachable(&world, 6.0), Some((132.5, 200.0)));
        // Past 9.375 s even the slowest VUT has passed the exit.
        assert_eq!(reachable(&world, 9.5), None);
    }
}
